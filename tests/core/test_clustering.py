"""Every rule of the hierarchical clustering, on hand-built maps, and the literal equivalence."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from literal_clustering import LiteralClustering, pair_hash

from semloc import _clustering_fast as kernels
from semloc.clustering import (
    ClusteringConfig,
    HierarchicalClustering,
    _kth_largest,
    merge_metric,
)
from semloc.maps import ObjectMap, SemanticObject

PAPER = ClusteringConfig(distance_tolerance=0.0)  # the paper's pure ratio


def clustering(global_xyz, config=PAPER) -> HierarchicalClustering:
    return HierarchicalClustering(
        np.asarray(global_xyz, float), [f"g{i}" for i in range(len(global_xyz))], config
    )


def feed(hc, local_xyz, detections) -> None:
    local_xyz = np.asarray(local_xyz, float)
    hc.update(local_xyz, [f"l{i}" for i in range(len(local_xyz))], detections)


def pair_sets(hc) -> dict[tuple, float]:
    return {s.pairs: s.score for s in hc.sets()}


# ---------------------------------------------------------------------------------------------
# merge metric
def test_merge_metric_is_the_distance_ratio():
    assert merge_metric(2.0, 1.0) == pytest.approx(0.5)
    assert merge_metric(1.0, 2.0) == pytest.approx(0.5)
    assert merge_metric(3.0, 3.0) == pytest.approx(1.0)


def test_merge_metric_degenerate_distances():
    assert merge_metric(0.01, 0.02) == 1.0  # both below min_distance: compatible
    assert merge_metric(0.01, 1.0) < 0.05  # only one tiny: incompatible
    assert merge_metric(0.0, 0.0) == 1.0


def test_tolerance_only_forgives_small_absolute_differences():
    assert merge_metric(1.0, 0.7, tolerance=0.4) == 1.0
    assert merge_metric(10.0, 7.0, tolerance=0.4) == pytest.approx(1 - 2.6 / 10)


@given(st.floats(0.06, 50), st.floats(0.06, 50))
def test_merge_metric_symmetric_and_bounded(a, b):
    h = merge_metric(a, b)
    assert 0 < h <= 1
    assert h == pytest.approx(merge_metric(b, a))


# ---------------------------------------------------------------------------------------------
# merging two singletons at the gamma boundary
@pytest.mark.parametrize("local_distance, merges", [(0.79, False), (0.81, True), (1.0, True)])
def test_merge_needs_ratio_above_gamma(local_distance, merges):
    hc = clustering([[0, 0, 0], [1, 0, 0]])
    feed(hc, [[0, 0, 0], [local_distance, 0, 0]], {0: [0], 1: [1]})
    sets = pair_sets(hc)
    assert ((0, 0), (1, 1)) in sets if merges else ((0, 0), (1, 1)) not in sets
    if merges:
        assert sets[((0, 0), (1, 1))] == pytest.approx(min(local_distance, 1 / local_distance))
    assert sets[((0, 0),)] == 0.0 and sets[((1, 1),)] == 0.0  # originals are kept


def test_one_to_one_violations_block_merges():
    # two local chairs, one global chair: both singletons share the global object
    hc = clustering([[0, 0, 0], [3, 0, 0]])
    feed(hc, [[0, 0, 0], [3, 0, 0], [0, 0.01, 0]], {0: [0], 1: [1], 2: [0]})
    sets = pair_sets(hc)
    assert not any({(0, 0), (0, 2)} <= set(p) for p in sets)
    assert ((0, 0), (1, 1)) in sets and ((0, 2), (1, 1)) in sets


def test_overlapping_sets_merge_over_new_cross_pairs_only():
    # A = {a, b}, B = {a, c}: the union is scored vA + vB + h(b, c)
    g = [[0, 0, 0], [4, 0, 0], [0, 3, 0]]
    local = [[0, 0, 0], [4, 0, 0], [0, 2.7, 0]]  # h(a,b)=1, h(a,c)=0.9, h(b,c)=4.675/5
    hc = clustering(g)
    feed(hc, local, {0: [0], 1: [1], 2: [2]})
    sets = pair_sets(hc)
    h_ab, h_ac = 1.0, 0.9
    h_bc = np.hypot(4, 2.7) / 5.0
    assert sets[((0, 0), (1, 1))] == pytest.approx(h_ab)
    assert sets[((0, 0), (2, 2))] == pytest.approx(h_ac)
    # every path to the triple gives h_ab + h_ac + h_bc; duplicates keep the larger (equal)
    assert sets[((0, 0), (1, 1), (2, 2))] == pytest.approx(h_ab + h_ac + h_bc)


def test_duplicates_keep_the_larger_score():
    # a square: {a,b,c} + {a,b,d} -> {a,b,c,d} scores 3 + 3 + h(c,d) = 7 > 3 + 0 + 3 = 6
    square = [[0, 0, 0], [2, 0, 0], [2, 2, 0], [0, 2, 0]]
    hc = clustering(square)
    feed(hc, square, {i: [i] for i in range(4)})
    sets = pair_sets(hc)
    full = ((0, 0), (1, 1), (2, 2), (3, 3))
    assert sets[full] == pytest.approx(7.0)
    assert len([p for p in sets if p == full]) == 1


def test_a_set_containing_the_other_is_not_merged():
    hc = clustering([[0, 0, 0], [1, 0, 0]])
    feed(hc, [[0, 0, 0], [1, 0, 0]], {0: [0], 1: [1]})
    before = pair_sets(hc)
    feed(hc, [[0, 0, 0], [1, 0, 0]], {0: [0]})  # re-detection: {a} is inside {a, b}
    after = pair_sets(hc)
    assert after == before  # no new set, scores unchanged


def test_incompatible_pair_blocks_the_whole_merge():
    # {a,b} and {c}: h(a,c) passes but h(b,c) fails, and that one pair blocks the merge
    g = [[0, 0, 0], [2, 0, 0], [4, 0, 0]]
    local = [[0, 0, 0], [2, 0, 0], [4.0, 1.9, 0]]
    hc = clustering(g)
    feed(hc, local, {0: [0], 1: [1], 2: [2]})
    assert merge_metric(4.0, np.hypot(4, 1.9)) > 0.8  # h(a, c) = 0.90 passes
    assert merge_metric(2.0, np.hypot(2, 1.9)) < 0.8  # h(b, c) = 0.72 fails
    sets = pair_sets(hc)
    assert ((0, 0), (2, 2)) in sets  # a and c alone do merge
    assert ((0, 0), (1, 1), (2, 2)) not in sets


def test_top_k_pruning_keeps_the_best_sets():
    rng = np.random.default_rng(4)
    g = rng.uniform(0, 5, (6, 3))
    config = ClusteringConfig(distance_tolerance=0.0, sets_per_object=2, protect_top=0)
    hc = clustering(g, config)
    local = g + rng.normal(0, 0.05, g.shape)
    feed(hc, local, {i: list(range(6)) for i in range(6)})  # everything is a chair
    assert hc.n_sets <= 2 * 6  # K = 2 * n_global
    best = hc.sets()[0]
    assert len(best) >= 4 and all(g == l for g, l in best.pairs)  # true pairs on top
    roomy = clustering(g, ClusteringConfig(distance_tolerance=0.0, protect_top=0))
    feed(roomy, local, {i: list(range(6)) for i in range(6)})
    assert roomy.n_sets > hc.n_sets
    assert roomy.sets()[0].pairs == tuple((i, i) for i in range(6))


def test_sets_expire_after_more_than_two_updates_without_merge():
    g = [[0, 0, 0], [1, 0, 0], [10, 10, 0], [20, 0, 0], [30, 5, 0], [40, 9, 0]]
    hc = clustering(g, ClusteringConfig(distance_tolerance=0.0, protect_top=0))
    local = np.array(g, float)
    feed(hc, local[:1], {0: [0]})  # step 1: singleton {a}
    feed(hc, local[:2], {1: [1]})  # step 2: {a}+{b} merge -> all refreshed
    # steps 3..5: objects that never merge with anything (no candidate)
    feed(hc, local[:3], {2: []})
    feed(hc, local[:4], {3: []})
    assert ((0, 0), (1, 1)) in pair_sets(hc)  # 2 updates without a merge: kept
    feed(hc, local[:5], {4: []})
    assert ((0, 0), (1, 1)) not in pair_sets(hc)  # more than two: dropped
    assert hc.n_sets == 0


def test_protected_top_sets_do_not_expire():
    g = [[0, 0, 0], [1, 0, 0], [5, 5, 0]]
    hc = clustering(g, ClusteringConfig(distance_tolerance=0.0, protect_top=1))
    local = np.array(g, float)
    feed(hc, local[:2], {0: [0], 1: [1]})
    for _ in range(4):
        feed(hc, local, {2: []})
    assert [s.pairs for s in hc.sets()] == [((0, 0), (1, 1))]


def test_incremental_update_adds_singletons_and_clusters_again():
    g = [[0, 0, 0], [3, 0, 0], [0, 4, 0]]
    hc = clustering(g)
    feed(hc, np.array(g)[:2], {0: [0], 1: [1]})
    assert hc.sets()[0].pairs == ((0, 0), (1, 1))
    feed(hc, np.array(g), {2: [2]})
    assert hc.sets()[0].pairs == ((0, 0), (1, 1), (2, 2))
    assert hc.sets()[0].score == pytest.approx(3.0)


def test_redetected_object_that_moved_drops_sets_it_breaks():
    g = [[0, 0, 0], [3, 0, 0]]
    hc = clustering(g)
    feed(hc, [[0, 0, 0], [3, 0, 0]], {0: [0], 1: [1]})
    assert ((0, 0), (1, 1)) in pair_sets(hc)
    feed(hc, [[0, 0, 0], [6, 0, 0]], {1: [1]})  # the second object was far off after all
    assert ((0, 0), (1, 1)) not in pair_sets(hc)


def test_relabelled_object_loses_its_old_candidates():
    hc = clustering([[0, 0, 0], [3, 0, 0], [3, 0.01, 0]])
    feed(hc, [[0, 0, 0], [3, 0, 0]], {0: [0], 1: [1]})
    feed(hc, [[0, 0, 0], [3, 0, 0]], {1: [2]})  # re-detected with another label
    assert all((1, 1) not in s.pairs for s in hc.sets())
    assert ((0, 0), (2, 1)) in pair_sets(hc)


# ---------------------------------------------------------------------------------------------
# equivalence with the literal transcription
def _scenario(seed: int, n_global: int, n_local: int, n_labels: int):
    rng = np.random.default_rng(seed)
    g = rng.uniform(0, 6, (n_global, 3))
    labels = rng.integers(0, n_labels, n_global)
    chosen = rng.choice(n_global, n_local, replace=False)
    local = g[chosen] + rng.normal(0, 0.15, (n_local, 3))
    detections = [{i: np.flatnonzero(labels == labels[c])} for i, c in enumerate(chosen)]
    return g, local, detections


@settings(max_examples=25)
@given(
    seed=st.integers(0, 10_000),
    n_global=st.integers(4, 10),
    n_local=st.integers(2, 6),
    n_labels=st.integers(1, 3),
    per_object=st.sampled_from([1, 3, 10]),
    tolerance=st.sampled_from([0.0, 0.4]),
)
def test_bitset_clustering_equals_literal_rules(
    seed, n_global, n_local, n_labels, per_object, tolerance
):
    n_local = min(n_local, n_global)
    g, local, detections = _scenario(seed, n_global, n_local, n_labels)
    config = ClusteringConfig(
        distance_tolerance=tolerance, sets_per_object=per_object, protect_top=2
    )
    fast = clustering(g, config)
    literal = LiteralClustering(g, [f"g{i}" for i in range(n_global)], config)
    for step in range(n_local):
        ids = [f"l{i}" for i in range(step + 1)]
        fast.update(local[: step + 1], ids, detections[step])
        literal.update(local[: step + 1], ids, detections[step])
        expected = {tuple(sorted(k)): v[0] for k, v in literal.sets.items()}
        got = pair_sets(fast)
        assert got.keys() == expected.keys()
        for key, score in expected.items():
            assert got[key] == pytest.approx(score, abs=1e-9)


@settings(max_examples=25)
@given(
    seed=st.integers(0, 10_000),
    n_global=st.integers(4, 10),
    n_local=st.integers(2, 6),
    n_labels=st.integers(1, 3),
    nudge=st.booleans(),
)
def test_top_scores_are_the_scores_of_the_top_sets(seed, n_global, n_local, n_labels, nudge):
    """With or without sets whose scores round alike but differ (nudged below the ranking's
    rounding) at the cut, the scores are those of `top`'s sets, largest first."""
    n_local = min(n_local, n_global)
    g, local, detections = _scenario(seed, n_global, n_local, n_labels)
    hc = clustering(g, ClusteringConfig(distance_tolerance=0.4))
    for step in range(n_local):
        feed(hc, local[: step + 1], detections[step])
        if nudge:
            hc._score += np.random.default_rng(seed).uniform(0, 4e-10, hc.n_sets)
        for k in (1, 2, 5, 40):
            for min_size in (1, 2):
                expected = sorted((s.score for s in hc.top(k, min_size)), reverse=True)
                assert hc.top_scores(k, min_size) == expected


