"""Every rule of the decision (`semloc.decision`), each just inside and just outside its threshold.

The hypotheses are built by hand with the confidence, evidence, residual, fitness and score each
case needs, and the thresholds are read from `DecisionConfig` (the default one and a second one
with every threshold moved), so that the tests hold whatever the shipped confidence model's
coefficients or features are.  A case "at t + EPS" or "at t - EPS" sits a hair beside the
threshold t on either side; each asserts the status and the key part of the reason.

Rules, in the order `decide` applies them: no hypotheses; the best's pose; `min_pairs`;
`min_fitness`; then either the confidence (`_by_confidence`: `min_confidence`, a rival place
whose centres fit nearly as well, a rival within `RIVAL_LOGIT_GAP` of the evidence named as the
reason) or, without a confidence (the baselines), dominance over every rival (`_dominates`, per
`rank_by`).  Rivals are other places sharing less than `rival_overlap` of the pairs
(`is_rival`, `_different`); `same_place` / `distinct` say which candidates are one place.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from semloc.decision import (
    _KEY_EPS,
    FEATURES,
    RESIDUAL_RANK,
    RIVAL_LOGIT_GAP,
    SEARCH_CUT,
    ConfidenceModel,
    Decision,
    DecisionConfig,
    _different,
    _dominates,
    cut_search,
    decide,
    distinct,
    duplicates,
    is_rival,
    local_anchor,
    rank,
    rank_places,
    same_place,
    same_place_index,
    score_confidence,
    shipped_model,
    verdict_refinements,
)
from semloc.results import Hypothesis
from semloc.transforms import pose_error, yaw_pose

EPS = 1e-9
CONFIGS = [
    DecisionConfig(),
    DecisionConfig(
        min_pairs=4,
        min_fitness=0.55,
        min_confidence=0.8,
        margin=1.0,
        residual_floor=0.05,
        rival_overlap=0.75,
        distinct_rotation_deg=5.0,
        distinct_translation=0.5,
    ),
]
IDS = ["default", "moved"]
HERE = yaw_pose(0.0)
ELSEWHERE = yaw_pose(2.0, [-6.0, 3.0, 0.0])


def pairs(n: int, start: int = 0) -> list[tuple[str, str]]:
    """n pairs of local objects l0.. with map objects g{start}.. (other `start`: another place)."""
    return [(f"g{start + i}", f"l{i}") for i in range(n)]


def shared(best: list, n: int, k: int) -> list[tuple[str, str]]:
    """n pairs of which the first k are `best`'s (the others match the rest elsewhere)."""
    return best[:k] + [(f"x{i}", f"l{i}") for i in range(k, n)]


def sure(config: DecisionConfig, n: int | None = None, **fields) -> Hypothesis:
    """A best hypothesis that passes every rule of `config` with room to spare."""
    values = dict(
        score=10.0,
        fitness=max(config.min_fitness, 0.9),
        residual=0.05,
        confidence=min(config.min_confidence + 0.05, 1.0),
        evidence=3.0,
    )
    values |= fields
    n = config.min_pairs + 1 if n is None else n
    return Hypothesis(1, values.pop("score"), pairs(n), HERE, **values)


def bare(config: DecisionConfig, n: int | None = None, **fields) -> Hypothesis:
    """A best hypothesis without a confidence (as the baselines make), otherwise `sure`."""
    return sure(config, n, **({"confidence": None, "evidence": None} | fields))


def rival(
    best: Hypothesis, rank: int = 2, n: int | None = None, k: int = 0, **fields
) -> Hypothesis:
    """Another place (sharing k of `best`'s pairs), by default as good as `best` in every term."""
    n = len(best.pairs) if n is None else n
    values = dict(
        score=best.score,
        fitness=best.fitness,
        residual=best.residual,
        confidence=best.confidence,
        evidence=best.evidence,
    )
    values |= fields
    return Hypothesis(rank, values.pop("score"), shared(best.pairs, n, k), ELSEWHERE, **values)


def threshold(best_residual: float | None, config: DecisionConfig) -> float:
    """The residual above which a rival with as many pairs is dominated."""
    return (1.0 + config.margin) * (best_residual or 0.0) + config.residual_floor


def first_variant_share(n: int, config: DecisionConfig) -> int:
    """The fewest shared pairs of n that make another hypothesis a variant, not a rival."""
    return math.ceil(config.rival_overlap * n - 1e-12)


# no hypotheses, no pose ----------------------------------------------------------------------
def test_no_hypotheses_fail_with_the_reason():
    assert decide([], DecisionConfig(), "evidence") == (
        "failed",
        "no association set with 2 or more pairs",
    )


@pytest.mark.parametrize("make", [sure, bare], ids=["confidence", "dominance"])
def test_failed_until_some_hypothesis_has_two_pairs(make):
    """A baseline's hypothesis may carry a pose (FPFH-RANSAC's) with fewer than 2 pairs: still
    no association set with 2 or more pairs."""
    config = DecisionConfig(min_pairs=2)
    fewer = [make(config, 1), make(config, 0)]
    assert decide(fewer, config, "score") == ("failed", "no association set with 2 or more pairs")
    assert decide([make(config, 2)], config, "score") == ("localized", "")
    status, reason = decide([*fewer, make(config, 2)], config, "score")
    assert status == "ambiguous"
    assert reason == "too few pairs: the best hypothesis has 1 agreeing pairs, 2 needed"


@pytest.mark.parametrize("make", [sure, bare], ids=["confidence", "dominance"])
@pytest.mark.parametrize("config", CONFIGS, ids=IDS)
def test_a_best_without_a_pose_is_ambiguous(config, make):
    best = make(config)
    assert decide([best], config, "evidence") == ("localized", "")
    best.pose = None
    status, reason = decide([best], config, "evidence")
    assert status == "ambiguous" and reason == "the best hypothesis's pose is under-determined"


# min_pairs -----------------------------------------------------------------------------------
@pytest.mark.parametrize("make", [sure, bare], ids=["confidence", "dominance"])
@pytest.mark.parametrize("config", CONFIGS, ids=IDS)
def test_min_pairs_just_inside_and_outside(config, make):
    n = config.min_pairs
    assert decide([make(config, n)], config, "evidence") == ("localized", "")
    status, reason = decide([make(config, n - 1)], config, "evidence")
    assert status == "ambiguous"
    assert reason == (f"too few pairs: the best hypothesis has {n - 1} agreeing pairs, {n} needed")


def test_min_pairs_comes_before_the_confidence():
    config = DecisionConfig(min_pairs=5)
    best = sure(config, 4, confidence=1.0)
    assert decide([best], config, "evidence").reason.startswith("too few pairs: ")


