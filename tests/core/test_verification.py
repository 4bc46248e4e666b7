"""Verification, evidence ranking, merging and confidence: one hand-built case per failure shape.

1. a set with one wrong pair: the pair is rejected and the pose is right;
2. two sets converging to one place after refinement: one hypothesis;
3. the right place with better fitness but as many pairs: ranked first;
and: the confidence is monotone in the evidence; every path of the decision says why.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import semloc
from semloc.decision import (
    FEATURES,
    NO_RIVAL,
    SIGNS,
    DecisionConfig,
    decide,
    duplicates,
    is_rival,
    local_anchor,
    rank_places,
    shipped_model,
)
from semloc.maps import ObjectMap, SemanticObject
from semloc.results import Hypothesis
from semloc.transforms import pose_error, yaw_pose
from semloc.verification import (
    Evidence,
    MapSupport,
    VerificationConfig,
    consensus,
    consensus_indexed,
    consensus_many,
    consensus_rows,
)

UP = np.array([0.0, 0.0, 1.0])
ROOM = np.array([[0, 0, 0.5], [3, 0, 0.4], [3, 2.5, 0.8], [0, 2, 0.3], [1.5, 4, 1.0], [4, 4, 0.6]])


def _apply(T: np.ndarray, xyz: np.ndarray) -> np.ndarray:
    return xyz @ T[:3, :3].T + T[:3, 3]


# 1. one planted wrong pair ------------------------------------------------------------------
@pytest.mark.parametrize("up", [UP, None], ids=["4dof", "6dof"])
def test_a_planted_wrong_pair_is_rejected_and_the_pose_is_right(up):
    truth = yaw_pose(0.7, [1.0, -2.0, 0.0])
    global_xyz = ROOM.copy()
    local_xyz = _apply(np.linalg.inv(truth), global_xyz)
    global_xyz[2] += [0.9, -0.8, 0.0]  # pair 2 is wrong: its partner is elsewhere
    least_squares_pose = semloc.pose.align_positions(local_xyz, global_xyz, up, up)
    assert pose_error(least_squares_pose, truth)[1] > 0.05  # the wrong pair pulls the pose
    found = consensus(local_xyz, global_xyz, up, up, VerificationConfig())
    assert found.inliers.tolist() == [True, True, False, True, True, True]
    rotation, translation = pose_error(found.pose, truth)
    assert rotation < 1e-4 and translation < 1e-6
    assert found.residual < 1e-9


def test_a_set_as_small_as_a_minimal_sample_is_kept_whole():
    found = consensus(ROOM[:2], ROOM[:2] + [0.1, 0, 0], UP, UP, VerificationConfig())
    assert found.inliers.tolist() == [True, True]


@settings(max_examples=40)
@given(
    yaw=st.floats(-np.pi, np.pi),
    shift=st.tuples(st.floats(-5, 5), st.floats(-5, 5), st.floats(-1, 1)),
    wrong=st.integers(0, 5),
    offset=st.floats(1.5, 4.0),
    direction=st.floats(-np.pi, np.pi),
)
def test_one_wrong_pair_of_six_is_always_found(yaw, shift, wrong, offset, direction):
    truth = yaw_pose(yaw, shift)
    global_xyz = ROOM.copy()
    local_xyz = _apply(np.linalg.inv(truth), global_xyz)
    global_xyz[wrong] += offset * np.array([np.cos(direction), np.sin(direction), 0.0])
    found = consensus(local_xyz, global_xyz, UP, UP, VerificationConfig())
    assert np.flatnonzero(~found.inliers).tolist() == [wrong]
    rotation, translation = pose_error(found.pose, truth)
    assert rotation < 1e-4 and translation < 1e-6


@pytest.mark.parametrize("up", [UP, None], ids=["4dof", "6dof"])
def test_many_sets_at_once_give_each_set_its_own_answer(up):
    """Batched sets of mixed sizes (padded together) answer as each set alone would; a set
    whose least-squares pose fits every pair is kept whole."""
    rng = np.random.default_rng(3)
    problems = []
    for size in (2, 3, 6, 4, 5, 6, 3):
        truth = yaw_pose(rng.uniform(-3, 3), rng.normal(size=3))
        local_xyz = rng.uniform(-3, 3, size=(size, 3))
        global_xyz = _apply(truth, local_xyz) + rng.normal(scale=0.05, size=(size, 3))
        if size >= 4:
            global_xyz[rng.integers(size)] += [2.0, -1.5, 0.0]  # one wrong pair
        problems.append((local_xyz, global_xyz))
    together = consensus_many(problems, up, up, VerificationConfig())
    for (local_xyz, global_xyz), found in zip(problems, together):
        alone = consensus(local_xyz, global_xyz, up, up, VerificationConfig())
        assert found.inliers.tolist() == alone.inliers.tolist()
        assert (found.pose is None) == (alone.pose is None)
        if found.pose is not None:
            np.testing.assert_allclose(found.pose, alone.pose, atol=1e-9)
            assert found.residual == pytest.approx(alone.residual, abs=1e-9)
    assert together[1].inliers.all() and together[3].inliers.sum() == 3
    assert consensus_many([], up, up, VerificationConfig()) == []


def test_sets_given_by_index_pairs_answer_as_their_positions_do():
    rng = np.random.default_rng(5)
    truth = yaw_pose(0.7, [1.0, -2.0, 0.3])
    local_xyz = rng.uniform(-4, 4, size=(9, 3))
    global_xyz = np.vstack([_apply(truth, local_xyz), rng.uniform(-4, 4, size=(3, 3))])
    pairs = [np.array([[0, 0], [1, 1]]), np.array([[2, 2], [3, 3], [9, 4], [5, 5], [6, 6]]),
             np.array([[7, 7], [10, 8], [4, 4]])]  # fmt: skip
    problems = [(local_xyz[p[:, 1]], global_xyz[p[:, 0]]) for p in pairs]
    for by_index, by_position in zip(
        consensus_indexed(pairs, local_xyz, global_xyz, UP, UP, VerificationConfig()),
        consensus_many(problems, UP, UP, VerificationConfig()),
    ):
        assert by_index.inliers.tolist() == by_position.inliers.tolist()
        np.testing.assert_array_equal(by_index.pose, by_position.pose)
        assert by_index.residual == by_position.residual
    assert not consensus_indexed(pairs, local_xyz, global_xyz, UP, UP, VerificationConfig())[
        1
    ].inliers[2]  # the wrong pair (global 9) is rejected
    assert consensus_indexed([], local_xyz, global_xyz, UP, UP, VerificationConfig()) == []
    rows = consensus_rows(np.zeros((0, 2), np.int64), np.zeros(0, np.int64), local_xyz,
                          global_xyz, UP, UP, VerificationConfig())  # fmt: skip
    assert len(rows.inliers) == len(rows.poses) == len(rows.has_pose) == len(rows.residual) == 0


def test_the_localizer_drops_a_wrong_pair_from_its_hypothesis():
    """Six distinct labels; the local 'desk' is seen 0.7 m from where the map has it (a moved
    object): the hypothesis keeps the five agreeing pairs, without the desk."""
    labels = ["bed", "desk", "sofa", "lamp", "shelf", "tv"]
    gmap = ObjectMap(
        [SemanticObject(f"g{i}", labels[i], ROOM[i]) for i in range(6)], up=UP, name="room"
    )
    truth = yaw_pose(-1.1, [0.5, 0.3, 0.0])
    local_xyz = _apply(np.linalg.inv(truth), ROOM)
    local_xyz[1] = _apply(np.linalg.inv(truth), ROOM[1] + [0.0, 0.7, 0.0])
    local = ObjectMap(
        [SemanticObject(f"l{i}", labels[i], local_xyz[i], seen=i) for i in range(6)], up=UP
    )
    result = semloc.localize(gmap, local)
    best = result.best
    assert ("g1", "l1") not in best.pairs
    assert sorted(best.pairs) == sorted((f"g{i}", f"l{i}") for i in (0, 2, 3, 4, 5))
    rotation, translation = pose_error(best.pose, truth)
    assert rotation < 1e-4 and translation < 1e-6


def test_guided_matching_adds_objects_that_land_on_a_candidate():
    support = MapSupport(
        [np.array([0]), np.array([1, 2]), np.array([], int)], ROOM, VerificationConfig()
    )
    local_xyz = ROOM[[0, 1, 5]] + [0.1, 0.0, 0.0]
    pairs, added, conflicts = support.extend(np.eye(4), local_xyz, [(0, 0)])
    assert pairs == [(0, 0), (1, 1)] and added == 1
    assert conflicts == 1  # object 2 has no candidate at all


# 2. two sets converging to one place -------------------------------------------------------
def _hyp(ids, pose, score=1.0, **features) -> Hypothesis:
    base = dict(n_pairs=4.0, rejected_share=0.0, residual=0.05, fitness=0.9, n_support=0.0,
                conflict_share=0.0)  # fmt: skip
    return Hypothesis(rank=0, score=score, pairs=ids, pose=pose, fitness=features.get(
        "fitness", base["fitness"]), residual=0.05, features=base | features)  # fmt: skip


def test_two_sets_converging_to_one_place_are_one_hypothesis():
    here = yaw_pose(0.3, [1.0, 2.0, 0.0])
    nearly = yaw_pose(0.3 + 1e-4, [1.0005, 2.0, 0.0])
    elsewhere = yaw_pose(2.0, [-3.0, 1.0, 0.0])
    a = _hyp([("g0", "l0"), ("g1", "l1"), ("g2", "l2"), ("g3", "l3")], here)
    b = _hyp([("g4", "l0"), ("g1", "l1"), ("g5", "l2"), ("g3", "l3")], nearly, fitness=0.8)
    c = _hyp([("g6", "l0"), ("g7", "l1"), ("g8", "l2"), ("g9", "l3")], elsewhere, fitness=0.5)
    ranked = rank_places([b, c, a], "evidence", DecisionConfig(), shipped_model())
    assert [h is a for h in ranked] == [True, False] and ranked[1] is c
    assert [h.rank for h in ranked] == [1, 2]


def test_no_same_place_duplicates_in_the_localizers_top_k():
    rng = np.random.default_rng(4)
    labels = ["chair"] * 12 + ["table"] * 4 + ["lamp"] * 4
    xyz = np.column_stack([rng.uniform(0, 12, 20), rng.uniform(0, 8, 20), rng.uniform(0, 1, 20)])
    gmap = ObjectMap([SemanticObject(f"g{i}", labels[i], xyz[i]) for i in range(20)], up=UP)
    truth = yaw_pose(0.4, [2.0, 1.0, 0.0])
    seen = [0, 1, 12, 16, 2]
    local = ObjectMap(
        [SemanticObject(f"l{k}", labels[i], _apply(np.linalg.inv(truth), xyz[i]), seen=k)
         for k, i in enumerate(seen)], up=UP,
    )  # fmt: skip
    result = semloc.localize(gmap, local)
    assert duplicates(result.hypotheses, DecisionConfig(), local_anchor(local.positions)) == 0
    poses = [h.pose for h in result.hypotheses if h.pose is not None]
    for i in range(len(poses)):
        for j in range(i):
            rotation, translation = pose_error(poses[i], poses[j])
            assert rotation >= 10.0 or translation >= 0.3
    assert pose_error(result.pose, truth)[1] < 1e-6


def test_duplicates_are_counted_where_the_local_objects_are():
    # two poses 1 deg apart about the local origin: the same place there, but objects 30 m
    # away land 0.52 m apart, so where the local objects are they are two places
    config = DecisionConfig(distinct_translation=0.3)
    a = Hypothesis(1, 1.0, [("g0", "l0")], yaw_pose(0.0))
    b = Hypothesis(2, 1.0, [("g1", "l1")], yaw_pose(np.radians(1.0)))
    near, far = np.zeros(3), np.array([30.0, 0.0, 0.0])
    assert local_anchor(np.array([[29.0, 0, 0], [31.0, 0, 0]])) == pytest.approx(far)
    assert local_anchor(np.zeros((0, 3))) is None
    assert duplicates([a, b], config, near) == 1
    assert duplicates([a, b], config, far) == 0
    assert duplicates([a, Hypothesis(2, 1.0, [], None), b], config, near) == 1


# 3. better fitness, equal pairs ------------------------------------------------------------
def test_the_right_place_with_better_fitness_is_ranked_first():
    wrong = _hyp([("g0", "l0"), ("g1", "l1"), ("g2", "l2")], yaw_pose(1.0), score=9.0,
                 n_pairs=3.0, fitness=0.84)  # fmt: skip
    right = _hyp([("g3", "l0"), ("g4", "l1"), ("g5", "l2")], yaw_pose(-1.0, [2, 0, 0]),
                 score=5.0, n_pairs=3.0, fitness=1.0)  # fmt: skip
    ranked = rank_places([wrong, right], "evidence", DecisionConfig(), shipped_model())
    assert ranked[0] is right
    assert ranked[0].confidence > ranked[1].confidence
    assert rank_places([wrong, right], "score", DecisionConfig(), shipped_model())[0] is wrong


# confidence --------------------------------------------------------------------------------
FEATURE_RANGES = {"n_pairs": (2, 12), "rejected_share": (0, 0.6), "residual": (0, 0.5),
                  "fitness": (0, 1), "n_support": (0, 6), "conflict_share": (0, 0.6)}  # fmt: skip


@settings(max_examples=60)
@given(
    values=st.tuples(*(st.floats(*FEATURE_RANGES[k]) for k in FEATURES)),
    feature=st.sampled_from([k for k in FEATURES if SIGNS[k]]),
    step=st.floats(0.01, 1.0),
    rival=st.one_of(st.none(), st.floats(-10, 10)),
)
def test_confidence_is_monotone_in_the_evidence(values, feature, step, rival):
    model = shipped_model()
    features = dict(zip(FEATURES, values))
    lo, hi = FEATURE_RANGES[feature]
    more = features | {feature: min(features[feature] + step * (hi - lo), hi)}
    before = model.confidence(model.evidence(features), rival)
    after = model.confidence(model.evidence(more), rival)
    assert (after - before) * SIGNS[feature] >= -1e-12
    if rival is not None:  # a stronger rival never raises the confidence
        assert model.confidence(model.evidence(features), rival + 1.0) <= before + 1e-12


def test_a_lone_weak_hypothesis_is_not_made_sure_by_having_no_rival():
    model = shipped_model()
    weak = {"n_pairs": 3.0, "rejected_share": 0.0, "residual": 0.04, "fitness": 0.42,
            "n_support": 0.0, "conflict_share": 0.0}  # fmt: skip
    evidence = model.evidence(weak)
    assert model.confidence(evidence, None) < model.min_confidence
    assert model.confidence(evidence, NO_RIVAL - 5.0) == model.confidence(evidence, None)


def test_hypotheses_are_ranked_by_the_ranking_logit_and_scored_by_the_evidence():
    by_fitness = dict.fromkeys(FEATURES, 0.0) | {"fitness": 10.0}
    model = shipped_model().model_copy(update={"ranking_bias": 0.0, "ranking_weights": by_fitness})
    many = _hyp([("g0", "l0"), ("g1", "l1"), ("g2", "l2"), ("g3", "l3"), ("g4", "l4")],
                yaw_pose(0.0), n_pairs=5.0, fitness=0.6)  # fmt: skip
    fitting = _hyp([("g5", "l0"), ("g6", "l1"), ("g7", "l2")], yaw_pose(2.0, [3, 0, 0]),
                   n_pairs=3.0, fitness=0.95)  # fmt: skip
    assert rank_places([many, fitting], "evidence", DecisionConfig(), model)[0] is fitting
    assert fitting.evidence == pytest.approx(model.evidence(fitting.features))
    assert rank_places([many, fitting], "evidence", DecisionConfig(), shipped_model())[0] is many


def test_a_variant_sharing_most_pairs_is_no_rival():
    model = shipped_model()
    best = _hyp([("g0", "l0"), ("g1", "l1"), ("g2", "l2"), ("g3", "l3")], yaw_pose(0.0),
                fitness=0.95)  # fmt: skip
    # the same answer with one object matched elsewhere: a different pose, nearly the evidence
    variant = _hyp([("g0", "l0"), ("g1", "l1"), ("g2", "l2"), ("g9", "l3")],
                   yaw_pose(0.6, [1.0, 0, 0]), fitness=0.9)  # fmt: skip
    # another place: it shares one of the best's four pairs
    rival = _hyp([("g0", "l0"), ("g6", "l1"), ("g7", "l2"), ("g8", "l3")],
                 yaw_pose(2.0, [-3.0, 1.0, 0]), fitness=0.9)  # fmt: skip
    assert not is_rival(best.pairs, variant.pairs, 0.5)
    assert is_rival(best.pairs, rival.pairs, 0.5)
    alone = model.confidence(model.evidence(best.features), None)
    with_variant = rank_places([best, variant], "evidence", DecisionConfig(), model)
    assert with_variant[0] is best and best.confidence == pytest.approx(alone)
    with_rival = rank_places([best, rival], "evidence", DecisionConfig(), model)
    assert with_rival[0] is best and best.confidence < alone - 0.1
    # the confidence of the variant itself still sees `best` as a rival only if it shares
    # less than half of the variant's pairs: here it is a variant of `best` as well
    assert variant.confidence == pytest.approx(model.confidence(variant.evidence, None))
    strict = DecisionConfig(rival_overlap=1.0)  # every other place is a rival
    rank_places([best, variant], "evidence", strict, model)
    assert best.confidence < alone - 0.1


def test_is_rival_counts_the_shared_share_of_the_first_pairs():
    four = [("a", "1"), ("b", "2"), ("c", "3"), ("d", "4")]
    assert is_rival(four, [("a", "1"), ("x", "2")], 0.5)  # 1 of 4 shared
    assert not is_rival(four, [("a", "1"), ("b", "2"), ("x", "3")], 0.5)  # 2 of 4
    assert not is_rival([("a", "1"), ("x", "2")], four, 0.5)  # 1 of 2
    assert is_rival(four, four[:3], 1.0) and not is_rival(four, four, 1.0)


def test_evidence_features_are_bounded():
    f = Evidence(30, 2, 5.0, 0.5, 40, 3, 40).features()
    assert set(f) == set(FEATURES)
    assert f["n_pairs"] == 12 and f["n_support"] == 12 and f["residual"] == 1.0
    assert f["rejected_share"] == pytest.approx(2 / 32)


# reasons -----------------------------------------------------------------------------------
def test_each_decision_path_says_why():
    config = DecisionConfig(min_confidence=0.9)
    pose = yaw_pose(0.0)
    sure = Hypothesis(1, 1.0, [("a", "1"), ("b", "2"), ("c", "3")], pose, fitness=1.0,
                      confidence=0.95, evidence=5.0)  # fmt: skip
    assert decide([sure], config, "evidence") == ("localized", "")
    assert decide([], config, "evidence").reason == "no association set with 2 or more pairs"
    two = Hypothesis(1, 1.0, [("a", "1"), ("b", "2")], pose, fitness=1.0, confidence=0.95)
    assert decide([two], config, "evidence").reason.startswith("too few pairs: ")
    loose = Hypothesis(1, 1.0, sure.pairs, pose, fitness=0.1, confidence=0.95)
    assert decide([loose], config, "evidence").reason.startswith("low fitness: 0.10")
    unsure = Hypothesis(1, 1.0, sure.pairs, pose, fitness=1.0, confidence=0.5, evidence=1.0)
    assert decide([unsure], config, "evidence") == ("ambiguous", "low confidence: 0.50 < 0.90")
    rival = Hypothesis(2, 1.0, [("d", "1"), ("e", "2"), ("f", "3")], yaw_pose(2.0),
                       fitness=1.0, confidence=0.4, evidence=0.5)  # fmt: skip
    status, reason = decide([unsure, rival], config, "evidence")
    assert status == "ambiguous" and reason.startswith("a rival place within the margin: rank 2")
    undetermined = Hypothesis(1, 1.0, sure.pairs, None)
    assert "under-determined" in decide([undetermined], config, "evidence").reason


def test_failed_results_say_why():
    gmap = ObjectMap([SemanticObject("g0", "bed", [0, 0, 0]), SemanticObject("g1", "sofa", [2, 0, 0])],
                     up=UP)  # fmt: skip
    one = ObjectMap([SemanticObject("l0", "bed", [0, 0, 0])], up=UP)
    assert semloc.localize(gmap, one).reason == "too few local objects: 1 seen, 2 needed"
    unknown = ObjectMap([SemanticObject("l0", "tv", [0, 0, 0]), SemanticObject("l1", "tv", [1, 0, 0])],
                        up=UP)  # fmt: skip
    result = semloc.localize(gmap, unknown)
    assert result.status == "failed" and result.reason.startswith("no candidates for these labels")
    half = ObjectMap([SemanticObject("l0", "bed", [0, 0, 0]), SemanticObject("l1", "tv", [1, 0, 0])],
                     up=UP)  # fmt: skip
    assert semloc.localize(gmap, half).reason.startswith("only one local object has candidates")


def test_a_set_where_no_two_pairs_agree_has_no_pose():
    local_xyz = ROOM[:3]
    global_xyz = ROOM[:3] * [3.0, -2.0, 1.0] + [0, 0, 2.0]  # stretched and lifted: no match
    found = consensus(local_xyz, global_xyz, UP, UP, VerificationConfig(inlier_tolerance=0.1))
    assert found.pose is None and found.inliers.sum() < 2


def _literal_consensus(local, global_, up, config):
    """The consensus as its docstring states it, one sample at a time (the reference)."""
    from itertools import combinations

    from semloc.pose import align_positions
    from semloc.verification import LOCAL_OPTIMISATIONS

    minimal, tol, n = (3 if up is None else 2), config.inlier_tolerance, len(local)
    ups = (None, None) if up is None else (up, up)

    def fit(mask):
        try:
            return align_positions(local, global_, *ups, weights=mask.astype(float))
        except ValueError:
            return None

    def errors(T):
        return np.linalg.norm(local @ T[:3, :3].T + T[:3, 3] - global_, axis=1)

    def cost(e):
        return float(np.sum(np.minimum(e, tol) ** 2))

    whole = fit(np.ones(n, bool))
    if n <= minimal or (whole is not None and np.all(errors(whole) < 0.5 * tol)):
        return np.ones(n, bool), whole
    tried = []
    for j, sample in enumerate(combinations(range(n), minimal)):
        mask = np.isin(np.arange(n), sample)
        T = fit(mask)
        if T is not None:
            tried.append((-(errors(T) < tol).sum(), cost(errors(T)), j, T))
    best = None
    for _, _, _, T in sorted(tried, key=lambda x: x[:3])[:LOCAL_OPTIMISATIONS]:
        inliers = errors(T) < tol
        for _ in range(3):
            if inliers.sum() < 2:
                break
            refit = fit(inliers)
            again = None if refit is None else errors(refit) < tol
            moves = refit is not None and again.sum() >= 2
            if moves:
                settled = np.array_equal(again, inliers)
                T, inliers = refit, again
                if settled:
                    break
            else:
                break
        key = (inliers.sum(), -cost(errors(T)))
        if best is None or key > best[0]:
            best = (key, inliers, T)
    if best is None:
        return np.ones(n, bool), None
    return best[1], (best[2] if best[1].sum() >= 2 else None)


@settings(max_examples=60)
@given(
    seed=st.integers(0, 10_000),
    n=st.integers(2, 7),
    wrong=st.integers(0, 3),
    six_dof=st.booleans(),
)
def test_the_compiled_consensus_is_the_literal_one(seed, n, wrong, six_dof):
    rng = np.random.default_rng(seed)
    local = rng.uniform(-3, 3, (n, 3))
    truth = yaw_pose(rng.uniform(-np.pi, np.pi), rng.uniform(-5, 5, 3))
    global_ = local @ truth[:3, :3].T + truth[:3, 3] + rng.normal(0, 0.05, (n, 3))
    global_[: min(wrong, n)] += rng.uniform(-2, 2, (min(wrong, n), 3))  # planted wrong pairs
    up = None if six_dof else np.array([0.0, 0.0, 1.0])
    config = VerificationConfig()
    found = consensus(local, global_, up, up, config)
    inliers, pose = _literal_consensus(local, global_, up, config)
    assert found.inliers.tolist() == inliers.tolist()
    assert (found.pose is None) == (pose is None)
    if pose is not None:
        np.testing.assert_allclose(found.pose, pose, atol=1e-9)


def _literal_extend(pose, local_xyz, pairs, candidates, global_xyz, config):
    """Guided matching as `MapSupport` states it, by brute force (the reference)."""
    inside = {l for _, l in pairs}
    if len(inside) == len(local_xyz):
        return list(pairs), 0, 0
    moved = local_xyz @ pose[:3, :3].T + pose[:3, 3]
    entries, conflicts = [], 0
    for r in range(len(local_xyz)):
        if r in inside:
            continue
        gaps = np.linalg.norm(global_xyz[candidates[r]] - moved[r], axis=1)
        conflicts += not np.any(gaps < config.conflict_radius)
        entries += [(gap, r, c) for c, gap in enumerate(gaps) if gap < config.inlier_tolerance]
    used_g, added = {g for g, _ in pairs}, []
    for _, r, c in sorted(entries):
        g = int(candidates[r][c])
        if g not in used_g and r not in inside:
            added.append((g, r))
            used_g.add(g)
            inside.add(r)
    return sorted([*pairs, *added], key=lambda p: p[1]), len(added), conflicts


@settings(max_examples=60)
@given(
    seed=st.integers(0, 10_000),
    n_local=st.integers(1, 7),
    n_global=st.integers(1, 60),
    axis=st.sampled_from([None, 0, 1, 2]),
)
def test_guided_matching_is_the_literal_greedy_one(seed, n_local, n_global, axis):
    """Whichever axis the candidates are sorted along (the map's longest, found or given:
    it only narrows the search), the answer is the literal greedy one."""
    rng = np.random.default_rng(seed)
    global_xyz = rng.uniform(0, 3, (n_global, 3))
    global_xyz[: n_global // 4] = global_xyz[0]  # duplicated positions: ties
    local_xyz = rng.uniform(0, 3, (n_local, 3))
    candidates = [
        np.sort(rng.choice(n_global, rng.integers(0, n_global + 1), replace=False))
        for _ in range(n_local)
    ]
    config = VerificationConfig(inlier_tolerance=0.6, conflict_radius=0.8)
    support = MapSupport(candidates, global_xyz, config, axis=axis)
    poses = np.stack([yaw_pose(rng.uniform(-0.3, 0.3), rng.normal(0, 0.2, 3)) for _ in range(4)])
    sets = []
    for _ in range(4):
        inside = rng.choice(n_local, rng.integers(0, n_local + 1), replace=False)
        sets.append([(int(rng.integers(n_global)), int(l)) for l in sorted(inside)])
    found = support.extend_many(poses, local_xyz, sets)
    for pose, pairs, got in zip(poses, sets, found):
        assert got == _literal_extend(pose, local_xyz, pairs, candidates, global_xyz, config)


def test_guided_matching_after_reassigned_candidates_is_that_of_the_final_ones():
    """A Localizer keeps one MapSupport and assigns an object's candidates again when it is
    re-detected: the answers are those of a MapSupport built from the final candidates."""
    rng = np.random.default_rng(3)
    global_xyz = rng.uniform(0, 4, (40, 3))
    local_xyz = rng.uniform(0, 4, (5, 3))
    final = [np.sort(rng.choice(40, 12, replace=False)) for _ in range(5)]
    config = VerificationConfig(inlier_tolerance=0.8, conflict_radius=1.0)
    kept = MapSupport([], global_xyz, config)
    for j in range(len(final)):
        kept.assign(j, np.arange(j, 40, 3))  # first detection: other candidates
        if j:
            kept.assign(j - 1, final[j - 1])  # the previous object re-detected
    kept.assign(4, final[4])
    poses = np.stack([yaw_pose(rng.uniform(-0.2, 0.2), rng.normal(0, 0.1, 3)) for _ in range(3)])
    sets = [[(0, 0)], [(5, 1), (7, 3)], []]
    fresh = MapSupport(final, global_xyz, config).extend_many(poses, local_xyz, sets)
    assert kept.extend_many(poses, local_xyz, sets) == fresh
    for pose, pairs, got in zip(poses, sets, fresh):
        assert got == _literal_extend(pose, local_xyz, pairs, final, global_xyz, config)