def test_union_key_collisions_fall_back_to_exact_member_lists(monkeypatch):
    """Merges are grouped and sets looked up by a sum of candidate keys; when that collides,
    the second key and the member lists decide."""
    import semloc.clustering as module

    g, local, detections = _scenario(7, 10, 6, 1)
    config = ClusteringConfig(sets_per_object=1000, protect_top=2)  # no pruning ties

    def final_sets():
        hc = clustering(g, config)
        for step in range(len(local)):
            hc.update(local[: step + 1], [f"l{i}" for i in range(step + 1)], detections[step])
        return pair_sets(hc)

    expected = final_sets()
    assert max(len(pairs) for pairs in expected) >= 3
    # every candidate's first key is 1, so the first key of a set is its size: sets of one
    # size collide, and only the second (independent) sum tells them apart
    original = module.candidate_keys

    def colliding(candidates):
        return np.ones(len(candidates), np.uint64), original(candidates)[1]

    monkeypatch.setattr(module, "candidate_keys", colliding)
    collided = final_sets()
    assert collided.keys() == expected.keys()
    for pairs, score in expected.items():
        assert collided[pairs] == pytest.approx(score, abs=1e-9)


def _one_by_one(labels, chosen, local):
    """Local objects `chosen` (at `local`) detected one per update, with every same-label map
    object as candidate: per update, the arguments of `update`."""
    for step, c in enumerate(chosen):
        ids = [f"l{i}" for i in range(step + 1)]
        yield local[: step + 1], ids, {step: np.flatnonzero(labels == labels[c])}