# min_fitness ---------------------------------------------------------------------------------
@pytest.mark.parametrize("make", [sure, bare], ids=["confidence", "dominance"])
@pytest.mark.parametrize("config", CONFIGS, ids=IDS)
def test_min_fitness_just_inside_and_outside(config, make):
    f = config.min_fitness
    assert decide([make(config, fitness=f)], config, "evidence") == ("localized", "")
    assert decide([make(config, fitness=f + EPS)], config, "evidence") == ("localized", "")
    status, reason = decide([make(config, fitness=f - EPS)], config, "evidence")
    assert status == "ambiguous" and reason.startswith("low fitness: ")
    assert reason.endswith(f"{f:.2f} needed")


def test_fitness_is_not_checked_without_one_or_when_off():
    config = DecisionConfig(min_fitness=0.5)
    assert decide([sure(config, fitness=None)], config, "evidence") == ("localized", "")
    off = DecisionConfig(min_fitness=0.0)
    assert decide([sure(off, fitness=0.0)], off, "evidence") == ("localized", "")


def test_min_fitness_comes_before_the_confidence():
    config = DecisionConfig(min_fitness=0.5)
    low = sure(config, fitness=0.2, confidence=1.0)
    assert decide([low], config, "evidence").reason == (
        "low fitness: 0.20 of the local points land on the map, 0.50 needed"
    )


# min_confidence ------------------------------------------------------------------------------
@pytest.mark.parametrize("config", CONFIGS, ids=IDS)
def test_min_confidence_just_inside_and_outside(config):
    c = config.min_confidence
    assert decide([sure(config, confidence=c)], config, "evidence") == ("localized", "")
    status, reason = decide([sure(config, confidence=c - EPS)], config, "evidence")
    assert status == "ambiguous"
    assert reason == f"low confidence: {c - EPS:.2f} < {c:.2f}"


def test_a_low_confidence_is_not_rescued_by_dominance():
    """With a confidence, dominance over the rivals does not make the answer: there are none."""
    config = DecisionConfig(min_confidence=0.9)
    alone = sure(config, confidence=0.5, score=100.0)
    assert decide([alone], config, "score") == ("ambiguous", "low confidence: 0.50 < 0.90")


def test_a_missing_confidence_is_the_dominance_path_not_a_low_confidence():
    config = DecisionConfig(min_confidence=0.9)
    assert decide([bare(config)], config, "evidence") == ("localized", "")


# the confidence path: a rival place whose centres fit nearly as well ----------------------
@pytest.mark.parametrize("config", CONFIGS, ids=IDS)
def test_a_sure_best_with_a_rival_whose_centres_fit_nearly_as_well_is_ambiguous(config):
    best = sure(config, residual=0.1)
    limit = threshold(best.residual, config)
    status, reason = decide([best, rival(best, residual=limit - EPS)], config, "evidence")
    assert status == "ambiguous"
    assert reason.startswith(
        "a rival place within the margin: rank 2 fits the centres nearly "
        f"as well ({len(best.pairs)} pairs, residual {limit - EPS:.2f} m)"
    )
    assert decide([best, rival(best, residual=limit + EPS)], config, "evidence") == (
        "localized",
        "",
    )


def test_a_rival_whose_centres_fit_exactly_is_named_with_its_residual_of_zero():
    config = DecisionConfig()
    best = sure(config, residual=0.0)
    status, reason = decide([best, rival(best)], config, "evidence")
    assert status == "ambiguous" and reason.endswith(f"({len(best.pairs)} pairs, residual 0.00 m)")


@pytest.mark.parametrize("config", CONFIGS, ids=IDS)
def test_the_confidence_paths_rival_rule_is_judged_by_pairs_then_residual(config):
    best = sure(config, residual=0.1)
    n = len(best.pairs)
    close = threshold(best.residual, config) / 2  # would be a rival with as many pairs
    fewer = rival(best, n=n - 1, residual=close)
    assert decide([best, fewer], config, "evidence") == ("localized", "")
    assert decide([best, rival(best, residual=None)], config, "evidence") == ("localized", "")
    assert decide([best, rival(best, residual=close)], config, "evidence")[0] == "ambiguous"
    # a best without a residual counts as 0: a rival within the floor still ties
    exact = sure(config, residual=None)
    tie = rival(exact, residual=config.residual_floor - EPS)
    assert decide([exact, tie], config, "evidence")[0] == "ambiguous"
    apart = rival(exact, residual=config.residual_floor + EPS)
    assert decide([exact, apart], config, "evidence") == ("localized", "")


@pytest.mark.parametrize("config", CONFIGS, ids=IDS)
def test_the_confidence_paths_rival_must_be_another_place(config):
    best = sure(config, n=4, residual=0.1)
    k = first_variant_share(4, config)
    close = dict(residual=best.residual, evidence=best.evidence + 1.0)
    variant = rival(best, k=k, **close)  # shares enough of the pairs: the same answer
    assert decide([best, variant], config, "evidence") == ("localized", "")
    other = rival(best, k=k - 1, **close)
    status, reason = decide([best, other], config, "evidence")
    assert status == "ambiguous" and "rank 2 fits the centres nearly as well" in reason


def test_the_first_close_rival_is_named():
    config = DecisionConfig()
    best = sure(config, residual=0.1)
    far = rival(best, 2, residual=threshold(0.1, config) + 0.5)
    near = rival(best, 3, residual=0.1)
    status, reason = decide([best, far, near], config, "evidence")
    assert status == "ambiguous"
    assert reason.startswith("a rival place within the margin: rank 3 fits the centres")


# the confidence path: a rival within RIVAL_LOGIT_GAP is named as the reason --------------
@pytest.mark.parametrize("config", CONFIGS, ids=IDS)
def test_a_rival_within_the_logit_gap_is_named(config):
    c = config.min_confidence - 0.1
    best = sure(config, confidence=c, evidence=1.0)
    at = best.evidence - RIVAL_LOGIT_GAP
    status, reason = decide([best, rival(best, evidence=at + EPS)], config, "evidence")
    assert status == "ambiguous"
    assert reason == (
        f"a rival place within the margin: rank 2 has nearly the same evidence "
        f"(confidence {c:.2f} < {config.min_confidence:.2f})"
    )
    status, reason = decide([best, rival(best, evidence=at - EPS)], config, "evidence")
    assert status == "ambiguous"
    assert reason == f"low confidence: {c:.2f} < {config.min_confidence:.2f}"


@pytest.mark.parametrize("config", CONFIGS, ids=IDS)
def test_a_variant_within_the_logit_gap_is_not_named(config):
    best = sure(config, n=4, confidence=config.min_confidence - 0.1, evidence=1.0)
    k = first_variant_share(4, config)
    variant = rival(best, k=k, evidence=best.evidence)
    assert decide([best, variant], config, "evidence")[1].startswith("low confidence: ")
    other = rival(best, k=k - 1, evidence=best.evidence)
    assert decide([best, other], config, "evidence")[1].startswith("a rival place within the")


