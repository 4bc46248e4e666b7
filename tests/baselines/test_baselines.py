"""Every baseline localizes an easy, noise-free case (a transformed crop of the global map) and
says so (`localized`); says `ambiguous` where the map repeats itself and `failed` on a view
with nothing in common with the map (the decision is `semloc.decision`'s, ranked by score)."""

from __future__ import annotations

import numpy as np
import pytest

from semloc.baselines import (
    ClipperBaseline,
    FpfhRansacBaseline,
    RandomWalkBaseline,
    SegMatchBaseline,
)  # fmt: skip
from semloc.baselines.base import consistency_groups
from semloc.baselines.clipper import ClipperConfig, dense_cluster
from semloc.baselines.fpfh import FpfhConfig
from semloc.eval.success import first_correct_rank, is_success
from semloc.localizer import Result
from semloc.maps import ObjectMap, SemanticObject
from semloc.transforms import pose_error, yaw_pose


@pytest.fixture(scope="module")
def easy():
    from semloc.sim.mapkinds import reconstruction_map
    from semloc.sim.world import generate_world

    gmap = reconstruction_map(generate_world(3, "tiny"))
    anchor = gmap.positions[0]
    near = [o for o in gmap if np.linalg.norm(o.position[:2] - anchor[:2]) < 3.0][:10]
    angle = 0.7
    T = np.eye(4)
    T[:3, :3] = [[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]]
    T[:3, 3] = anchor + [0.5, -0.3, 0.0]
    inv = np.linalg.inv(T)
    local = ObjectMap(
        [
            SemanticObject(f"l{o.id}", o.label, inv[:3, :3] @ o.position + inv[:3, 3],
                           points=o.points @ inv[:3, :3].T + inv[:3, 3], seen=i)
            for i, o in enumerate(near)
        ],
        up=[0, 0, 1],
    )  # fmt: skip
    assert len(local) >= 5
    return gmap, local, T


@pytest.mark.parametrize(
    "cls",
    [pytest.param(ClipperBaseline, marks=pytest.mark.slow),  # 15-30 s
     RandomWalkBaseline, SegMatchBaseline, FpfhRansacBaseline],
)  # fmt: skip
def test_baseline_localizes_easy_case(easy, cls):
    gmap, local, T = easy
    method = cls(gmap, local_up=local.up)
    result = method.update(local)
    assert isinstance(result, Result)
    assert result.hypotheses and result.hypotheses[0].rank == 1
    assert first_correct_rank(result.hypotheses, T) == 1
    assert is_success(result.pose, T)
    assert result.steps[-1].n_local == len(local)
    assert (result.status, result.reason) == ("localized", "")  # one clear place
    assert result.steps[-1].status == "localized"


def _blob(seed: int, centre, half) -> np.ndarray:
    return np.asarray(centre) + np.random.default_rng(seed).uniform(-1, 1, (80, 3)) * half


@pytest.fixture(scope="module")
def ring():
    """12 objects on a circle, labels chair / table / sofa in turn, each object (points too) the
    one before turned by 30 deg: the map looks the same turned by 90 deg, so a view of 5
    neighbours fits 4 places exactly (no mirror fit: the labels run the other way there)."""
    shapes = {"chair": _blob(1, [4.0, 0, 0.45], [0.25, 0.2, 0.4]),
              "table": _blob(2, [4.0, 0, 0.4], [0.4, 0.3, 0.35]),
              "sofa": _blob(3, [4.0, 0, 0.4], [0.3, 0.8, 0.4])}  # fmt: skip
    objects = []
    for i in range(12):
        label = ("chair", "table", "sofa")[i % 3]
        turn = yaw_pose(2 * np.pi * i / 12)[:3, :3]
        objects.append(SemanticObject(f"g{i}", label, points=shapes[label] @ turn.T))
    gmap = ObjectMap(objects, up=[0, 0, 1])
    inverse = np.linalg.inv(yaw_pose(0.4, [1.0, -2.0, 0.0]))
    view = [o.transformed(inverse).replace(id=f"l{k}", seen=k) for k, o in enumerate(objects[:5])]
    # nothing in common: labels the map lacks, flat slabs unlike its shapes, in a line
    alien = [SemanticObject(f"l{k}", "piano", points=_blob(10 + k, [k * 1.7, (k % 2) * 1.1, 0.5],
                                                           [0.6, 0.1, 0.2]), seen=k)
             for k in range(5)]  # fmt: skip
    return gmap, ObjectMap(view, up=[0, 0, 1]), ObjectMap(alien, up=[0, 0, 1])


def _ring_method(cls, gmap):
    # FPFH registers the `retrieve` sub-maps most like the view; the default 6 all lie around one
    # of the 4 places, so it would see no rival at all
    config = FpfhConfig(retrieve=60) if cls is FpfhRansacBaseline else None
    return cls(gmap, config, local_up=[0, 0, 1])


@pytest.mark.parametrize(
    "cls",
    [pytest.param(ClipperBaseline, marks=pytest.mark.slow),  # 15-30 s
     RandomWalkBaseline, SegMatchBaseline, FpfhRansacBaseline],
)  # fmt: skip
def test_baseline_is_ambiguous_where_the_map_repeats_itself(ring, cls):
    gmap, view, _ = ring
    result = _ring_method(cls, gmap).update(view)
    assert result.status == "ambiguous" and not result.pose_is_answer
    assert result.reason.startswith("a rival place within the margin (rank ")
    assert result.reason.endswith(", score)")  # the baselines rank by their score
    exact = [h for h in result.hypotheses if len(h.pairs) == 5 and h.residual < 0.01]
    assert len(exact) >= 2  # the rival is a real second place, not a poor fit
    assert pose_error(exact[0].pose, exact[1].pose)[0] == pytest.approx(90.0, abs=0.5)