def _replay_against_literal(g, labels, chosen, local, config):
    """Local objects detected one per update (`_one_by_one`): the clustering's sets and scores
    equal the literal rules' after each update.  Returns the clustering and its final sets."""
    fast = clustering(g, config)
    literal = LiteralClustering(g, [f"g{i}" for i in range(len(g))], config)
    for update in _one_by_one(labels, chosen, local):
        fast.update(*update)
        literal.update(*update)
        expected = {tuple(sorted(k)): v[0] for k, v in literal.sets.items()}
        got = pair_sets(fast)
        assert got.keys() == expected.keys()
        for key, score in expected.items():
            assert got[key] == pytest.approx(score, abs=1e-9)
    return fast, got


@pytest.mark.slow
@pytest.mark.parametrize("sweep", [False, True])
def test_large_sparse_map_equals_literal_rules(monkeypatch, sweep):
    """A building-like map (many same-label objects far apart, compatibility sparse): the
    sparse formulation gives the literal sets, testing all candidate pairs or sweeping."""
    import semloc.clustering as module

    monkeypatch.setattr(module, "_BRUTE_FORCE_PAIRS", 0 if sweep else 10**9)
    rng = np.random.default_rng(11)
    g = np.column_stack([rng.uniform(0, 20, 40), rng.uniform(0, 20, 40), rng.uniform(0, 2, 40)])
    labels = rng.integers(0, 2, len(g))
    chosen = np.argsort(np.linalg.norm(g - g[0], axis=1))[:5]
    local = g[chosen] + rng.normal(0, 0.1, (5, 3))
    config = ClusteringConfig(max_sets=None, protect_top=3)
    fast, got = _replay_against_literal(g, labels, chosen, local, config)
    assert fast.n_candidates > 80 and max(len(p) for p in got) >= 4
    assert len(fast._graph_indices) < 0.1 * fast.n_candidates**2  # compatibility stays sparse