def test_the_named_rival_is_judged_by_the_share_of_the_bests_pairs():
    """`is_rival(best, other)`: a smaller set sharing one of the best's four pairs is a rival
    here (1 < 0.5 x 4), though it shares half of its own pairs (no rival by `_different`)."""
    config = DecisionConfig(rival_overlap=0.5)
    best = sure(config, n=4, confidence=config.min_confidence - 0.1, evidence=1.0)
    small = Hypothesis(2, 1.0, best.pairs[:1] + [("x9", "l9")], ELSEWHERE, evidence=1.0)
    assert "rank 2 has nearly the same evidence" in decide([best, small], config, "evidence")[1]


def test_without_evidence_no_rival_is_named():
    config = DecisionConfig()
    best = sure(config, confidence=config.min_confidence - 0.1, evidence=None)
    other = rival(best, evidence=5.0)
    assert decide([best, other], config, "evidence")[1].startswith("low confidence: ")
    best.evidence, other.evidence = 1.0, None
    assert decide([best, other], config, "evidence")[1].startswith("low confidence: ")


# the dominance path (no confidence): _dominates per rank_by ------------------------------
def dominance_reason(rank: int, rank_by: str) -> str:
    return f"a rival place within the margin (rank {rank}, {rank_by})"


@pytest.mark.parametrize("config", CONFIGS, ids=IDS)
def test_score_dominance_just_inside_and_outside(config):
    best = bare(config, score=3.0)
    at = best.score / (1.0 + config.margin)
    assert _dominates(best, rival(best, score=at - EPS), "score", config)
    assert not _dominates(best, rival(best, score=at + EPS), "score", config)
    assert decide([best, rival(best, score=at - EPS)], config, "score") == ("localized", "")
    assert decide([best, rival(best, score=at + EPS)], config, "score") == (
        "ambiguous",
        dominance_reason(2, "score"),
    )


@pytest.mark.parametrize("config", CONFIGS, ids=IDS)
def test_fitness_dominance_just_inside_and_outside(config):
    best = bare(config, fitness=0.9)
    at = best.fitness / (1.0 + config.margin)
    assert decide([best, rival(best, fitness=at - EPS)], config, "fitness") == ("localized", "")
    assert decide([best, rival(best, fitness=at + EPS)], config, "fitness") == (
        "ambiguous",
        dominance_reason(2, "fitness"),
    )
    # no fitness counts as 0: a rival without one is dominated, a best without one is not
    assert decide([best, rival(best, fitness=None)], config, "fitness") == ("localized", "")
    unmeasured = bare(config, fitness=None)
    assert decide([unmeasured, rival(unmeasured, fitness=EPS)], config, "fitness")[0] == (
        "ambiguous"
    )


@pytest.mark.parametrize("rank_by", ["residual", "evidence"])
@pytest.mark.parametrize("config", CONFIGS, ids=IDS)
def test_residual_dominance_just_inside_and_outside(config, rank_by):
    """rank_by residual (and evidence, for hypotheses without a confidence): more pairs, or as
    many and a residual above (1 + margin) x the best's + residual_floor."""
    best = bare(config, residual=0.1)
    limit = threshold(best.residual, config)
    assert decide([best, rival(best, residual=limit + EPS)], config, rank_by) == ("localized", "")
    assert decide([best, rival(best, residual=limit - EPS)], config, rank_by) == (
        "ambiguous",
        dominance_reason(2, rank_by),
    )
    n = len(best.pairs)
    assert decide([best, rival(best, n=n - 1, residual=0.0)], config, rank_by) == ("localized", "")
    assert decide([best, rival(best, residual=None)], config, rank_by) == ("localized", "")
    exact = bare(config, residual=None)  # counts as 0
    assert (
        decide([exact, rival(exact, residual=config.residual_floor - EPS)], config, rank_by)[0]
        == "ambiguous"
    )
    assert (
        decide([exact, rival(exact, residual=config.residual_floor + EPS)], config, rank_by)[0]
        == "localized"
    )


@pytest.mark.parametrize("rank_by", ["score", "fitness", "residual", "evidence"])
def test_dominates_is_not_fooled_by_the_other_terms(rank_by):
    """Each ranking is judged in its own terms only: a rival as good in that term and far worse
    in the others is not dominated."""
    config = DecisionConfig()
    best = bare(config, score=5.0, fitness=0.9, residual=0.1)
    worse = dict(score=0.1, fitness=0.01, residual=5.0)
    term = {"score": "score", "fitness": "fitness"}.get(rank_by, "residual")
    tie = rival(best, **(worse | {term: getattr(best, term)}))
    assert not _dominates(best, tie, rank_by, config)
    assert _dominates(best, rival(best, **worse), rank_by, config)


@pytest.mark.parametrize("rank_by", ["score", "fitness", "residual", "evidence"])
def test_every_rival_must_be_dominated(rank_by):
    config = DecisionConfig()
    best = bare(config, score=5.0, fitness=0.9, residual=0.1)
    beaten = rival(best, 2, score=0.1, fitness=0.01, residual=5.0)
    close = rival(best, 3)
    assert decide([best, beaten], config, rank_by) == ("localized", "")
    assert decide([best, beaten, close], config, rank_by) == (
        "ambiguous",
        dominance_reason(3, rank_by),
    )


@pytest.mark.parametrize("rank_by", ["score", "fitness", "residual"])
@pytest.mark.parametrize("config", CONFIGS, ids=IDS)
def test_a_variant_of_the_best_needs_no_dominating(config, rank_by):
    """`_different`: a rival shares less than `rival_overlap` of the smaller one's pairs."""
    best = bare(config, n=4)
    k = first_variant_share(4, config)
    assert decide([best, rival(best, k=k)], config, rank_by) == ("localized", "")
    assert decide([best, rival(best, k=k - 1)], config, rank_by)[0] == "ambiguous"
    if rank_by == "residual":
        return  # fewer pairs are dominated in its terms anyway
    # the smaller one's share decides: 2 pairs sharing one of the best's 4
    small = Hypothesis(
        2,
        best.score,
        best.pairs[:1] + [("x9", "l9")],
        ELSEWHERE,
        fitness=best.fitness,
        residual=best.residual,
    )
    expected = "localized" if config.rival_overlap * 2 <= 1 else "ambiguous"
    assert decide([best, small], config, rank_by)[0] == expected


# is_rival / _different -----------------------------------------------------------------------
PAIR_SETS = st.sets(st.tuples(st.sampled_from("abcdefgh"), st.sampled_from("1234")), max_size=8)


def test_is_rival_just_inside_and_outside():
    four = pairs(4)
    for overlap in (0.25, 0.5, 0.75, 1.0):
        k = first_variant_share(4, DecisionConfig(rival_overlap=overlap))
        assert is_rival(four, shared(four, 4, k - 1), overlap)
        assert not is_rival(four, shared(four, 4, k), overlap)