@pytest.mark.parametrize(
    "cls",
    [pytest.param(ClipperBaseline, marks=pytest.mark.slow),  # 15-30 s
     RandomWalkBaseline, SegMatchBaseline, FpfhRansacBaseline],
)  # fmt: skip
def test_baseline_fails_on_a_view_with_nothing_in_common(ring, cls):
    gmap, _, alien = ring
    result = _ring_method(cls, gmap).update(alien)
    assert (result.status, result.reason) == ("failed", "no association set with 2 or more pairs")
    assert result.pose is None and result.steps[-1].status == "failed"


def test_dense_cluster_finds_the_clique():
    # 4 mutually consistent nodes (0-3) and 2 outliers consistent only with node 0
    C = np.zeros((6, 6))
    C[:4, :4] = 1
    C[0, 4] = C[4, 0] = C[0, 5] = C[5, 0] = 1
    np.fill_diagonal(C, 1)
    assert sorted(dense_cluster(C.copy(), C, ClipperConfig()).tolist()) == [0, 1, 2, 3]


def test_consistency_groups_are_one_to_one_and_consistent():
    local = np.array([[0, 0, 0], [1, 0, 0], [0, 2, 0]], dtype=float)
    glob = np.array([[5, 5, 0], [6, 5, 0], [5, 7, 0], [9, 9, 0]], dtype=float)
    candidates = [(0, 0, 1.0), (1, 1, 1.0), (2, 2, 1.0), (3, 2, 0.5), (1, 0, 0.2)]
    groups = consistency_groups(candidates, local, glob, 0.1)
    assert sorted(groups[0][1]) == [(0, 0), (1, 1), (2, 2)]


def _answers(result: Result) -> list[tuple]:
    return [(h.rank, h.score, tuple(h.pairs), h.pose.round(9).tobytes()) for h in result.hypotheses]


@pytest.mark.slow
def test_fpfh_index_shared_through_pickle_gives_the_same_answer(easy):
    import pickle

    from semloc.baselines import fpfh

    gmap, local, _ = easy
    fpfh._GLOBAL_INDICES.clear()
    fresh = _answers(FpfhRansacBaseline(gmap, local_up=local.up).update(local))
    index = pickle.loads(pickle.dumps(fpfh.global_index(gmap)))  # as from another worker
    fpfh._GLOBAL_INDICES.clear()
    fpfh._LOCAL_CLOUDS.clear()
    fpfh.share_index(gmap, index)
    method = FpfhRansacBaseline(gmap, local_up=local.up)
    assert method._hist is index.hist
    assert _answers(method.update(local)) == fresh
    again = FpfhRansacBaseline(gmap, local_up=local.up)  # local features from the cache
    assert _answers(again.update(local)) == fresh


def test_segmatch_training_is_shared_per_map_and_settings(easy):
    gmap, local, _ = easy
    first, second = (
        SegMatchBaseline(gmap, local_up=local.up),
        SegMatchBaseline(gmap, local_up=local.up),
    )
    assert second._forest is first._forest
    other = SegMatchBaseline(gmap, SegMatchBaseline.config_class(trees=5), local_up=local.up)
    assert other._forest is not first._forest and len(other._forest.estimators_) == 5
    assert _answers(first.update(local)) == _answers(second.update(local))


def _brute_mutual(local: np.ndarray, target: np.ndarray) -> list[tuple[int, int]]:
    d = np.linalg.norm(local[:, None] - target[None], axis=2)
    forward, backward = d.argmin(axis=1), d.argmin(axis=0)
    mutual = [(i, int(j)) for i, j in enumerate(forward) if backward[j] == i]
    return mutual if len(mutual) >= 3 else [(i, int(j)) for i, j in enumerate(forward)]


@pytest.mark.parametrize("n_local", [5, 40, 2500])  # 2500: several blocks of rows
def test_fpfh_matches_over_shared_sub_maps_equal_one_sub_map_at_a_time(n_local):
    from semloc.baselines import fpfh

    rng = np.random.default_rng(n_local)
    features = rng.uniform(0, 100, (600, 33))
    local = features[rng.choice(600, n_local)] + rng.normal(0, 5, (n_local, 33))
    subsets = [np.sort(rng.choice(600, size, replace=False)) for size in (50, 300, 300, 8)]
    subsets.append(subsets[1][:100])  # overlapping sub-maps, as the retrieved ones are
    together = fpfh._mutual_matches_many(local, features, subsets)
    assert len(together) == len(subsets)
    for subset, pairs in zip(subsets, together, strict=True):
        alone = fpfh._mutual_matches(local, features[subset])
        assert pairs.dtype == np.int32 and np.array_equal(pairs, alone)
        if n_local <= 40:
            assert [tuple(p) for p in pairs.tolist()] == _brute_mutual(local, features[subset])


def test_recent_keeps_the_last_values_and_knows_their_owner():
    from semloc.baselines.recent import Recent

    made = []
    recent = Recent(2)

    def make(key):
        made.append(key)
        return key * 10

    assert [recent.get(k, lambda k=k: make(k)) for k in (1, 2, 1, 3, 2)] == [10, 20, 10, 30, 20]
    assert made == [1, 2, 3, 2]  # 2 was dropped when 3 came (1 had been used since)
    first, second = object(), object()
    assert recent.get("map", lambda: "a", owner=first) == "a"
    assert recent.get("map", lambda: "b", owner=second) == "b"  # the same key, another object
    assert recent.get("map", lambda: "c", owner=second) == "b"