def test_sweep_over_rows_of_equal_coordinates_equals_literal_rules(monkeypatch):
    """Rows of identical chairs share coordinates along the sweep axis: the sweep's order by
    rank keeps ties in a stable order and still finds every compatible pair."""
    import semloc.clustering as module

    monkeypatch.setattr(module, "_BRUTE_FORCE_PAIRS", 0)  # always the sweep
    rows, seats = np.meshgrid(np.arange(6) * 0.9, np.arange(7) * 1.4)
    g = np.column_stack([seats.ravel(), rows.ravel(), np.zeros(rows.size)])  # long along x
    rng = np.random.default_rng(2)
    labels = rng.integers(0, 2, len(g))
    chosen = np.argsort(np.linalg.norm(g - g[17], axis=1))[:5]
    local = g[chosen] + rng.normal(0, 0.05, (5, 3))
    config = ClusteringConfig(sets_per_object=2, protect_top=3)
    _, got = _replay_against_literal(g, labels, chosen, local, config)
    assert max(len(p) for p in got) >= 3


def _long_strip():
    """A corridor-like map of two labels, 60 m along y, and 5 objects seen near one end."""
    rng = np.random.default_rng(5)
    g = np.column_stack([rng.uniform(0, 4, 36), rng.uniform(0, 60, 36), rng.uniform(0, 2, 36)])
    labels = rng.integers(0, 2, len(g))
    chosen = np.argsort(np.linalg.norm(g - g[3], axis=1))[:5]
    return g, labels, chosen, g[chosen] + rng.normal(0, 0.1, (5, 3))