@settings(max_examples=200)
@given(a=PAIR_SETS, b=PAIR_SETS, overlap=st.floats(0, 1))
def test_is_rival_limits_and_symmetry(a, b, overlap):
    a, b = sorted(a), sorted(b)
    assert not is_rival(a, b, 0.0)  # overlap 0: nothing is a rival
    assert not is_rival(a, a, overlap)  # never its own rival
    assert is_rival(a, b, 1.0) == (bool(a) and not set(a) <= set(b))  # 1: all of it shared
    if a and not set(a) & set(b) and overlap > 0:
        assert is_rival(a, b, overlap)  # nothing shared
    if len(a) == len(b):
        assert is_rival(a, b, overlap) == is_rival(b, a, overlap)
    if is_rival(a, b, overlap):  # monotone in the overlap
        assert is_rival(a, b, min(1.0, overlap + 0.1))
    one, other = Hypothesis(1, 1.0, a, HERE), Hypothesis(2, 1.0, b, HERE)
    assert _different(one, other, overlap) == _different(other, one, overlap)
    assert _different(one, other, overlap) == (is_rival(a, b, overlap) and is_rival(b, a, overlap))


# same_place / distinct -----------------------------------------------------------------------
@pytest.mark.parametrize("config", CONFIGS, ids=IDS)
def test_same_place_just_inside_and_outside(config):
    deg, metres = config.distinct_rotation_deg, config.distinct_translation
    here = ((), HERE)

    def at(theta_deg: float, shift: float) -> tuple:
        return ((), yaw_pose(np.radians(theta_deg), [shift, 0.0, 0.0]))

    assert same_place(at(deg - 1e-6, 0.0), here, config)
    assert not same_place(at(deg + 1e-6, 0.0), here, config)
    assert same_place(at(0.0, metres - EPS), here, config)
    assert not same_place(at(0.0, metres + EPS), here, config)
    assert not same_place(((), None), here, config) and not same_place(here, ((), None), config)


@pytest.mark.parametrize("config", CONFIGS, ids=IDS)
@pytest.mark.parametrize("anchor", [None, np.array([2.0, -1.0, 0.5])])
def test_same_place_index_just_inside_and_outside(config, anchor):
    """The compiled screen of `distinct` draws the bounds where `same_place` does."""
    deg, metres = config.distinct_rotation_deg, config.distinct_translation
    far = yaw_pose(np.radians(90.0), [5.0, 0.0, 0.0])

    def at(theta_deg: float, shift: float) -> np.ndarray:
        pose = yaw_pose(np.radians(theta_deg))
        point = np.zeros(3) if anchor is None else anchor
        pose[:3, 3] = point - pose[:3, :3] @ point + [shift, 0.0, 0.0]  # shift at the anchor
        return pose

    for pose, inside in [(at(deg - 1e-6, 0.0), True), (at(deg + 1e-6, 0.0), False),
                         (at(0.0, metres - EPS), True), (at(0.0, metres + EPS), False)]:  # fmt: skip
        assert same_place(((), pose), ((), HERE), config, anchor) is inside
        assert same_place_index(pose, np.stack([far, HERE]), config, anchor) == (
            1 if inside else None
        )
    assert same_place_index(HERE, np.zeros((0, 4, 4)), config, anchor) is None


@pytest.mark.parametrize("config", CONFIGS, ids=IDS)
def test_same_place_exactly_at_the_thresholds_is_another_place(config):
    """A pose exactly `distinct_rotation_deg` or exactly `distinct_translation` from another
    is another place (the thresholds are strict); the rotation threshold is set to the angle
    `pose_error` measures, so the case sits exactly on it."""
    turned = yaw_pose(np.radians(config.distinct_rotation_deg))
    exact = config.model_copy(update={"distinct_rotation_deg": pose_error(turned, HERE)[0]})
    assert not same_place(((), turned), ((), HERE), exact)
    shifted = yaw_pose(0.0, [config.distinct_translation, 0.0, 0.0])
    assert pose_error(shifted, HERE)[1] == config.distinct_translation
    assert not same_place(((), shifted), ((), HERE), config)


def test_duplicates_counts_the_posed_hypotheses_at_a_better_ones_place():
    config = DecisionConfig()
    near = yaw_pose(0.0, [0.1, 0.0, 0.0])
    ranked = [
        Hypothesis(1, 1.0, pairs(3), HERE),
        Hypothesis(2, 1.0, pairs(3, 10), None),  # no pose: not counted
        Hypothesis(3, 1.0, pairs(3, 20), ELSEWHERE),
        Hypothesis(4, 1.0, pairs(3, 30), near),  # at the best's place
        Hypothesis(5, 1.0, pairs(3, 40), ELSEWHERE),  # at rank 3's
    ]
    assert duplicates(ranked, config, None) == 2
    assert duplicates(ranked[:3], config, None) == 0
    turned = [Hypothesis(1, 1.0, pairs(3), HERE), Hypothesis(2, 1.0, pairs(3, 10), yaw_pose(0.02))]
    assert duplicates(turned, config, None) == 1  # 1.1 deg and no shift at the origin
    assert duplicates(turned, config, np.array([30.0, 0.0, 0.0])) == 0  # 0.6 m apart there


def test_same_place_by_pairs():
    config = DecisionConfig()
    four = pairs(4)
    assert same_place((four[:2], ELSEWHERE), (four, HERE), config)  # a subset: the same answer
    assert same_place((four[:2], None), (four, None), config)
    assert not same_place((shared(four, 2, 1), ELSEWHERE), (four, HERE), config)
    assert not same_place(([], ELSEWHERE), (four, HERE), config)  # no pairs: the pose decides
    assert same_place((shared(four, 2, 1), HERE), (four, HERE), config)  # the pose does


def test_same_place_compares_translations_at_the_anchor():
    config = DecisionConfig(distinct_translation=0.3)
    a, b = ((), yaw_pose(0.0)), ((), yaw_pose(np.radians(1.0)))
    assert same_place(a, b, config, np.zeros(3))
    assert not same_place(a, b, config, np.array([30.0, 0.0, 0.0]))  # 0.52 m apart there


ANGLES = st.floats(-math.pi, math.pi)
SHIFTS = st.tuples(*[st.floats(-20, 20)] * 3)