@pytest.mark.parametrize("window_table", [True, False])
def test_long_strip_map_equals_literal_rules(monkeypatch, window_table):
    """A corridor-like map, longest along y: the compatibility sweep runs along that axis and
    still finds every compatible pair (the literal sets, with the pool bound biting), whether
    its windows start from the merged table or, for many added candidates, binary searches."""
    import semloc.clustering as module

    monkeypatch.setattr(module, "_BRUTE_FORCE_PAIRS", 0)  # always the sweep
    if not window_table:
        monkeypatch.setattr(module, "_WINDOW_ENTRIES", 0)
    g, labels, chosen, local = _long_strip()
    config = ClusteringConfig(sets_per_object=2, protect_top=3)
    fast, got = _replay_against_literal(g, labels, chosen, local, config)
    assert max(len(p) for p in got) >= 3 and fast.n_sets == 2 * len(g)


def test_a_maps_sweep_order_serves_the_clustering(monkeypatch):
    """Given the map's sweep order (as a Localizer gives it, computed once per map), the
    clustering sweeps in it and finds the same sets as one that derives the order itself."""
    import semloc.clustering as module

    monkeypatch.setattr(module, "_BRUTE_FORCE_PAIRS", 0)  # always the sweep
    g, labels, chosen, local = _long_strip()
    ids = [f"g{i}" for i in range(len(g))]
    world = ObjectMap([SemanticObject(i, str(c), p) for i, c, p in zip(ids, labels, g)])
    config = ClusteringConfig(sets_per_object=2, protect_top=3)
    given_order = HierarchicalClustering(g, ids, config, sweep_order=world.sweep_order)
    own_order = HierarchicalClustering(g, ids, config)
    for update in _one_by_one(labels, chosen, local):
        given_order.update(*update)
        own_order.update(*update)
        assert pair_sets(given_order) == pair_sets(own_order)
    assert given_order._sweep_order() is world.sweep_order
    own, given = own_order._sweep_order(), world.sweep_order
    assert (own.axis, own.cross_axis, own.n_ranks) == (given.axis, given.cross_axis, given.n_ranks)
    assert np.array_equal(own.rank, given.rank)
    assert max(len(p) for p in pair_sets(given_order)) >= 3


@pytest.mark.slow
@pytest.mark.parametrize("sweep", [False, True])
def test_kernels_out_of_room_are_called_again_with_more(monkeypatch, sweep):
    """Every merge pass and compatibility search starts with room for one output: each runs
    out, is called again with four times the room until its outputs fit, and the sets are
    still the literal rules'."""
    import semloc.clustering as module

    if sweep:
        monkeypatch.setattr(module, "_BRUTE_FORCE_PAIRS", 0)
    rooms: list[int] = []
    original = module._with_room

    def cramped(kernel, arguments, room):
        found, room = original(kernel, arguments, 1)
        rooms.append(room)
        return found, room

    monkeypatch.setattr(module, "_with_room", cramped)
    rng = np.random.default_rng(11)
    g = np.column_stack([rng.uniform(0, 8, 30), rng.uniform(0, 8, 30), rng.uniform(0, 2, 30)])
    labels = rng.integers(0, 2, len(g))
    chosen = np.argsort(np.linalg.norm(g - g[0], axis=1))[:5]
    local = g[chosen] + rng.normal(0, 0.1, (5, 3))
    _, got = _replay_against_literal(g, labels, chosen, local, ClusteringConfig(protect_top=3))
    assert max(len(p) for p in got) >= 3
    assert max(rooms) >= 64  # some calls ran out of room several times


@settings(max_examples=200)
@given(
    st.lists(st.sampled_from([0.0, 0.0, 0.25, 0.5, 1.0, 1.75, 3.0]), min_size=1, max_size=30),
    st.data(),
)
def test_kth_largest_score_equals_a_partition(scores, data):
    """The pool's k-th best score (its shortcuts: exactly k sets, at most k positive, only the
    positive ones partitioned) is the value a full partition gives."""
    values = np.array(scores)
    k = data.draw(st.integers(1, len(values)))
    assert _kth_largest(values, k) == np.sort(values)[::-1][k - 1]


@settings(max_examples=200)
@given(st.lists(st.integers(1, 9), min_size=1, max_size=40), st.data())
def test_kth_largest_size_equals_a_partition(sizes, data):
    """The k-th largest set size, counted rather than partitioned, is a full partition's."""
    values = np.array(sizes, dtype=np.int64)
    k = data.draw(st.integers(1, len(values)))
    assert _kth_largest(values, k) == np.sort(values)[::-1][k - 1]


def test_singletons_tied_at_the_cut_are_kept_by_their_pair_digests():
    """One object with more candidates than the pool holds: every singleton scores 0, so the
    pool keeps those with the smallest BLAKE2b digests of "global id NUL local id", whatever
    the order of the candidates."""
    g = np.random.default_rng(5).uniform(0, 20, (40, 3))
    config = ClusteringConfig(distance_tolerance=0.0, max_sets=7, protect_top=0)
    expected = sorted(range(40), key=lambda i: pair_hash(f"g{i}", "l0"))[:7]
    for order in (list(range(40)), list(range(39, -1, -1))):
        hc = clustering(g, config)
        feed(hc, [[0.0, 0.0, 0.0]], {0: order})
        assert [s.pairs for s in hc.sets()] == [((i, 0),) for i in expected]