@settings(max_examples=150)
@given(
    theta=ANGLES,
    t=SHIFTS,
    d_theta=st.floats(-0.4, 0.4),
    dt=st.tuples(*[st.floats(-1, 1)] * 3),
    anchor=SHIFTS,
    s_theta=ANGLES,
    s_t=SHIFTS,
)
def test_same_place_does_not_depend_on_the_local_frames_origin(
    theta, t, d_theta, dt, anchor, s_theta, s_t
):
    """Re-expressing the local frame by S (x = S x') turns poses P into P S and the anchor p into
    S^-1 p: the verdict stays the same."""
    config = DecisionConfig()
    a = yaw_pose(theta, t)
    b = yaw_pose(theta + d_theta, np.add(t, dt))
    p = np.asarray(anchor)
    shift = np.linalg.norm((a - b) @ np.append(p, 1.0))
    assume(abs(abs(np.degrees(d_theta)) - config.distinct_rotation_deg) > 1e-6)
    assume(abs(shift - config.distinct_translation) > 1e-6)
    s = yaw_pose(s_theta, s_t)
    moved = (np.linalg.inv(s) @ np.append(p, 1.0))[:3]
    assert same_place(((), a), ((), b), config, p) == same_place(
        ((), a @ s), ((), b @ s), config, moved
    )


@settings(max_examples=100)
@given(
    places=st.lists(
        st.tuples(
            st.sets(st.sampled_from(pairs(4) + pairs(4, start=10)), max_size=4),
            st.one_of(st.none(), st.tuples(st.floats(-0.4, 0.4), st.floats(-0.6, 0.6))),
        ),
        max_size=8,
    ),
    top_k=st.integers(1, 8),
    anchored=st.booleans(),
)
def test_distinct_is_a_greedy_walk_by_same_place(places, top_k, anchored):
    """`distinct` (batched) picks exactly what a walk testing `same_place` against every earlier
    pick picks."""
    config = DecisionConfig()
    anchor = np.array([3.0, -1.0, 0.5]) if anchored else None
    made = [(sorted(p), None if q is None else yaw_pose(q[0], [q[1], 0.0, 0.0])) for p, q in places]
    expected: list[int] = []
    for i, place in enumerate(made):
        if len(expected) == top_k:
            break
        if not any(same_place(place, made[j], config, anchor) for j in expected):
            expected.append(i)
    assert distinct(iter(made), top_k, config, anchor) == expected


def test_distinct_just_inside_and_outside_and_stops_at_top_k():
    config = DecisionConfig()
    deg, metres = config.distinct_rotation_deg, config.distinct_translation
    places = [
        (pairs(3), HERE),
        (pairs(2), ELSEWHERE),  # a subset of the first: skipped
        ([], yaw_pose(np.radians(deg - 1e-6))),  # the same place: skipped
        ([], yaw_pose(0.0, [metres - EPS, 0, 0])),  # the same place: skipped
        ([], yaw_pose(np.radians(deg + 1e-6))),  # another place
        ([], yaw_pose(0.0, [metres + EPS, 0, 0])),  # another place
        (pairs(3, start=5), None),  # another place
    ]
    assert distinct(places, 10, config) == [0, 4, 5, 6]
    consumed = []

    def lazily():
        for i, place in enumerate(places):
            consumed.append(i)
            yield place

    assert distinct(lazily(), 2, config) == [0, 4]
    assert consumed == [0, 1, 2, 3, 4]  # nothing computed beyond the last pick


# decide never says localized for less than it needs ---------------------------------------
@settings(max_examples=200)
@given(
    n=st.integers(2, 6),
    fitness=st.one_of(st.none(), st.floats(0, 1)),
    confidence=st.one_of(st.none(), st.floats(0, 1)),
    rival_residual=st.one_of(st.none(), st.floats(0, 1)),
    rank_by=st.sampled_from(["evidence", "residual", "score", "fitness"]),
)
def test_localized_only_when_every_rule_holds(n, fitness, confidence, rival_residual, rank_by):
    config = CONFIGS[1]
    best = Hypothesis(
        1, 3.0, pairs(n), HERE, fitness=fitness, residual=0.1, confidence=confidence, evidence=2.0
    )
    other = rival(best, n=n, residual=rival_residual, evidence=-5.0)
    status, reason = decide([best, other], config, rank_by)
    assert (status == "localized") == (reason == "")
    if status == "localized":
        assert n >= config.min_pairs
        assert fitness is None or fitness >= config.min_fitness
        assert confidence is None or confidence >= config.min_confidence
        assert confidence is not None or rank_by != "score"  # the rival's score ties
        if confidence is None and rank_by == "fitness":
            assert fitness is None  # 0 against 0 dominates; a fitness ties
        else:  # the confidence path and the residual ranking judge the residual
            assert rival_residual is None or rival_residual > threshold(0.1, config)


def test_distinct_takes_any_top_k():
    """A huge `top_k` (a user's setting) costs nothing up front; more places than the first
    buffer holds are all compared."""
    config = DecisionConfig()
    places = [((), yaw_pose(0.0, [float(i), 0.0, 0.0])) for i in range(40)]
    places.append(((), yaw_pose(0.0, [3.1, 0.0, 0.0])))  # the same place as the fourth
    assert distinct(places, 10**15, config) == list(range(40))


@pytest.mark.parametrize("top_k", [0, -1])
def test_distinct_picks_nothing_when_asked_for_nothing(top_k):
    places = [((), yaw_pose(0.0, [float(i), 0.0, 0.0])) for i in range(3)]
    assert distinct(places, top_k, DecisionConfig()) == []
    assert distinct(places, 1, DecisionConfig()) == [0]


# exactly at each boundary (values whose products are exact in binary) ------------------------
def test_dominance_exactly_at_the_margin_is_dominance_by_score_and_fitness():
    """score / fitness: the best dominates a rival of exactly 1 / (1 + margin) of it."""
    config = DecisionConfig(margin=0.5)
    best = bare(config, score=3.0, fitness=0.75)
    assert _dominates(best, rival(best, score=2.0), "score", config)
    assert _dominates(best, rival(best, fitness=0.5), "fitness", config)
    assert decide([best, rival(best, score=2.0)], config, "score") == ("localized", "")


def test_a_rival_exactly_at_the_residual_threshold_is_not_dominated():
    config = DecisionConfig()
    best = bare(config, residual=0.1)
    at = rival(best, residual=threshold(best.residual, config))
    assert not _dominates(best, at, "residual", config)
    assert decide([best, at], config, "residual")[0] == "ambiguous"


def test_a_rival_exactly_at_the_logit_gap_is_named():
    config = DecisionConfig()
    best = sure(config, confidence=config.min_confidence - 0.1, evidence=1.0)
    at = rival(best, evidence=best.evidence - RIVAL_LOGIT_GAP)
    assert "rank 2 has nearly the same evidence" in decide([best, at], config, "evidence")[1]


def test_a_rival_outside_the_prior_does_not_count_against_a_best_inside_it():
    """With a prior, a place outside it is wrong if the prior holds: it is no rival."""
    config = DecisionConfig()
    for make in (sure, bare):
        best = make(config, outside_prior=False)
        twin = rival(best, outside_prior=True)
        assert decide([best, twin], config, "residual") == ("localized", "")
        twin.outside_prior = False
        assert decide([best, twin], config, "residual")[0] == "ambiguous"


def test_a_variant_does_not_lower_the_confidence_a_rival_does():
    """`score_confidence`: the rival of a hypothesis is the best evidence among the others
    that share less than `rival_overlap` of its pairs; a variant (sharing more) is the same
    answer and leaves its confidence as without a rival."""
    model = shipped_model()
    features = {"n_pairs": 6.0, "rejected_share": 0.0, "residual": 0.05, "fitness": 0.9,
                "n_support": 6.0, "conflict_share": 0.0}  # fmt: skip
    assert set(features) == set(FEATURES)
    best = Hypothesis(1, 1.0, pairs(4), HERE, features=features)
    variant = Hypothesis(2, 1.0, shared(best.pairs, 4, 2), ELSEWHERE,
                         features=features | {"n_pairs": 9.0})  # fmt: skip
    score_confidence([best, variant], model, 0.5)
    assert best.confidence == model.confidence(best.evidence, None)
    other = Hypothesis(2, 1.0, shared(best.pairs, 4, 1), ELSEWHERE,
                       features=features | {"n_pairs": 9.0})  # fmt: skip
    score_confidence([best, other], model, 0.5)
    assert best.confidence == model.confidence(best.evidence, other.evidence)
    assert best.confidence < model.confidence(best.evidence, None)


# the confidence model, ranking and the search's cut ----------------------------------------
WEIGHTS = {"n_pairs": 0.5, "rejected_share": -1.0, "residual": -2.0, "fitness": 1.0, "n_support": 0.25,
           "conflict_share": -1.5}  # fmt: skip
FEATURE_VALUES = {"n_pairs": 4.0, "rejected_share": 0.1, "residual": 0.2, "fitness": 0.8,
                  "n_support": 2.0, "conflict_share": 0.3}  # fmt: skip


def hand_model(**fields) -> ConfidenceModel:
    values = dict(evidence_bias=-1.0, evidence_weights=WEIGHTS, confidence_bias=0.1,
                  confidence_evidence=0.7, confidence_rival=-1.3, confidence_gap=0.4,
                  min_confidence=0.9)  # fmt: skip
    return ConfidenceModel(**(values | fields))


def sigmoid(x: float) -> float:
    return 1.0 / (1.0 + math.exp(-x))


def test_the_ranking_logit_is_its_own_fit_else_the_evidence():
    dot = sum(WEIGHTS[k] * FEATURE_VALUES[k] for k in FEATURES)
    assert hand_model().ranking(FEATURE_VALUES) == pytest.approx(-1.0 + dot)
    twice = {k: 2 * w for k, w in WEIGHTS.items()}
    assert hand_model(ranking_weights=twice).ranking(FEATURE_VALUES) == pytest.approx(2 * dot)
    fitted = hand_model(ranking_weights=twice, ranking_bias=0.5)
    assert fitted.ranking(FEATURE_VALUES) == pytest.approx(0.5 + 2 * dot)


@pytest.mark.parametrize(("evidence", "rival"), [(1.5, 0.5), (1.5, None), (2.0, -6.0), (9.0, 0.0)])
def test_the_confidence_is_the_logistic_of_evidence_rival_and_gap(evidence, rival):
    r = -4.0 if rival is None else max(rival, -4.0)
    gap = min(evidence - r, 4.0)
    logit = 0.1 + 0.7 * evidence - 1.3 * sigmoid(r) + 0.4 * gap
    assert hand_model().confidence(evidence, rival) == pytest.approx(sigmoid(logit))


def test_the_confidence_bottoms_out_at_a_logit_of_minus_fifty():
    """Evidence far below any real answer's neither overflows nor goes below the confidence
    of a logit of -50 (nor above that of +50)."""
    model = hand_model(confidence_evidence=1.0, confidence_bias=0.0, confidence_rival=0.0,
                       confidence_gap=0.0)  # fmt: skip
    assert math.isclose(model.confidence(-1000.0, None), 1 / (1 + math.exp(50.0)), rel_tol=1e-9)
    assert math.isclose(model.confidence(-49.0, None), 1 / (1 + math.exp(49.0)), rel_tol=1e-9)
    assert model.confidence(1000.0, None) == 1.0


def test_local_anchor_is_the_centroid_of_the_local_objects():
    assert local_anchor(np.array([[0.0, 0, 0], [2.0, 4, 6]])) == pytest.approx([1.0, 2.0, 3.0])
    assert local_anchor(np.zeros((0, 3))) is None


def test_rank_numbers_the_hypotheses_from_one_in_order():
    hypotheses = [Hypothesis(9, score, pairs(3), HERE) for score in (1.0, 3.0, 2.0)]
    ordered = rank(hypotheses, "score")
    assert [(h.rank, h.score) for h in ordered] == [(1, 3.0), (2, 2.0), (3, 1.0)]


def featured(rank_: int, score: float, features: dict, pose=HERE, start: int = 0, **fields):
    return Hypothesis(rank_, score, pairs(4, start), pose, features=features, **fields)


def test_rank_places_orders_by_the_ranking_logit_less_the_missing_penalty():
    """The second hypothesis has the larger ranking logit (and score), but its pose expects
    three objects nobody saw beyond the gone share: it ranks second."""
    model = hand_model()
    low = featured(1, 1.0, FEATURE_VALUES)
    high = featured(
        2, 5.0, FEATURE_VALUES | {"n_pairs": 5.0}, ELSEWHERE, 10, n_missing=4, n_expected=4
    )
    kept = rank_places([high, low], "evidence", DecisionConfig(), model)
    assert kept == [low, high] and [h.rank for h in kept] == [1, 2]


def test_rank_places_merges_same_places_where_the_local_objects_are():
    """Two poses 1.1 deg apart: the same place at the origin, another 30 m off, where the
    local objects are (the anchor)."""
    turned = [
        featured(1, 2.0, FEATURE_VALUES),
        featured(2, 1.0, FEATURE_VALUES, yaw_pose(0.02), 10),
    ]
    config = DecisionConfig()
    assert len(rank_places(list(turned), "score", config, hand_model())) == 1
    far = np.array([30.0, 0.0, 0.0])
    assert len(rank_places(list(turned), "score", config, hand_model(), far)) == 2


def test_rank_places_weighs_rivals_by_the_configured_overlap():
    """Sharing 3 of 4 pairs: a variant at `rival_overlap` 0.5, a rival at 0.8."""
    model = hand_model()
    for overlap, rival_counts in [(0.5, False), (0.8, True)]:
        best = featured(1, 2.0, FEATURE_VALUES)
        other = Hypothesis(2, 1.0, shared(best.pairs, 4, 3), ELSEWHERE, features=FEATURE_VALUES)
        rank_places([best, other], "score", DecisionConfig(rival_overlap=overlap), model)
        expected = model.confidence(best.evidence, other.evidence if rival_counts else None)
        assert best.confidence == expected