def _splitmix64_finaliser(x: int) -> int:
    mask = (1 << 64) - 1
    x = ((x ^ (x >> 30)) * 0xBF58476D1CE4E5B9) & mask
    x = ((x ^ (x >> 27)) * 0x94D049BB133111EB) & mask
    return x ^ (x >> 31)


@settings(max_examples=50)
@given(st.lists(st.integers(0, 2**62 - 1), max_size=20))
def test_candidate_keys_are_splitmix64_of_two_odd_and_even_counters(indices):
    key, key2 = kernels.candidate_keys(np.array(indices, dtype=np.int64))
    assert key.dtype == key2.dtype == np.uint64
    assert key.tolist() == [_splitmix64_finaliser(2 * i + 1) for i in indices]
    assert key2.tolist() == [_splitmix64_finaliser(2 * i + 2) for i in indices]


@settings(max_examples=50)
@given(
    st.lists(st.lists(st.integers(-1, 9), min_size=1, max_size=4), max_size=6),
    st.lists(st.lists(st.integers(-1, 9), min_size=1, max_size=4), max_size=6),
)
def test_pool_rows_stack_renumber_and_count_like_numpy(top_rows, bottom_rows):
    """The pool's append: rows padded with -1 to the wider width, stacked; members renumbered
    through an index (padding stays -1); sizes count the members."""

    def matrix(rows):
        width = max((len(r) for r in rows), default=1)
        return np.array([r + [-1] * (width - len(r)) for r in rows] or np.zeros((0, 1)), np.int64)

    top, bottom = matrix(top_rows), matrix(bottom_rows)
    width = max(top.shape[1], bottom.shape[1])
    padded = [
        np.pad(m, ((0, 0), (0, width - m.shape[1])), constant_values=-1) for m in (top, bottom)
    ]
    assert np.array_equal(kernels.stacked(top, bottom), np.vstack(padded))
    index = np.arange(10, dtype=np.int64)[::-1] * 3
    assert np.array_equal(
        kernels.renumbered(bottom, index), np.where(bottom >= 0, index[bottom], -1)
    )
    assert kernels.row_sizes(bottom).tolist() == (bottom >= 0).sum(axis=1).tolist()
    is_held = np.zeros(12, dtype=bool)
    is_held[bottom[bottom >= 0]] = True
    assert np.array_equal(kernels.held(bottom, 12), is_held)
    table = np.arange(30, dtype=float).reshape(10, 3)
    owner = np.arange(10) * 7 % 10  # candidate -> object row
    which = np.flatnonzero(is_held)
    assert np.array_equal(kernels.rows_of(table, owner, which), table[owner[which]])


@settings(max_examples=80)
@given(
    seed=st.integers(0, 10_000),
    n_global=st.integers(1, 12),
    n_local=st.integers(1, 4),
    n_covered=st.integers(0, 10),
    n_added=st.integers(1, 10),
)
def test_sweep_windows_start_where_a_binary_search_would(
    seed, n_global, n_local, n_covered, n_added
):
    """The compatibility sweep finds where each added candidate's window starts among another
    local object's candidates by one merge walk; whole-number coordinates and reaches put many
    window edges exactly on a candidate (ties, and the boundary that the search includes)."""
    rng = np.random.default_rng(seed)
    global_xyz = rng.integers(0, 5, (n_global, 3)).astype(float)
    n = n_covered + n_added
    cand_g = rng.integers(0, n_global, n)
    cand_l = rng.integers(0, n_local, n)
    covered, added = np.arange(n_covered), np.arange(n_covered, n)
    reach = rng.integers(0, 3, (n_local, n_local)).astype(float)
    axis = int(rng.integers(3))
    everyone = np.concatenate([covered, added])
    order = np.argsort(global_xyz[cand_g[everyone], axis], kind="stable")
    by_local = everyone[order][np.argsort(cand_l[everyone[order]], kind="stable")]
    starts = np.concatenate([[0], np.cumsum(np.bincount(cand_l, minlength=n_local))])
    sorted_x = global_xyz[cand_g[by_local], axis]
    window = kernels.window_starts(
        added, cand_g, cand_l, global_xyz, reach, axis, order, starts, sorted_x
    )
    for i, x in enumerate(added):
        la = cand_l[x]
        for lb in range(n_local):
            if lb == la:
                continue
            lo, hi = starts[lb], starts[lb + 1]
            at = global_xyz[cand_g[x], axis] - reach[la, lb]
            assert window[i, lb] == lo + np.searchsorted(sorted_x[lo:hi], at)