def test_score_confidence_takes_a_variant_for_no_rival_by_default():
    model = hand_model()
    best = featured(1, 2.0, FEATURE_VALUES)
    variant = Hypothesis(2, 1.0, shared(best.pairs, 4, 3), ELSEWHERE, features=FEATURE_VALUES)
    score_confidence([best, variant], model)
    assert best.confidence == model.confidence(best.evidence, None)


def test_a_twin_the_view_tells_apart_is_no_rival_another_place_is():
    """`place` pairs two local objects its twin lacks: the twin is not its rival; a place
    that is not a twin, told apart alike, still is."""
    model = hand_model()

    def place(locals_: str, start: int, pose=HERE) -> Hypothesis:
        return Hypothesis(1, 1.0, [(f"g{start + i}", l) for i, l in enumerate(locals_)], pose,
                          features=FEATURE_VALUES)  # fmt: skip

    best, twin, other = place("abcde", 0), place("abc", 10, ELSEWHERE), place("abc", 20)
    score_confidence([best, twin], model, twinned=[best, twin])
    assert best.confidence == model.confidence(best.evidence, None)
    score_confidence([best, twin, other], model, twinned=[best, twin])
    assert best.confidence == model.confidence(best.evidence, other.evidence)


@pytest.mark.parametrize("reason", ["", "low fitness"])
def test_a_cut_search_says_so_first(reason):
    decision = cut_search(Decision("localized" if not reason else "ambiguous", reason), True, 5)
    assert decision.status == "ambiguous"
    why = (
        f"{SEARCH_CUT}: places as well supported as the best (5 pairs) were left out of the "
        "hypotheses, and the right one may be among them"
    )
    assert decision.reason == (why if not reason else f"{why}; {reason}")


# lazy refinement: which pending hypotheses could change the verdict --------------------------
PLAIN = {"n_pairs": 1.0, "rejected_share": 0.0, "residual": -2.0, "fitness": 1.0,
         "n_support": 0.0, "conflict_share": 0.0}  # fmt: skip
"""A model whose evidence (and ranking) is pairs + fitness - 2 residual: exact in binary."""


def gap_model(min_gap: float = 1.0) -> ConfidenceModel:
    """Evidence `PLAIN`; confidence the logistic of the gap to the strongest rival (4 without
    one), claimable from a gap of `min_gap`."""
    return ConfidenceModel(evidence_bias=0.0, evidence_weights=PLAIN, confidence_bias=0.0,
                           confidence_evidence=0.0, confidence_rival=0.0, confidence_gap=1.0,
                           min_confidence=sigmoid(min_gap))  # fmt: skip


def plain(n_pairs: float, fitness: float = 1.0, residual: float = 0.0) -> dict[str, float]:
    return {"n_pairs": n_pairs, "rejected_share": 0.0, "residual": residual, "fitness": fitness,
            "n_support": 0.0, "conflict_share": 0.0}  # fmt: skip


def place(features: dict | None, n: int = 4, start: int = 0, score: float = 1.0,
          **fields) -> Hypothesis:  # fmt: skip
    return Hypothesis(1, score, pairs(n, start), HERE, features=features, **fields)


def refinements(hypotheses, pending, min_gap: float = 1.0, **config):
    """`verdict_refinements` under `gap_model(min_gap)` (its `min_confidence` the config's),
    as indices into `hypotheses`."""
    model = gap_model(min_gap)
    config = DecisionConfig(**({"min_confidence": model.min_confidence} | config))
    found = verdict_refinements(hypotheses, pending, config, model)
    return [next(i for i, h in enumerate(hypotheses) if h is f) for f in found]


def test_no_hypotheses_need_no_refinement():
    assert verdict_refinements([], [], DecisionConfig(), gap_model()) == []


def test_a_pending_best_is_refined_first_and_alone():
    best, other = place(plain(5.0), score=2.0), place(plain(5.0), start=10)
    assert refinements([other, best], [other, best]) == [1]  # equal keys: the higher score
    assert refinements([best, other], [other]) == [1]  # refined best: the rival's turn


def test_without_features_the_best_by_score_decides_and_nothing_is_refined():
    """Hypotheses without features (a baseline's) rank last; the best by score among them is
    refined only when pending."""
    low, high = place(None, score=1.0), place(None, start=10, score=2.0)
    assert refinements([low, high], [low]) == []
    assert refinements([low, high], [low, high]) == [1]
    featured_ = place(plain(1.0, fitness=0.0), start=20)  # any features rank before none
    assert refinements([high, featured_], [high, featured_]) == [1]


@pytest.mark.parametrize(
    ("n_pairs", "refined"),
    [(2.0, True), (2.0 - 0.5e-6, True), (2.0 - 2e-6, False), (1.0, False)],
)
def test_a_pending_place_is_refined_when_at_its_best_it_could_outrank_the_best(n_pairs, refined):
    """The best ranks 4 + 1 - 4 x its 0.25 m residual = 4; a pending place at its best (ICP
    giving fitness 1, residual 0) ranks `n_pairs` + 1 + 1: from 4, less the ranking's rounding
    (`_KEY_EPS`: 1e-6), it could outrank the best.  No claim is possible (`min_confidence`
    1), so only the ranking decides."""
    best = place(plain(4.0), residual=0.25)
    pending = place(plain(n_pairs + 1.0, fitness=0.5, residual=0.5), start=10)
    assert refinements([best, pending], [pending], min_gap=math.inf) == ([1] if refined else [])


def test_a_pending_place_whose_best_case_ties_the_best_exactly_is_refined():
    """The best's bar computed as `verdict_refinements` does (its ranking less 4 x its 0.25 m
    residual and `_KEY_EPS`), and a pending place that reaches it exactly at its best."""
    bar = 5.0 - (RESIDUAL_RANK * 0.25 + _KEY_EPS)
    assert (bar - 1.0) + 1.0 == bar  # (the model's sum: pairs + fitness 1, exactly)
    best = place(plain(4.0), residual=0.25)
    tie = place(plain(bar - 1.0, fitness=0.0), start=10)
    assert refinements([best, tie], [tie], min_gap=math.inf) == [1]


@pytest.mark.parametrize(
    ("first", "second", "best"),
    [
        ((3.25, None, 1.0), (3.0, None, 2.0), 0),  # the higher ranking logit
        ((3.0000004, None, 1.0), (3.0, None, 2.0), 1),  # equal to 6 decimals: the score
        ((3.0, 0.125, 2.0), (2.75, None, 1.0), 1),  # 4 logits per metre of residual
    ],
)
def test_the_best_to_refine_is_the_one_rank_places_puts_first(first, second, best):
    """(ranking logit, residual, score) of two pending places: the one refined first is the
    best by `RANKINGS["evidence"]`: the ranking logit less 4 x the residual (None: 0), rounded
    to 6 decimals, then the score."""
    places = [place(plain(logit - 1.0), start=10 * i, score=score, residual=residual)
              for i, (logit, residual, score) in enumerate([first, second])]  # fmt: skip
    assert refinements(places, places, min_gap=math.inf) == [best]


def test_the_bests_missing_objects_lower_the_bar_for_its_rivals():
    """As above, a pending place ranking 1.5 now and 3.5 at best: short of the best's 4, but
    not of 4 less the best's missing penalty (4 expected, 3 missing: 2 beyond the gone share),
    though the best still ranks first (at 2)."""
    pending = place(plain(2.5, fitness=0.0, residual=0.5), start=10)
    clean = place(plain(4.0), residual=0.25)
    missing = place(plain(4.0), residual=0.25, n_missing=3, n_expected=4)
    assert refinements([clean, pending], [pending], min_gap=math.inf) == []
    assert refinements([missing, pending], [pending], min_gap=math.inf) == [1]


@pytest.mark.parametrize(("rival_pairs", "refined"), [(1.0, False), (1.0 + 2**-20, True)])
def test_a_pending_rival_is_refined_when_at_its_best_it_could_deny_a_claim(rival_pairs, refined):
    """The best's evidence is 3 (4 pairs, fitness 0, residual 0) and a claim needs a gap of
    1: a pending rival of three pairs that reaches 2 after ICP leaves the claim standing; a
    hair more could deny it.  It cannot outrank the best, nor contest it (fewer pairs)."""
    best = place(plain(3.0, fitness=0.0))
    rival = Hypothesis(2, 1.0, pairs(3, 10), ELSEWHERE, features=plain(rival_pairs, 0.5, 1.0))
    assert refinements([best, rival], [rival]) == ([1] if refined else [])


def test_a_refined_rival_that_denies_the_claim_makes_every_pending_rival_count():
    """A refined rival at evidence 2.5 already denies the claim (gap 0.5) while the best
    alone could claim: the verdict hangs on the rivals, and a pending one is refined however
    weak; a pending variant of the best (sharing its pairs) is no rival and is not, nor is a
    place without features (a baseline's).  With four of four expected objects missing (3
    beyond the gone share) the refined rival's evidence is -0.5: the claim stands."""
    best = place(plain(3.0, fitness=0.0))
    strong = Hypothesis(2, 1.0, pairs(3, 10), ELSEWHERE, features=plain(1.5, 1.0))
    weak = Hypothesis(3, 1.0, pairs(3, 20), ELSEWHERE, features=plain(-5.0, 0.0, 0.0))
    variant = Hypothesis(4, 1.0, shared(best.pairs, 3, 3), ELSEWHERE, features=plain(-5.0, 0.0))
    baseline = Hypothesis(5, 9.0, pairs(3, 30), ELSEWHERE)
    hypotheses = [best, strong, weak, variant, baseline]
    assert refinements(hypotheses, [weak, variant, baseline]) == [2]
    strong.n_missing, strong.n_expected = 4, 4
    assert refinements(hypotheses, [weak, variant, baseline]) == []


def test_the_bests_missing_objects_count_against_its_claim():
    """The best's evidence 3, less 1 for its missing objects (two of four expected): 2.  A
    pending rival reaching 1.5 would leave a gap of 0.5, short of the 1 a claim needs: it is
    refined; without the missing objects the gap would be 1.5 and it would not be."""
    rival = Hypothesis(2, 1.0, pairs(3, 10), ELSEWHERE, features=plain(0.5, 0.5, 1.0))
    missing = place(plain(3.0, fitness=0.0), n_missing=2, n_expected=4)
    assert refinements([missing, rival], [rival]) == [1]
    assert refinements([place(plain(3.0, fitness=0.0)), rival], [rival]) == []


def test_a_best_that_cannot_be_claimed_either_way_refines_no_rival():
    """A claim needs a gap of 5, more than the 4 a lone best counts: no rival changes that,
    and no other place contests a claim that cannot be made, however large."""
    best = place(plain(3.0, fitness=0.0))
    rival = Hypothesis(2, 1.0, pairs(3, 10), ELSEWHERE, features=plain(1.5, 1.0))
    large = Hypothesis(3, 1.0, pairs(4, 20), ELSEWHERE, features=plain(-5.0, 0.0))
    assert refinements([best, rival, large], [rival, large], min_gap=5.0) == []


def test_a_best_exactly_at_the_operating_point_can_be_claimed():
    """A claim needs a gap of 4, the most a lone best counts: a best alone is claimable
    exactly at `min_confidence`; a weak pending rival (gap still 4) that is smaller cannot
    deny or contest it, and is not refined; a pending place as large as the best contests
    the claim, and both are."""
    best = place(plain(3.0, fitness=0.0))
    weak = Hypothesis(2, 1.0, pairs(3, 10), ELSEWHERE, features=plain(-5.0, 0.0))
    assert refinements([best, weak], [weak], min_gap=4.0) == []
    large = Hypothesis(3, 1.0, pairs(4, 20), ELSEWHERE, features=plain(-5.0, 0.0))
    assert refinements([best, weak, large], [weak, large], min_gap=4.0) == [1, 2]


@pytest.mark.parametrize(("n", "refined"), [(4, True), (3, False)])
def test_a_pending_place_with_as_many_pairs_as_a_claimable_best_is_refined(n, refined):
    """A claimable best of four pairs: a pending other place as large might win the
    dominance rule (its residual is not final), a smaller one cannot."""
    best = place(plain(3.0, fitness=0.0))
    other = Hypothesis(2, 1.0, pairs(n, 10), ELSEWHERE, features=plain(-5.0, 0.0))
    assert refinements([best, other], [other]) == ([1] if refined else [])


@pytest.mark.parametrize(("residual", "contested"), [(0.5, True), (0.5 + 2**-20, False)])
def test_a_refined_place_that_the_best_does_not_dominate_contests_the_claim(residual, contested):
    """A refined other place as large as the claimable best (residuals 0.25 and `residual`):
    not clearly worse by the residual rule (more than 1.5 x 0.25 + 0.125 = 0.5), it contests
    the claim, and every pending other place is refined, even a small one."""
    best = place(plain(3.0, fitness=0.0), residual=0.25)
    other = Hypothesis(2, 1.0, pairs(4, 10), ELSEWHERE, features=plain(-5.0, 0.0),
                       residual=residual)  # fmt: skip
    small = Hypothesis(3, 1.0, pairs(2, 20), ELSEWHERE, features=plain(-5.0, 0.0))
    found = refinements([best, other, small], [small], residual_floor=0.125)
    assert found == ([2] if contested else [])