@pytest.mark.slow
def test_top_pairs_are_the_top_sets_as_arrays():
    """`top_pairs` gives the sets of `top` (same order, pairs ascending by global index, same
    scores) as arrays, for both orders."""
    g, labels, chosen, local = _long_strip()
    clustering, _ = _replay_against_literal(g, labels, chosen, local, ClusteringConfig())
    for largest_first in (False, True):
        sets = clustering.top(25, min_size=2, largest_first=largest_first)
        rows = clustering.top_pairs(25, min_size=2, largest_first=largest_first)
        assert rows.sizes.tolist() == [len(s) for s in sets]
        assert rows.scores.tolist() == [s.score for s in sets]
        assert rows.pairs.tolist() == [list(p) for s in sets for p in s.pairs]
        assert all(list(s.pairs) == sorted(s.pairs) for s in sets)
        assert len(sets) > 5 and max(rows.sizes) >= 3


def _gate_of_every_pair(self, members: np.ndarray, changed: np.ndarray) -> np.ndarray:
    """The clique check measuring every pair of members (what `_gate_of_sets` spares)."""
    valid = members >= 0
    m = np.maximum(members, 0)
    g = self._global_positions[self._cand_g[m]]
    l = self._local_positions[self._cand_l[m]]
    d_global = np.linalg.norm(g[:, :, None] - g[:, None], axis=3)
    d_local = np.linalg.norm(l[:, :, None] - l[:, None], axis=3)
    compatible = self.criterion.compatible(d_global, d_local)
    pair = valid[:, :, None] & valid[:, None, :] & ~np.eye(members.shape[1], dtype=bool)
    return np.all(compatible | ~pair, axis=(1, 2))


@pytest.mark.parametrize("seed", range(6))
def test_redetections_check_only_the_pairs_of_changed_objects_with_the_same_pool(monkeypatch, seed):
    """Re-detections that move objects (by noise, or far enough to break sets) leave the same
    pool whether the clique check measures every pair or only those of changed objects."""
    rng = np.random.default_rng(seed)
    g = rng.uniform(0, 8, (24, 3))
    labels = rng.integers(0, 4, len(g))
    chosen = rng.choice(len(g), 9, replace=False)
    config = ClusteringConfig(distance_tolerance=0.4)
    fast, full = clustering(g, config), clustering(g, config)
    checks = {"full": 0, "dropped": 0}

    def every_pair(self, members, changed):
        checks["full"] += len(members)
        kept = _gate_of_every_pair(self, members, changed)
        checks["dropped"] += int((~kept).sum())
        return kept

    local: list[np.ndarray] = []
    for step in range(30):
        if len(local) < len(chosen) and (step % 3 != 2 or len(local) < 2):
            local.append(g[chosen[len(local)]] + rng.normal(0, 0.15, 3))
            detected = [len(local) - 1]
        else:  # re-detect two known objects: noise, or a move that breaks their sets
            detected = rng.choice(len(local), 2, replace=False).tolist()
            for i in detected:
                jump = rng.uniform(1, 3) if rng.random() < 0.3 else 0.0
                local[i] = g[chosen[i]] + rng.normal(0, 0.15, 3) + [jump, 0, 0]
        detections = {i: np.flatnonzero(labels == labels[chosen[i]]) for i in detected}
        feed(fast, local, detections)
        with monkeypatch.context() as patch:
            patch.setattr(HierarchicalClustering, "_gate_of_sets", every_pair)
            feed(full, local, detections)
        assert pair_sets(fast) == pair_sets(full)
    assert checks["full"] > 0 and checks["dropped"] > 0
