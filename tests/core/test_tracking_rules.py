"""Tracking outside the clean room (`semloc.tracking`, `semloc.changes.RunChanges`): every
decision boundary pinned by a unit test built from its rule, then the Localizer's behaviour
with moved objects, phantoms, gone objects, coverage and a look-alike kidnap."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
from scipy.optimize import brentq
from scipy.stats import binom

from semloc import Coverage, Localizer, ObjectMap, Prior, SemanticObject
from semloc.changes import RunChanges
from semloc.copy_watch import TWIN_DOUBTED, TWIN_UPDATES, CopyWatch
from semloc.decision import PLACE_APART, RIVAL_LOGIT_GAP, missing_penalty, prior_first
from semloc.pose import _CLOUDS
from semloc.results import Hypothesis
from semloc.search import NEWEST_CONTRADICT, STALE
from semloc.tracking import (
    CONFIDENCE_CAP,
    CONTRADICTED,
    CONTRADICTION_UPDATES,
    DOUBT,
    DOUBT_OBJECTS,
    DOUBTED,
    EVIDENCE_LOGITS,
    PRIOR_AGAINST,
    PRIOR_WEIGHT,
    UNUSUAL,
    AgainstRate,
    Track,
    TrackingConfig,
    Verdict,
    check,
    footprints,
    one_to_one,
    recent_contradiction,
)
from semloc.twins import ANCHORS

GLOBALS = np.array([[0.0, 0, 0], [10.0, 0, 0], [20.0, 0, 0]])
ALLOWANCE = np.array([0.5, 0.5, 0.5])


def at(x: float, label: str = "chair", i: str = "l") -> SemanticObject:
    return SemanticObject(i, label, [x, 0.0, 0.0])


# check: supported / changed / contradicting ------------------------------------------------
@pytest.mark.parametrize(
    ("x", "kind"),
    [(0.5, "supported"), (0.51, "changed"), (3.0, "changed"), (3.01, "contradicting")],
)
def test_check_sorts_an_object_by_its_nearest_candidates_gap(x, kind):
    verdict = check(np.eye(4), [at(x)], {"l": np.array([0])}, GLOBALS, ALLOWANCE, move_m=3.0)
    found = {
        "supported": [g for g, _ in verdict.supported],
        "changed": [g for g, _ in verdict.changed],
        "contradicting": verdict.contradicting,
    }
    assert {k: bool(v) for k, v in found.items()} == {k: k == kind for k in found}


def test_an_object_without_candidates_says_nothing():
    verdict = check(np.eye(4), [at(0.0)], {"l": np.zeros(0, int)}, GLOBALS, ALLOWANCE, 3.0)
    assert verdict == Verdict([], [], [], 0)


def test_a_redetection_of_a_paired_object_is_a_repeat_but_not_of_another_pairing():
    candidates = {"l": np.array([0])}
    same = check(np.eye(4), [at(0.1)], candidates, GLOBALS, ALLOWANCE, 3.0, paired={"l": 0})
    other = check(np.eye(4), [at(0.1)], candidates, GLOBALS, ALLOWANCE, 3.0, paired={"l": 1})
    assert same.repeated == 1 and other.repeated == 0
    assert same.towards == 0.5 and other.towards == 1.0


@pytest.mark.parametrize(
    ("second", "part_m", "verdict"),
    [
        (0.4, None, ("changed", 1)),  # no part rule: chair 1, 1.6 m off, moved
        (0.4, 0.31, None),  # 0.3 m from the first: a part of the same chair (split)
        (0.4, 0.3, ("changed", 1)),  # just outside half the footprint: another chair
    ],
)
def test_one_map_object_supports_one_object_of_an_update_the_nearest(second, part_m, verdict):
    """Two chairs of one view near chair 0 of the map: the nearer is its support; the other is
    judged on the free candidates (chair 1 within the move distance: changed), unless it lies
    within half the chair's footprint of the first (a detector's split: it says nothing)."""
    chairs = np.array([[0.0, 0, 0], [2.0, 0, 0], [20.0, 0, 0]])
    objects = [at(0.1, i="a"), at(second, i="b")]
    candidates = {"a": np.array([0, 1]), "b": np.array([0, 1])}
    parts = None if part_m is None else np.full(3, part_m)
    found = check(np.eye(4), objects, candidates, chairs, ALLOWANCE, 3.0, part_m=parts)
    assert found.supported == [(0, "a")]
    judgement = {l: ("changed", g) for g, l in found.changed}
    judgement |= {l: ("contradicting", -1) for l in found.contradicting}
    assert judgement == ({} if verdict is None else {"b": verdict})


@pytest.mark.parametrize(("x", "found"), [(0.5, None), (0.51, ("changed", 1))])
def test_check_a_part_lies_within_the_allowance_of_the_chair_another_object_took(x, found):
    """Object "a" takes chair 0; "b" lies well within half the chair's footprint of it:
    exactly at chair 0's allowance (0.5 m) it is a part of "a" and says nothing, just beyond
    it is judged on the free chair 1 (moved)."""
    chairs = np.array([[0.0, 0, 0], [2.0, 0, 0], [20.0, 0, 0]])
    objects = [at(0.25, i="a"), at(x, i="b")]
    candidates = {"a": np.array([0, 1]), "b": np.array([0, 1])}
    verdict = check(np.eye(4), objects, candidates, chairs, ALLOWANCE, 3.0, part_m=np.full(3, 0.5))
    assert verdict.supported == [(0, "a")] and verdict.contradicting == []
    assert verdict.changed == ([] if found is None else [(1, "b")])


@pytest.mark.parametrize(("part_m", "found"), [(0.25, ("changed", 1)), (0.2501, None)])
def test_check_a_part_lies_closer_than_part_m_to_the_object_that_took_the_chair(part_m, found):
    """Object "b" lies 0.25 m from "a", which took chair 0: exactly `part_m` away it is another
    chair (moved from chair 1), just within it a part of "a" (a detector's split)."""
    chairs = np.array([[0.0, 0, 0], [2.0, 0, 0], [20.0, 0, 0]])
    objects = [at(0.125, i="a"), at(0.375, i="b")]
    candidates = {"a": np.array([0, 1]), "b": np.array([0, 1])}
    parts = np.full(3, part_m)
    verdict = check(np.eye(4), objects, candidates, chairs, ALLOWANCE, 3.0, part_m=parts)
    assert verdict.supported == [(0, "a")] and verdict.contradicting == []
    assert verdict.changed == ([] if found is None else [(1, "b")])


@pytest.mark.parametrize("order", [[0, 1], [1, 0]])
def test_a_changed_object_is_changed_from_its_nearest_candidate_whatever_their_order(order):
    """An object 0.8 m from chair 0 and 1.2 m from chair 1 (both beyond the allowance) moved
    from chair 0, however its candidates are listed."""
    chairs = np.array([[0.0, 0, 0], [2.0, 0, 0], [20.0, 0, 0]])
    verdict = check(np.eye(4), [at(0.8)], {"l": np.array(order)}, chairs, ALLOWANCE, 3.0)
    assert verdict.changed == [(0, "l")] and verdict.supported == []


def test_an_object_whose_only_chair_another_took_contradicts_beyond_the_move_distance():
    objects = [at(0.1, i="a"), at(0.4, i="b")]
    candidates = {"a": np.array([0]), "b": np.array([0])}
    found = check(np.eye(4), objects, candidates, GLOBALS, ALLOWANCE, 3.0)
    assert found.supported == [(0, "a")] and found.contradicting == ["b"]
    assert found.against == 1 and found.towards == 1


def test_without_a_move_distance_an_object_beyond_the_allowance_contradicts():
    verdict = check(np.eye(4), [at(0.51)], {"l": np.array([0])}, GLOBALS, ALLOWANCE)
    assert verdict == Verdict([], ["l"], [], 0)


def test_check_skips_objects_without_candidates_and_counts_every_repeat():
    """Objects without candidates say nothing and do not stop the others; two re-detections
    of paired objects in one update are two repeats."""
    objects = [at(0.0, i="new"), at(0.1, i="a"), at(10.1, i="b"), at(20.1, i="c")]
    candidates = {"a": np.array([0]), "b": np.array([1]), "c": np.array([2])}
    paired = {"a": 0, "b": 1}
    verdict = check(np.eye(4), objects, candidates, GLOBALS, ALLOWANCE, 3.0, paired)
    assert verdict.supported == [(0, "a"), (1, "b"), (2, "c")] and verdict.repeated == 2


def test_the_evidence_against_counts_contradictions_changes_and_missing_objects():
    verdict = Verdict([(0, "a")], ["b", "c"], [(1, "d")], 0, 1.5)
    assert verdict.against == 2 + 1 + 1.5 and verdict.towards == 1


# one_to_one: the change report's judgement, each map object explaining one object ----------
TWO_CHAIRS = np.array([[0.0, 0, 0], [2.0, 0, 0], [20.0, 0, 0]])


def judged(
    objects: list, held: dict[int, float], move_m: float = 3.0, settled: tuple[int, ...] = ()
) -> dict[str, tuple]:
    """Each object's (verdict, map index) by `one_to_one` (-1: none; absent: ambiguous)."""
    candidates = {o.id: np.array([0, 1]) for o in objects}
    holders = {g: TWO_CHAIRS[g] - [d, 0, 0] for g, d in held.items()}  # behind the chair
    verdict = one_to_one(
        np.eye(4), objects, candidates, TWO_CHAIRS, ALLOWANCE, move_m, holders, settled
    )
    found = {l: ("supported", g) for g, l in verdict.supported}
    found |= {l: ("changed", g) for g, l in verdict.changed}
    return found | {l: ("contradicting", -1) for l in verdict.contradicting}


@pytest.mark.parametrize(
    ("held_m", "verdict"),
    [(0.3, ("changed", 1)), (0.29, ("changed", 1)), (0.31, ("supported", 0))],
)
def test_an_object_by_a_chair_a_nearer_pair_holds_is_the_other_chair_moved(held_m, verdict):
    """The map's chair 0 is held by another object of the claim `held_m` from it: an object
    0.3 m from it (ties go to the pair) takes the free chair 1, 1.7 m away: moved."""
    assert judged([at(0.3)], {0: held_m}) == {"l": verdict}


def test_two_objects_of_one_update_share_no_map_object_and_the_nearer_keeps_it():
    found = judged([at(0.1, i="a"), at(0.4, i="b")], {})
    assert found == {"a": ("supported", 0), "b": ("changed", 1)}
    held = judged([at(0.1, i="a"), at(0.4, i="b")], {1: 0.0})  # the other chair held too
    assert held == {"a": ("supported", 0), "b": ("contradicting", -1)}


@pytest.mark.parametrize(
    ("move_m", "verdict"), [(1.6, ("changed", 1)), (1.59, ("contradicting", -1))]
)
def test_a_freed_object_takes_only_a_candidate_within_the_move_distance(move_m, verdict):
    assert judged([at(0.4)], {0: 0.0}, move_m=move_m) == {"l": verdict}


@pytest.mark.parametrize(
    ("x", "move_m", "sources"), [(1.1, 3.0, [1, 0]), (1.1, 1.1, [1, 0]), (1.1, 1.09, [1])]
)
def test_an_object_between_two_free_chairs_names_both_as_its_sources(x, move_m, sources):
    """Which of two chairs gone from their places stands between them cannot be told yet:
    both within `move_m` are its sources, nearest first."""
    candidates = {"l": np.array([0, 1])}
    verdict = one_to_one(np.eye(4), [at(x)], candidates, TWO_CHAIRS, ALLOWANCE, move_m, {})
    assert verdict.changed == [(1, "l")]
    assert verdict.sources == ({"l": sources} if len(sources) > 1 else {})


@pytest.mark.parametrize(("holder", "found"), [(-0.125, ("changed", 1)), (-0.0625, None)])
def test_an_object_overlapping_the_detection_that_took_its_chair_is_a_part_of_it(holder, found):
    """Chair 0 (half its diagonal 0.5 m) is taken by a nearer detection: an object 0.375 m
    from the chair and 0.5 m from that detection is another chair (moved from chair 1); closer
    to it, the two overlap: one chair split in two by the detector, which says nothing."""
    part_m = np.full(3, 0.5)
    candidates = {"l": np.array([0, 1])}
    held = {0: np.array([holder, 0.0, 0.0])}
    verdict = one_to_one(
        np.eye(4), [at(0.375)], candidates, TWO_CHAIRS, ALLOWANCE, 3.0, held, (), part_m
    )
    judgement = {l: ("changed", g) for g, l in verdict.changed}
    judgement |= {l: ("supported", g) for g, l in verdict.supported}
    judgement |= {l: ("contradicting", -1) for l in verdict.contradicting}
    assert judgement == ({} if found is None else {"l": found})


@pytest.mark.parametrize(("x", "found"), [(0.5, None), (0.51, ("changed", 1))])
def test_a_part_lies_within_the_allowance_of_the_chair_another_detection_took(x, found):
    """Detection "a" takes chair 0; "b" overlaps it (within `part_m`): exactly at chair 0's
    allowance (0.5 m) it is a part of "a" and says nothing, just beyond it is chair 1 moved."""
    part_m = np.full(3, 0.5)
    objects = [at(0.25, i="a"), at(x, i="b")]
    candidates = {"a": np.array([0, 1]), "b": np.array([0, 1])}
    verdict = one_to_one(np.eye(4), objects, candidates, TWO_CHAIRS, ALLOWANCE, 3.0, {}, (), part_m)
    assert verdict.supported == [(0, "a")] and verdict.contradicting == []
    assert verdict.changed == ([] if found is None else [(1, "b")])


def test_one_to_one_skips_objects_without_candidates_and_judges_the_others():
    """An object without candidates (absent or empty) says nothing, and does not stop the
    objects after it from being judged."""
    objects = [at(0.0, i="new"), at(0.0, i="none"), at(0.1, i="a")]
    candidates = {"none": np.zeros(0, int), "a": np.array([0])}
    verdict = one_to_one(np.eye(4), objects, candidates, TWO_CHAIRS, ALLOWANCE, 3.0, {})
    assert verdict == Verdict([(0, "a")], [], [])


def test_one_to_one_puts_each_object_where_the_pose_says():
    """Under a pose that shifts the local frame by +5 m, a local object at -5 m is chair 0."""
    pose = np.eye(4)
    pose[0, 3] = 5.0
    verdict = one_to_one(pose, [at(-4.9)], {"l": np.array([0, 1])}, TWO_CHAIRS, ALLOWANCE, 3.0, {})
    assert verdict.supported == [(0, "l")]


def test_an_object_that_took_its_chair_does_not_stop_the_others():
    """ "a" takes chair 0 (its gap to chair 1 comes next in the nearest-first walk, and is
    passed over); "b", 2 m beyond chair 1, then takes chair 1: moved."""
    assert judged([at(0.1, i="a"), at(4.0, i="b")], {}) == {
        "a": ("supported", 0),
        "b": ("changed", 1),
    }


@pytest.mark.parametrize("local_id", ["A", "l", "~"])
def test_a_tie_between_a_held_pair_and_a_new_object_goes_to_the_pair(local_id):
    """Whatever the new object's id sorts as, at an equal gap the claim's pair keeps the chair."""
    objects = [at(0.3, i=local_id)]
    candidates = {local_id: np.array([0, 1])}
    held = {0: np.array([-0.3, 0.0, 0.0])}
    verdict = one_to_one(np.eye(4), objects, candidates, TWO_CHAIRS, ALLOWANCE, 3.0, held)
    assert verdict.changed == [(1, local_id)] and verdict.supported == []


def test_the_judgements_are_listed_by_local_id():
    """Supported and changed objects are listed by their local id, not by map object."""
    chairs = np.array([[0.0, 0, 0], [2.0, 0, 0], [10.0, 0, 0], [12.0, 0, 0]])
    objects = [at(2.1, i="a"), at(0.1, i="b"), at(13.0, i="c"), at(11.0, i="d")]
    candidates = {"a": np.array([1]), "b": np.array([0]), "c": np.array([3]), "d": np.array([2])}
    allowance = np.full(4, 0.5)
    verdict = one_to_one(np.eye(4), objects, candidates, chairs, allowance, 3.0, {})
    assert verdict.supported == [(1, "a"), (0, "b")]
    assert verdict.changed == [(3, "c"), (2, "d")]


def test_the_sources_of_a_moved_object_are_listed_nearest_first():
    """Three free chairs 0.8, 1 and 2 m from an object: it took the nearest, and its other
    sources are the next nearest first, whatever their order in the map."""
    chairs = np.array([[2.0, 0, 0], [-1.0, 0, 0], [0.8, 0, 0]])
    candidates = {"l": np.array([0, 1, 2])}
    verdict = one_to_one(np.eye(4), [at(0.0)], candidates, chairs, np.full(3, 0.5), 3.0, {})
    assert verdict.changed == [(2, "l")] and verdict.sources == {"l": [2, 1, 0]}


def test_a_footprint_across_a_map_without_up_is_across_z():
    box = SemanticObject("box", "bed", [0, 0, 0], size=[0.6, 0.8, 2.0])
    assert footprints(ObjectMap([box])) == pytest.approx([1.0])


def test_a_footprint_is_the_widest_extent_across_up_of_the_box_else_of_the_points():
    turn = np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])
    objects = [
        SemanticObject("box", "bed", [0, 0, 0], size=[0.6, 0.8, 2.0]),
        SemanticObject("turned", "bed", [0, 0, 0], size=[0.6, 0.8, 2.0], rotation=turn),
        SemanticObject("points", "bed", [0, 0, 0], points=[[0, 0, 0], [0.3, 0.4, 5.0]]),
        SemanticObject("centre", "bed", [0, 0, 0]),
    ]
    assert footprints(ObjectMap(objects, up=[0, 0, 1])) == pytest.approx([1.0, 1.0, 0.5, 0.0])
    lying = ObjectMap(objects[:1], up=[1, 0, 0])  # across x: 0.8 by 2.0
    assert footprints(lying) == pytest.approx([np.hypot(0.8, 2.0)])


def test_each_box_has_its_own_footprint_and_a_tilted_box_its_widest_extent_across_up():
    """Two upright boxes of different sizes keep their own footprints; a unit cube tilted by
    45 degrees about x spans 1 m along x and its face diagonal (1.41 m) along y: its footprint
    is the diagonal of those, the square root of 3, though most of its corners lie nearer."""
    c, s = np.cos(np.pi / 4), np.sin(np.pi / 4)
    tilt = np.array([[1.0, 0, 0], [0, c, -s], [0, s, c]])
    objects = [
        SemanticObject("big", "bed", [0, 0, 0], size=[0.6, 0.8, 2.0]),
        SemanticObject("small", "bed", [0, 0, 0], size=[0.3, 0.4, 1.0]),
        SemanticObject("tilted", "box", [0, 0, 0], size=[1.0, 1.0, 1.0], rotation=tilt),
    ]
    found = footprints(ObjectMap(objects, up=[0, 0, 1]))
    assert found == pytest.approx([1.0, 0.5, math.sqrt(3)])


def test_a_chair_seen_at_its_place_before_is_no_source_but_may_be_seen_there_again():
    assert judged([at(1.0)], {}, settled=(0,)) == {"l": ("changed", 1)}
    assert judged([at(0.51)], {}, settled=(0,)) == {"l": ("changed", 1)}
    assert judged([at(0.5)], {}, settled=(0,)) == {"l": ("supported", 0)}
    assert judged([at(1.0)], {}, settled=(0, 1)) == {"l": ("contradicting", -1)}


# the contradiction rules ---------------------------------------------------------------------
def against(n: float, towards: int = 0) -> Verdict:
    supported = [(i, f"s{i}") for i in range(towards)]
    return Verdict(supported, [], [], 0, n)


@pytest.mark.parametrize(
    ("n", "towards", "ends"),
    [(2, 0, True), (1.99, 0, False), (2, 1, False), (3, 1, True), (4, 2, False), (4.01, 2, True)],
)
def test_one_update_ends_a_claim_at_least_and_more_than_twice_for(n, towards, ends):
    assert recent_contradiction([against(n, towards)], least=2) is ends


@pytest.mark.parametrize(
    ("amounts", "ends"),
    [((1, 1, 1), True), ((1, 1, 0.99), False), ((1, 1, 0.5), False)],
)
def test_three_updates_together_end_a_claim_at_least_plus_one(amounts, ends):
    assert recent_contradiction([against(a) for a in amounts], least=2) is ends


def test_the_three_update_rule_weighs_the_support_of_all_three():
    verdicts = [against(1.0), against(1.0, towards=1), against(1.5)]
    assert recent_contradiction(verdicts, least=2) is True  # 3.5 against > 2 x 1 for
    verdicts = [against(1.0), against(1.0, towards=2), against(1.5)]
    assert recent_contradiction(verdicts, least=2) is False  # 3.5 against, not > 2 x 2


def supported_updates(*latest: Verdict) -> list[Verdict]:
    """Two updates of three supporting objects each, then `latest`."""
    return [against(0, towards=3), against(0, towards=3), *latest]


@pytest.mark.parametrize(("n", "towards", "ends"), [(2, 0, True), (1.99, 0, False), (4, 2, False), (4.01, 2, True)])  # fmt: skip
def test_the_newest_update_alone_ends_a_claim_its_older_updates_supported(n, towards, ends):
    """The older updates' support keeps the three-update rule quiet: the newest update ends
    the claim by itself, at least `least` against and more than twice its own support."""
    verdicts = supported_updates(against(n, towards))
    assert recent_contradiction(verdicts[:-1], least=2) is False
    assert recent_contradiction(verdicts, least=2) is ends


@pytest.mark.parametrize(("last", "ends"), [(1.0, False), (1.01, True)])
def test_three_updates_together_end_a_claim_more_than_twice_their_support(last, ends):
    """1.5 + 1.5 + `last` against, 2 for: 4 is not more than twice 2, 4.01 is."""
    verdicts = [against(1.5, towards=1), against(1.5, towards=1), against(last)]
    assert recent_contradiction(verdicts, least=2) is ends


def test_a_claim_weighs_only_its_latest_updates_together():
    """1.5 missing objects, then 0.5 in each of three updates: the latest three hold 1.5
    against, short of `contradiction` + 1; the first update's no longer counts."""
    claim = track()
    updates = [1.5, 0.5, 0.5, 0.5]
    assert [claim.contradicted(Verdict([], [], [], 0, m)) for m in updates] == [0, 0, 0, 0]


def test_no_update_contradicts_nothing():
    assert recent_contradiction([], least=1) is False


def track(
    n_pairs: int = 3, confidence: float = 0.99, rate: AgainstRate | None = None, **config
) -> Track:
    pairs = [(i, f"p{i}") for i in range(n_pairs)]
    return Track(np.eye(4), pairs, confidence, 3.0, TrackingConfig(**config), rate)


def test_a_claim_ends_when_its_judged_objects_lose_the_supporting_share():
    """Each object counts once, by its latest verdict: half of the judged supporting keeps
    the claim, one flipping to contradicting ends it; below `min_judged` nothing is asked."""
    claim = track(min_judged=4)
    assert claim.contradicted(Verdict([(10, "a"), (11, "b")], ["x", "y"])) == 0  # 2 of 4
    assert claim.contradicted(Verdict([], ["a"])) == 1  # 1 of 4
    young = track(min_judged=5)
    assert young.contradicted(Verdict([(10, "a"), (11, "b")], ["x", "y"])) == 0
    assert young.contradicted(Verdict([], ["a"])) == 0  # only 4 judged


def test_changed_objects_and_missing_ones_count_among_the_judged_objects():
    """The share asks of every object judged (changed ones and missing ones too), each
    counted once: a run of changed objects, one an update beside a re-detected supporting
    one, never ends a claim by the recent rules but loses it its supporting share (2 of 5);
    missing objects alone take a young claim past `min_judged` and below the share."""
    claim = track(min_judged=4)
    assert claim.contradicted(Verdict([(10, "a"), (11, "b")], [])) == 0
    for k, moved in enumerate(["x", "y", "z"]):
        ends = claim.contradicted(Verdict([(10, "a")], [], [(12 + k, moved)]))
        assert ends == (1 if moved == "z" else 0), moved  # 2 of 4 keeps it, 2 of 5 does not
    unseen = track(min_judged=4)
    assert unseen.contradicted(Verdict([(10, "a"), (11, "b")], [], [], 0, 1.5)) == 0  # 2 of 3.5
    assert unseen.contradicted(Verdict([(10, "a")], [], [], 0, 1.0)) == 1  # 2 of 4.5
    assert unseen.missing == 2.5


def test_accept_keeps_one_pair_per_map_object_and_a_refreshed_pair_is_the_newest():
    claim = track()  # p0 -> 0, p1 -> 1, p2 -> 2
    claim.accept(Verdict([(0, "q")], []))  # another local object on map object 0
    assert claim.newest(5) == [(1, "p1"), (2, "p2"), (0, "q")]
    claim.accept(Verdict([(7, "p1")], []))  # p1 seen again, on another map object
    assert claim.newest(5) == [(2, "p2"), (0, "q"), (7, "p1")]
    assert claim.newest(2) == [(0, "q"), (7, "p1")]


def test_objects_that_left_the_window_are_no_longer_judged():
    claim = track(min_judged=4)
    claim.contradicted(Verdict([(10, "a"), (11, "b")], ["x"]))
    claim.keep_only(["p0", "p1", "a", "x"])
    assert claim.judged == {"a": "supported", "x": "contradicting"}
    assert [l for _, l in claim.newest(5)] == ["p0", "p1"]


def test_a_restored_track_ignores_a_verdict_it_does_not_know():
    ids = [f"g{i}" for i in range(20)]
    state = track().state(ids)
    state["judged"] = {"a": "supported", "b": "puzzling"}
    assert Track.restored(state, ids.index, TrackingConfig()).counts() == {
        "supported": 1,
        "changed": 0,
        "contradicting": 0,
    }


@pytest.mark.parametrize("against, judged", [(1, 1), (2, 2), (2, 8), (3, 5), (4, 6), (5, 12)])
@pytest.mark.parametrize("share", [(1, 100), (40, 100), (0, 0)])
def test_new_objects_against_a_claim_are_unusual_by_the_binomial_tail_of_the_runs_share(
    against, judged, share
):
    rate = AgainstRate(*share)
    expected_share = (share[0] + PRIOR_WEIGHT * PRIOR_AGAINST) / (share[1] + PRIOR_WEIGHT)
    assert rate.share == pytest.approx(expected_share)
    tail = binom.sf(against - 1, judged, expected_share)
    assert rate.unusual(against, judged) is bool(against >= 2 and tail < UNUSUAL)


@pytest.mark.parametrize(("against", "judged"), [(2, 3), (3, 6)])
def test_new_objects_are_unusual_just_below_the_share_where_the_tail_is_unusual(against, judged):
    """At the run's share where the binomial tail of `against` of `judged` is `UNUSUAL`: just
    below that share they are unusual, just above it they are not."""
    border = brentq(lambda p: binom.sf(against - 1, judged, p) - UNUSUAL, 1e-6, 0.5)

    def rate(share: float) -> AgainstRate:  # 1000 judged objects at `share`, with the prior
        return AgainstRate(share * (1000 + PRIOR_WEIGHT) - PRIOR_WEIGHT * PRIOR_AGAINST, 1000)

    assert rate(border * (1 - 1e-6)).unusual(against, judged)
    assert not rate(border * (1 + 1e-6)).unusual(against, judged)


@pytest.mark.parametrize(("against", "judged", "tail"), [(2, 2, 0.25), (3, 3, 0.125), (2, 3, 0.5)])
def test_a_tail_exactly_at_the_level_is_not_unusual(against, judged, tail):
    """At a run share of one half (15 of 20 judged, with the prior's 5 of 20) the binomial
    tails are exact in binary: a tail equal to the level is not unusual, one just below is."""
    rate = AgainstRate(15, 20)
    assert rate.share == 0.5
    assert not rate.unusual(against, judged, level=tail)
    assert rate.unusual(against, judged, level=tail * (1 + 1e-9))


def at_share(share: float) -> AgainstRate:
    """A run that judged 1000 objects at `share` against its claims (the prior included)."""
    return AgainstRate(share * (1000 + PRIOR_WEIGHT) - PRIOR_WEIGHT * PRIOR_AGAINST, 1000)


def test_a_claim_is_doubted_when_its_newest_objects_hold_an_unlikely_share_against_it():
    """Two of the newest six against: at a run share of 5 % the tail (0.033) lies between
    `UNUSUAL` and `DOUBT`: the claim holds (not ended) but is doubted; at 10 % (0.114) not."""
    assert UNUSUAL < binom.sf(1, 6, 0.05) < DOUBT < binom.sf(1, 6, 0.10)
    view = Verdict([(10, "a"), (11, "b"), (12, "c"), (13, "d")], ["x", "y"])
    doubted = track(rate=at_share(0.05))
    assert doubted.contradicted(view) == 0 and doubted.doubted()
    calm = track(rate=at_share(0.10))
    assert calm.contradicted(view) == 0 and not calm.doubted()


def test_a_doubt_weighs_the_newest_judged_objects_across_updates():
    """Updates without new objects change nothing (a robot carried off sees nothing for a
    while: no news); a doubt lifts once `DOUBT_OBJECTS` - 1 newer objects support the place
    (one against of six is never unusual); an object judged again alike is not new."""
    claim = track(rate=at_share(0.05))
    claim.contradicted(Verdict([(10, "a"), (11, "b"), (12, "c"), (13, "d")], ["x", "y"]))
    for _ in range(3):
        claim.contradicted(Verdict([], []))
        claim.contradicted(Verdict([(10, "a")], ["x"]))  # the same objects, the same verdicts
        assert claim.doubted()
    supporting = [(20 + k, f"s{k}") for k in range(DOUBT_OBJECTS - 1)]
    for k, pair in enumerate(supporting, start=1):
        claim.contradicted(Verdict([pair], []))
        assert claim.doubted() is (k < DOUBT_OBJECTS - 1), k  # [y, s0..s4]: one against left


def test_one_object_against_never_doubts_a_claim():
    claim = track(rate=at_share(0.0))
    claim.contradicted(Verdict([], ["x"]))
    assert not claim.doubted()


def test_a_restored_track_keeps_its_newest_judged_objects():
    ids = [f"g{i}" for i in range(40)]
    claim = track(rate=at_share(0.05))
    claim.contradicted(Verdict([(10, "a"), (11, "b"), (12, "c"), (13, "d")], ["x", "y"]))
    state = json.loads(json.dumps(claim.state(ids)))
    again = Track.restored(state, ids.index, TrackingConfig(), at_share(0.05))
    assert again.doubted() and list(again._newest) == list(claim._newest)


def test_the_runs_share_adds_up_every_claims_objects():
    rate = AgainstRate()
    rate.add(1, 3)
    rate.add(2, 5)
    assert (rate.against, rate.judged) == (3, 8)


def test_an_object_judged_again_alike_is_not_new_to_the_runs_share():
    """The same verdict on the same objects, update after update: only the first update's
    objects are new (1 against of 3); the later updates add nothing to the run's share."""
    rate = AgainstRate()
    claim = track(rate=rate)
    for _ in range(CONTRADICTION_UPDATES + 2):
        claim.contradicted(Verdict([(10, "a"), (11, "b")], ["c"]))
    assert (rate.against, rate.judged) == (1, 3)


def test_a_clean_run_ends_a_claim_whose_new_objects_turn_against_it_as_its_places_never_did():
    """Four new supporting objects and two contradicting ones per update: the old rules keep
    the claim (twice as many for as against); a run whose claims saw 1 % of their objects
    against ends it, a run that saw 40 % does not."""
    updates = [Verdict([(10 + 2 * k, f"s{k}"), (11 + 2 * k, f"t{k}"), (30 + 2 * k, f"u{k}"),
                        (31 + 2 * k, f"v{k}")], [f"x{k}", f"y{k}"]) for k in range(3)]  # fmt: skip
    clean = track(rate=AgainstRate(1, 100))
    hard = track(rate=AgainstRate(40, 100))
    assert [clean.contradicted(v) for v in updates[:2]] == [0, 2]  # both updates' objects
    assert [hard.contradicted(v) for v in updates] == [0, 0, 0]
    assert not any(recent_contradiction([v], least=2) for v in updates)


def test_the_runs_share_learns_from_a_claims_older_updates_only():
    rate = AgainstRate()
    claim = track(rate=rate)
    first = Verdict([(10, "a"), (11, "b")], ["c"])
    claim.contradicted(first)
    for k in range(CONTRADICTION_UPDATES - 1):
        claim.contradicted(Verdict([(20 + k, f"n{k}")], []))
    assert (rate.against, rate.judged) == (0, 0)  # the latest updates are what is tested
    claim.contradicted(Verdict([(30, "m")], []))
    assert (rate.against, rate.judged) == (1, 3)  # the first update's new objects


def test_a_changed_or_contradicting_redetection_drops_its_pair_and_never_refits():
    claim = track()
    claim.accept(Verdict([(5, "x")], []))
    assert claim.pairs["x"] == 5
    claim.accept(Verdict([], [], [(5, "x")]))
    assert "x" not in claim.pairs
    claim.accept(Verdict([(6, "y")], []))
    claim.accept(Verdict([], ["y"]))
    assert "y" not in claim.pairs and [l for _, l in claim.newest(5)] == ["p0", "p1", "p2"]


def test_the_claims_confidence_moves_with_its_evidence():
    claim = track(confidence=0.9)
    start = claim.current_confidence()
    assert math.isclose(start, 0.9)
    claim.contradicted(Verdict([(5, "a"), (6, "b")], []))
    up = claim.current_confidence()
    claim.contradicted(Verdict([], ["c"]))
    down = claim.current_confidence()
    assert start < up and down < up
    expected = math.log(9) + 2 * EVIDENCE_LOGITS["supported"] + EVIDENCE_LOGITS["contradicting"]
    assert math.isclose(down, 1 / (1 + math.exp(-expected)))
    sure = track(confidence=0.999999)
    assert math.isclose(sure.current_confidence(), 1 / (1 + math.exp(-CONFIDENCE_CAP)))
    unsure = track(confidence=1e-6)  # the cap holds both ways
    assert math.isclose(unsure.current_confidence(), 1 / (1 + math.exp(CONFIDENCE_CAP)))
    certain = track(confidence=1.0)  # a certain search is capped too
    assert math.isclose(certain.current_confidence(), 1 / (1 + math.exp(-CONFIDENCE_CAP)))
    assert track(confidence=None).current_confidence() == 0.5  # no confidence: even odds


def test_each_kind_of_judged_object_moves_the_confidence_by_its_logit():
    """One supporting, one changed, one contradicting and 1.5 missing objects beyond the
    tolerated share: the search's logit plus each one's log-likelihood ratio."""
    claim = track(confidence=0.5)  # logit 0
    claim.contradicted(Verdict([(5, "a")], ["c"], [(6, "b")], 0, 1.5))
    logits = EVIDENCE_LOGITS
    expected = (logits["supported"] + logits["changed"] + logits["contradicting"]
                + 1.5 * logits["missing"])  # fmt: skip
    assert math.isclose(claim.current_confidence(), 1 / (1 + math.exp(-expected)))
    assert all(logits[k] < 0 for k in ("changed", "contradicting", "missing"))


def test_the_claims_confidence_bottoms_out_at_a_logit_of_minus_fifty():
    """Evidence against far beyond any real run's (a logit of -80, then -8000) neither
    overflows nor goes below the confidence of a logit of -50."""
    floor = 1 / (1 + math.exp(50.0))
    claim = track(confidence=0.5)  # logit 0
    claim.contradicted(Verdict([], [], [], 0, 100.0))  # 100 missing: -80
    assert math.isclose(claim.current_confidence(), floor, rel_tol=1e-9)
    claim.contradicted(Verdict([], [], [], 0, 10_000.0))
    assert math.isclose(claim.current_confidence(), floor, rel_tol=1e-9)
    near = track(confidence=0.5)
    near.contradicted(Verdict([], [], [], 0, 61.25))  # -49: above the floor
    assert math.isclose(near.current_confidence(), 1 / (1 + math.exp(49.0)), rel_tol=1e-9)


def test_a_restored_tracks_pose_is_float_whatever_the_numbers_it_was_written_with():
    """A state written by hand or by another tool may hold the pose as integers (JSON's 1 for
    1.0): the restored pose is a float array all the same (it warm-starts the refit)."""
    ids = [f"g{i}" for i in range(20)]
    state = json.loads(json.dumps(track().state(ids)))
    state["pose"] = [[int(v) for v in row] for row in state["pose"]]
    pose = Track.restored(state, ids.index, TrackingConfig()).pose
    assert pose.dtype == np.float64 and np.array_equal(pose, np.eye(4))


def test_a_track_round_trips_through_its_state_and_reads_an_old_one():
    ids = [f"g{i}" for i in range(20)]
    claim = track()
    claim.contradicted(Verdict([(5, "a")], ["b"], [(7, "c")], 1, 0.5))
    claim.accept(Verdict([(5, "a")], ["b"], [(7, "c")], 1, 0.5))
    state = json.loads(json.dumps(claim.state(ids)))
    assert state["confidence"] == 0.99 and state["score"] == 3.0
    again = Track.restored(state, ids.index, TrackingConfig())
    assert again.state(ids) == state and again.counts() == claim.counts()
    old = {**state, "verdicts": [v[:2] for v in state["verdicts"]]}
    for key in ("judged", "missing", "recent", "newest"):
        old.pop(key)
    restored = Track.restored(old, ids.index, TrackingConfig())
    assert restored.counts()["supported"] == 0 and not restored.doubted()
    upgraded = restored.state(ids)  # an old verdict: no change, no repeat, nothing missing
    assert upgraded["verdicts"] == [[*v, [], 0, 0.0] for v in old["verdicts"]]
    assert upgraded["missing"] == 0.0 and upgraded["recent"] == [] and upgraded["newest"] == []


def test_a_restored_track_shares_the_runs_against_rate():
    """A restored claim adds its older updates' objects to the run's share it is given."""
    ids = [f"g{i}" for i in range(40)]
    rate = AgainstRate()
    claim = Track.restored(track().state(ids), ids.index, TrackingConfig(), rate)
    for k in range(CONTRADICTION_UPDATES + 1):
        claim.contradicted(Verdict([(10 + k, f"a{k}"), (20 + k, f"b{k}")], [f"c{k}"]))
    assert (rate.against, rate.judged) == (1, 3)


# the run's change report ---------------------------------------------------------------------
def test_a_change_is_reported_once_seen_twice_and_a_sighting_in_place_cancels_it():
    run = RunChanges()
    ids = ["g0", "g1", "g2"]
    run.observe_moved(1, "l1", 2.0, seen=3)
    assert run.report(ids).moved == []
    run.observe_moved(1, "l1", 2.1, seen=4)
    moved = run.report(ids).moved
    assert [(m.global_id, m.local_id, m.evidence, m.last_seen) for m in moved] == [
        ("g1", "l1", 2, 4)
    ]
    run.observe_new("l5", seen=4)
    run.observe_new("l6", seen=4, unknown_label=True)  # a label the map does not hold
    run.observe_missing([2])
    report = run.report(ids)
    assert report.new == ["l6"] and report.missing == []
    run.observe_missing([2])
    assert run.report(ids).missing == ["g2"]
    run.observe_matched(1, "lx")
    run.observe_matched(2, "ly")
    report = run.report(ids)
    assert report.moved == [] and report.missing == [] and report.evidence["new"] == {"l6": 2}
    state = json.loads(json.dumps(run.state(ids)))
    assert RunChanges.restored(state, ids.index).report(ids) == report


# decisions -----------------------------------------------------------------------------------
def hypothesis(rank: int, evidence: float, outside: bool | None) -> Hypothesis:
    return Hypothesis(rank, 1.0, [(f"g{rank}", "l")], np.eye(4), evidence=evidence,
                      outside_prior=outside)  # fmt: skip


def test_the_prior_decides_among_places_whose_evidence_is_within_the_margin():
    outside, inside = hypothesis(1, 3.0, True), hypothesis(2, 3.0 - RIVAL_LOGIT_GAP, False)
    assert [h.rank for h in prior_first([outside, inside])] == [1, 2]
    assert prior_first([outside, inside])[0] is inside and outside.rank == 2
    outside, inside = hypothesis(1, 3.0, True), hypothesis(2, 2.99 - RIVAL_LOGIT_GAP, False)
    assert prior_first([outside, inside])[0] is outside
    alone = [hypothesis(1, 1.0, True)]
    assert prior_first(alone) == alone
    # a best place inside the prior keeps the order, outside places among the inside ones
    ranked = [hypothesis(1, 3.0, False), hypothesis(2, 3.0, True), hypothesis(3, 3.0, False)]
    assert [h.rank for h in prior_first(list(ranked))] == [1, 2, 3]
    assert prior_first(list(ranked)) == ranked
    # without the evidence of either, nothing tells the places apart: the order stays
    for best, candidate in [(3.0, None), (None, 3.0)]:
        ranked = [hypothesis(1, best, True), hypothesis(2, candidate, False)]
        assert prior_first(list(ranked)) == ranked and ranked[0].rank == 1


def test_the_missing_penalty_forgives_the_gone_share():
    h = hypothesis(1, 0.0, None)
    assert missing_penalty(h) == 0.0
    h.n_missing, h.n_expected = 2, 8
    assert missing_penalty(h) == 0.0  # 2 of 8 is the share an old map may lose
    h.n_missing = 4
    assert missing_penalty(h) == pytest.approx(2.0)
    h.n_missing = 1  # fewer than the share: no penalty, and no bonus either
    assert missing_penalty(h) == 0.0
    h.n_missing, h.n_expected = 3, None  # a count without what was expected says nothing
    assert missing_penalty(h) == 0.0


# the Localizer outside the clean room ----------------------------------------------------------
LABELS = ["chair", "table", "lamp", "sofa", "shelf", "plant", "bin", "desk", "tv", "bed"]


def room(offset: float = 0.0, drop: tuple[int, ...] = (), prefix: str = "a") -> list:
    """Ten objects of ten labels on a 6 x 4 m floor, shifted by `offset` in x."""
    rng = np.random.default_rng(4)
    xy = rng.uniform([0, 0], [6, 4], (10, 2))
    return [SemanticObject(f"{prefix}{i}", LABELS[i], [xy[i, 0] + offset, xy[i, 1], 0.5],
                           size=[0.5, 0.5, 1.0])
            for i in range(10) if i not in drop]  # fmt: skip


def local(objects: list, ids: str = "l", shift: float = 0.0) -> list:
    return [o.replace(id=f"{ids}{o.id}", position=o.position - [shift, 0, 0], size=None)
            for o in objects]  # fmt: skip


ALL_AROUND = Coverage(np.eye(4) @ np.diag([1, 1, 1, 1.0]), 12.0)


def claimed(global_map: ObjectMap, unseen: tuple[str, ...] = ()) -> Localizer:
    """A Localizer tracking the place of the map's first ten objects (but `unseen`)."""
    localizer = Localizer(global_map, local_up=[0, 0, 1])
    objects = local([o for o in list(global_map)[:10] if o.id not in unseen])
    result = localizer.update(objects[:5])
    result = localizer.update(objects[5:])
    assert result.status == "localized" and np.allclose(result.pose, np.eye(4), atol=0.05)
    return localizer


def test_a_claim_whose_newest_objects_speak_against_it_is_doubted_then_claimed_again():
    """In a run whose claims saw 5 % of their objects against them, four objects of the room
    and two chairs where it has none: no end rule fires, but two of the newest six against is
    unlikely at that share (`Track.doubted`); five more of the room's objects lift the doubt
    (one against of the newest six)."""
    building = ObjectMap(room(), up=[0, 0, 1])
    localizer = claimed(building, unseen=("a6", "a7", "a8", "a9"))
    localizer._against.against, localizer._against.judged = 46.0, 1000.0  # the run's share
    rest = local([o for o in building if o.id in {"a6", "a7", "a8", "a9"}])
    strays = [SemanticObject(f"s{i}", "chair", [20.0 + 5 * i, 20.0, 0.5]) for i in range(2)]
    doubted = localizer.update([*rest, *strays])
    assert doubted.status == "ambiguous" and doubted.reason == DOUBTED
    assert localizer.tracking and doubted.best.confidence <= 0.5
    again = localizer.update(local(room(), ids="m")[:5])  # the room's objects, seen anew
    assert again.status == "localized" and np.allclose(again.pose, np.eye(4), atol=0.05)


def test_a_moved_object_is_reported_moved_and_does_not_move_the_pose():
    building = ObjectMap(room(), up=[0, 0, 1])
    localizer = claimed(building, unseen=("a2",))  # the lamp not seen at its place
    before = localizer.update([]).pose
    lamp = building[building.index_of("a2")]
    moved = lamp.replace(id="moved-lamp", position=lamp.position + [2.0, 0, 0], size=None)
    for _ in range(2):  # seen twice: a change, not a one-off
        result = localizer.update([moved])
    assert result.status == "localized"
    assert [(m.global_id, m.local_id) for m in result.changes.moved] == [("a2", "moved-lamp")]
    assert result.changes.moved[0].offset_m == pytest.approx(2.0, abs=0.05)
    assert np.allclose(result.pose, before, atol=1e-6)
    assert ("a2", "moved-lamp") not in result.best.pairs


def test_a_lamp_seen_at_its_place_is_not_reported_moved_by_a_second_lamp_elsewhere():
    building = ObjectMap(room(), up=[0, 0, 1])
    localizer = claimed(building)  # its detection `la2` holds the map's lamp a2
    lamp = building[building.index_of("a2")]
    other = lamp.replace(id="other-lamp", position=lamp.position + [2.0, 0, 0], size=None)
    for _ in range(2):
        result = localizer.update([other])
    assert result.status == "localized" and result.changes.moved == []


def test_a_claim_needs_a_detection_of_its_place_within_the_stale_distance():
    """Walking on with nothing seen, the claim holds for `stale_m` metres of travel; beyond, a
    kidnap could not be told, so the answer is `ambiguous` (stale) until the place is seen
    again."""
    building = ObjectMap(room(), up=[0, 0, 1])
    localizer = Localizer(building, local_up=[0, 0, 1])
    objects = local(list(building))
    localizer.update(objects[:5], position=[0.0, 0, 0])
    assert localizer.update(objects[5:], position=[0.0, 0, 0]).status == "localized"
    stale_m = localizer.config.tracking.stale_m
    statuses = {}
    for x in range(1, int(stale_m) + 3):
        result = localizer.update([], position=[float(x), 0, 0])
        statuses[x] = result.status
    assert statuses[int(stale_m)] == "localized"
    assert statuses[int(stale_m) + 1] == "ambiguous" and result.reason.startswith(STALE)
    again = localizer.update(objects[:4], position=[stale_m + 2, 0, 0])  # seen again
    assert again.status == "localized"


def test_a_phantom_never_becomes_support():
    building = ObjectMap(room(), up=[0, 0, 1])
    localizer = claimed(building)
    bin_ = building[building.index_of("a6")]
    phantom = SemanticObject("bag", "bin", bin_.position + [5.0, 3.0, 0.0])
    result = localizer.update([phantom])
    assert all(l != "bag" for _, l in result.best.pairs)
    assert "bag" not in localizer._track.pairs
    assert localizer._track.judged["bag"] == "contradicting"


def test_coverage_is_optional_and_round_trips_in_the_state():
    building = ObjectMap(room(), up=[0, 0, 1])
    localizer = claimed(building)
    assert localizer.update([]).support.n_missing is None  # no coverage: no negative evidence
    result = localizer.update(local(list(building)), coverage=ALL_AROUND)  # all it saw
    assert result.support.n_missing == 0 and result.support.n_expected >= 6
    state = json.loads(json.dumps(localizer.state()))
    again = Localizer.restore(building, state, list(localizer.local_map), local_up=[0, 0, 1])
    assert again.state() == state
    with pytest.raises(ValueError, match="range_m"):
        localizer.update([], coverage={"pose": np.eye(4).tolist(), "range_m": -1})


def test_the_support_of_an_unweighed_best_place_names_keyframes_not_map_objects():
    """A best place not weighed against the looks yet (not refined) is weighed for the
    support; its keyframes stay those of its detections."""
    building = ObjectMap(room(), up=[0, 0, 1])
    localizer = Localizer(building, local_up=[0, 0, 1], track=False)
    objects = local(list(building))
    localizer.update(objects[:5])
    best = localizer.update(objects, coverage=ALL_AROUND).best  # the look's every detection
    unweighed = dataclasses.replace(best, n_missing=None, n_expected=None)
    support_of = localizer._sightings.support_of
    support = support_of(unweighed, None)
    assert support.seen == support_of(best, None).seen  # its detections' keyframes
    assert support.n_missing == 0 and support.n_expected >= 6


def test_gone_objects_within_the_tolerated_share_do_not_end_a_right_claim():
    building = ObjectMap(room(), up=[0, 0, 1])
    localizer = claimed(building)
    today = local(room(drop=(3, 8)))  # two of ten gone: within the share an old map loses
    for _ in range(3):
        result = localizer.update(today, coverage=ALL_AROUND)
        assert result.status == "localized"
    assert result.support.n_missing == 2 and result.support.n_expected >= 8


def lookalikes(extras: int = 2) -> ObjectMap:
    """The room and a copy 30 m away that lacks four of its objects (and has `extras`
    others)."""
    copy = room(offset=30.0, drop=(1, 3, 5, 7), prefix="b")
    extra = [SemanticObject("b10", "tv", [31.0, 3.5, 0.5], size=[0.5, 0.5, 1.0]),
             SemanticObject("b11", "bed", [35.0, 0.5, 0.5], size=[0.5, 0.5, 1.0])]  # fmt: skip
    return ObjectMap([*room(), *copy, *extra[:extras]], up=[0, 0, 1])


def kidnapped(coverage: Coverage | None, extras: int = 2) -> list[str]:
    """Claim the room, then be carried to the same spot of the copy (odometry unaware): the
    statuses of the three updates after the kidnap (the copy's extras in the first two), a
    claim marked by its place ("localized a", "localized b")."""
    building = lookalikes(extras)
    localizer = Localizer(building, local_up=[0, 0, 1])
    room_objects = local([o for o in building if o.id.startswith("a")])
    localizer.update(room_objects[:5], coverage=coverage)
    assert localizer.update(room_objects[5:], coverage=coverage).status == "localized"
    there = local([o for o in building if o.id.startswith("b")], ids="k", shift=30.0)
    results = [localizer.update(there[i::3], coverage=coverage) for i in range(3)]
    return [r.status if r.status != "localized" else f"localized {r.hypotheses[0].pairs[0][0][0]}"
            for r in results]  # fmt: skip


def test_a_kidnap_into_a_copy_lacking_objects_is_caught_only_with_the_coverage():
    """The copy's objects all fit the room where the tracked pose puts them; only the room's
    objects that the copy lacks, in plain view and not detected, tell the two apart."""
    assert kidnapped(ALL_AROUND, extras=0)[0] == "ambiguous"
    assert kidnapped(None, extras=0) == ["localized a"] * 3  # semloc cannot know


def test_a_kidnap_into_a_copy_is_caught_by_two_of_its_own_objects_without_coverage():
    """The copy's tv and bed stand where the room has nothing of their labels (so they
    contradict it) and where the copy, a twin of the room (`semloc.twins`), has them."""
    there = local([o for o in lookalikes() if o.id.startswith("b")], ids="k", shift=30.0)
    assert [o.id for o in there[0::3]][-1] == "kb10" and [o.id for o in there[1::3]][-1] == "kb11"
    # the first makes the copy lead (the claim is doubted), the second ends the claim
    assert kidnapped(None) == ["ambiguous", "ambiguous", "localized b"]
    # one could be the map's change: the claim is doubted, not ended, while the copy leads
    assert kidnapped(None, extras=1) == ["ambiguous"] * 3


def room_claimed() -> tuple[ObjectMap, Localizer, list, list]:
    """The room claimed in a building with its copy (that holds a tv too): the building, the
    Localizer, the room's local objects and the copy's as seen from the same spot."""
    building = lookalikes(extras=1)
    localizer = Localizer(building, local_up=[0, 0, 1])
    room_objects = local([o for o in building if o.id.startswith("a")])
    localizer.update(room_objects[:5])
    assert localizer.update(room_objects[5:]).status == "localized"
    there = local([o for o in building if o.id.startswith("b")], ids="k", shift=30.0)
    return building, localizer, room_objects, there


def test_a_copy_leading_by_one_object_makes_the_answer_ambiguous_with_the_copy_listed():
    building, localizer, room_objects, there = room_claimed()
    doubted = localizer.update(there[0::3])
    assert doubted.status == "ambiguous" and doubted.reason == TWIN_DOUBTED
    assert localizer.tracking  # weighed on, not ended
    place, copy = doubted.hypotheses
    assert {g[0] for g, _ in place.pairs} == {"a"} and place.confidence <= 0.5
    assert copy.method == "copy" and copy.pairs and {g[0] for g, _ in copy.pairs} == {"b"}
    assert copy.rank == 2 and copy.score == len(copy.pairs)  # the place's rival, by its pairs
    assert {l for _, l in copy.pairs} <= {l for _, l in place.pairs}
    np.testing.assert_allclose(copy.pose[:3, 3] - place.pose[:3, 3], [30.0, 0.0, 0.0], atol=0.2)


def test_a_doubt_lasts_while_nothing_tells_the_place_from_its_copy():
    """Updates of objects both rooms hold say nothing of which one the robot is in: the tv
    keeps the copy ahead however many of them follow (nothing seen is no news)."""
    building, localizer, room_objects, there = room_claimed()
    assert localizer.update(there[0::3]).reason == TWIN_DOUBTED
    both_hold = [o for o in there if o.id != "kb10"]
    for _ in range(2 * TWIN_UPDATES):
        assert localizer.update(both_hold[:3]).reason == TWIN_DOUBTED


def test_a_restored_localizer_reads_the_older_state_of_every_updates_objects():
    """A state written before only the telling updates were kept (one list per update)."""
    building, one, _, there = room_claimed()
    one.update(there[0::3])
    state = json.loads(json.dumps(one.state()))
    state["twins"]["fits"] = [None, [[]], [["+local kb10"]]]
    other = Localizer.restore(building, state, list(one.local_map), local_up=[0, 0, 1])
    assert list(other._copies.fits) == [(3, [["+local kb10"]])]
    assert other.update(there[1::3]).reason == TWIN_DOUBTED


def test_the_place_seen_again_lifts_the_doubt():
    """Once an object only the room holds is seen, the copy no longer leads."""
    building, localizer, room_objects, _ = room_claimed()
    tv = local([o for o in building if o.id == "b10"], ids="k", shift=30.0)
    assert localizer.update(tv).status == "ambiguous"  # a tv where the room has none
    only_the_room = [o for o in room_objects if o.id in {"la1", "la3"}]  # the copy lacks them
    assert len(only_the_room) == 2
    assert localizer.update(only_the_room).status == "localized"


def test_after_a_kidnap_into_a_copy_the_copy_is_claimed_and_kept():
    """Each look's update holds every object in view (the coverage's contract): the copy's
    whole view ends the room's claim, then the copy is claimed, and its claim holds."""
    building = lookalikes()
    localizer = Localizer(building, local_up=[0, 0, 1])
    room_objects = local([o for o in building if o.id.startswith("a")])
    localizer.update(room_objects[:5], coverage=ALL_AROUND)
    localizer.update(room_objects, coverage=ALL_AROUND)
    there = local([o for o in building if o.id.startswith("b")], ids="k", shift=30.0)
    statuses = [localizer.update(there, coverage=ALL_AROUND) for _ in range(4)]
    assert [r.status for r in statuses] == ["ambiguous", "localized", "localized", "localized"]
    assert {g[0] for g, _ in statuses[-1].hypotheses[0].pairs} == {"b"}


def test_a_look_missing_objects_the_copy_lacks_ends_the_claim():
    """Tracking the copy, a look that misses the two objects only the copy holds (tv, bed)
    is explained by the room (it lacks them): two objects for the room, none for the copy."""
    building = lookalikes()
    localizer = Localizer(building, local_up=[0, 0, 1])
    there = local([o for o in building if o.id.startswith("b")], ids="k", shift=30.0)
    localizer.update(there, coverage=ALL_AROUND)
    assert localizer.update(there, coverage=ALL_AROUND).status == "localized"
    without_one = [o for o in there if o.id != "kb11"]
    assert localizer.update(without_one, coverage=ALL_AROUND).status == "localized"
    without_both = [o for o in there if o.id not in ("kb10", "kb11")]
    assert localizer.update(without_both, coverage=ALL_AROUND).reason == CONTRADICTED


def test_a_search_claim_that_the_newest_objects_contradict_is_not_made():
    building = ObjectMap(room(), up=[0, 0, 1])
    localizer = Localizer(building, local_up=[0, 0, 1], track=False)
    objects = local(list(building))
    localizer.update(objects[:8])
    wrong = [o.replace(id=f"w{o.id}", position=o.position + [0, 7.0, 0]) for o in objects[:3]]
    result = localizer.update(wrong)
    assert result.status == "ambiguous" and result.reason == NEWEST_CONTRADICT
    assert CONTRADICTED != NEWEST_CONTRADICT


def test_a_prior_picks_the_copy_inside_it_among_identical_copies():
    twins = ObjectMap([*room(), *room(offset=30.0, prefix="b")], up=[0, 0, 1])
    objects = local(room())
    for centre in ([0.0, 0, 0], [30.0, 0, 0]):
        result = Localizer(twins, local_up=[0, 0, 1], prior=Prior(centre, 5.0)).update(objects)
        assert result.status == "localized"
        assert result.pose[0, 3] == pytest.approx(centre[0], abs=0.1)
    assert Localizer(twins, local_up=[0, 0, 1]).update(objects).status == "ambiguous"


def held(min_pairs: int, track_min_pairs: int = 3) -> Localizer:
    """The room claimed on its ten objects, with these least pairs for a claim and a track."""
    building = ObjectMap(room(), up=[0, 0, 1])
    localizer = Localizer(building, local_up=[0, 0, 1], min_pairs=min_pairs,
                          tracking={"track_min_pairs": track_min_pairs})  # fmt: skip
    localizer.update(local(room())[:5])
    result = localizer.update(local(room())[5:])
    assert result.status == "localized" and len(result.best.pairs) == 10
    return localizer


@pytest.mark.parametrize(("min_pairs", "track_min_pairs"), [(10, 3), (3, 10)])
def test_a_track_holding_exactly_the_least_pairs_is_followed(min_pairs, track_min_pairs):
    """The least pairs of a track are the larger of tracking's and the decision's: a track
    with exactly that many supporting pairs in the window is still followed."""
    result = held(min_pairs, track_min_pairs).update([])
    assert result.status == "localized" and result.best.method.startswith("tracked/")


@pytest.mark.parametrize(("min_pairs", "track_min_pairs"), [(10, 3), (3, 10)])
def test_a_track_one_pair_short_of_the_least_lapses_into_the_search(min_pairs, track_min_pairs):
    """A changed re-detection drops its pair (nine left): the claim is not renewed, and the
    search, on nine pairs that still fit, claims only when nine are enough."""
    localizer = held(min_pairs, track_min_pairs)
    lamp = local(room())[2]
    result = localizer.update([lamp.replace(position=lamp.position + [1.5, 0, 0])])
    assert not result.best.method.startswith("tracked/")
    assert result.status == ("ambiguous" if min_pairs == 10 else "localized")


def test_a_restored_localizer_counts_a_copys_objects_as_the_uninterrupted_one():
    """One of the copy's own objects seen before the state is saved, the second after: the
    restored Localizer ends the claim at the same update (the copies and counts are state)."""
    building = lookalikes()
    room_objects = local([o for o in building if o.id.startswith("a")])
    there = local([o for o in building if o.id.startswith("b")], ids="k", shift=30.0)
    one = Localizer(building, local_up=[0, 0, 1])
    one.update(room_objects[:5])
    one.update(room_objects[5:])
    assert one.update(there[0::3]).reason == TWIN_DOUBTED  # the tv: one object of the copy
    state = json.loads(json.dumps(one.state()))
    assert state["twins"]["fits"] == [[3, [["+local kb10"]]]]  # the tv at the third update
    other = Localizer.restore(building, state, list(one.local_map), local_up=[0, 0, 1])
    assert other.tracking
    ended = [one.update(there[1::3]), other.update(there[1::3])]
    assert [r.reason for r in ended] == [CONTRADICTED] * 2 and not one.tracking


def motion(x: float, yaw: float = 0.0) -> np.ndarray:
    """A map motion: a turn by `yaw` about up, then `x` m along x."""
    S = np.eye(4)
    S[:2, :2] = [[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]]
    S[0, 3] = x
    return S


def test_kept_evidence_follows_a_copy_that_puts_the_robot_less_than_place_apart_away():
    """Walked on, the copies are looked up again: a new copy is the old one when it puts the
    robot less than `PLACE_APART` from where the old one did (it keeps its evidence); exactly
    that far, it is another copy and starts with none (an update left with none is dropped)."""
    at = np.array([1.0, 2.0, 0.0])
    old = motion(30.0, yaw=0.5)
    where = old[:3, :3] @ at + old[:3, 3]
    near, far = motion(0.0), motion(0.0)
    near[:3, 3] = where - at - [PLACE_APART - 1e-6, 0, 0]  # puts the robot just inside
    far[:3, 3] = where - at + [0, PLACE_APART, 0]  # exactly PLACE_APART away
    watch = CopyWatch(None, 12)  # (carrying the evidence reads no map)
    watch.fits.extend([(3, [["+local k1"]]), (5, [["-map a2"]])])
    watch._carry_fits([old], [far, near], at)
    assert list(watch.fits) == [(3, [[], ["+local k1"]]), (5, [[], ["-map a2"]])]
    watch._carry_fits([far, near], [far], at)
    assert list(watch.fits) == []


def test_a_restored_watch_looks_its_copies_up_through_the_tracked_places_anchor_pairs():
    """A copy lacking the objects of the first `ANCHORS` anchor pairs (their labels held once
    more, far off) is found only through more pairs: a restored watch finds it as the watch
    of a tracked place does (`TRACK_ANCHORS`)."""
    copy = [o for o in room(offset=30.0, prefix="b") if int(o.id[1:]) >= 3]
    far_off = [SemanticObject(f"c{i}", LABELS[i], [100.0 + 10 * i, 0, 0.5], size=[0.5, 0.5, 1])
               for i in range(3)]  # fmt: skip
    building = ObjectMap([*room(), *copy, *far_off], up=[0, 0, 1])
    context = Localizer(building, local_up=[0, 0, 1])._context
    members = np.array([building.index_of(f"a{i}") for i in range(10)])
    assert context.copies_of(members, ANCHORS) == []  # (the premise)
    watch = CopyWatch(context, 12)
    watch.restore({"members": [f"a{i}" for i in range(10)], "fits": []}, 4)
    (found,) = watch.copies[1]
    np.testing.assert_allclose(found[:3, 3], [30.0, 0, 0], atol=0.1)


def test_a_track_whose_refit_misses_its_pairs_by_exactly_the_tolerance_is_followed():
    """The refit's residual over its newest pairs may reach `track_tolerance`; just past it
    the pose no longer fits them and the claim is not renewed."""
    building = ObjectMap(room(), up=[0, 0, 1])
    localizer = claimed(building)
    track, sightings = localizer._track, localizer._sightings
    rng = np.random.default_rng(7)  # the pairs' objects a little off: a residual to meet
    noisy = [o.replace(position=o.position + [*rng.normal(0, 0.05, 2), 0])
             for o in local(room())]  # fmt: skip
    sightings.register(noisy)
    pose = track.pose.copy()
    residual = track.follow(sightings, 3, np.array([0, 0, 1.0]), False).residual
    assert residual > 0.01
    for tolerance, followed in [(residual, True), (np.nextafter(residual, 0), False)]:
        track.pose, track.config = (
            pose,
            track.config.model_copy(update={"track_tolerance": tolerance}),
        )
        assert (track.follow(sightings, 3, np.array([0, 0, 1.0]), False) is not None) == followed


@pytest.mark.parametrize(("drop", "missing"), [((3, 8), 0.0), ((1, 3, 8), 1.0)])
def test_a_tracks_check_counts_the_missing_objects_beyond_the_gone_share(drop, missing):
    """Of the eight map objects the look expects, two gone are exactly the share an old map
    loses (`GONE_SHARE`): none counts against the place; a third gone counts as one."""
    localizer = claimed(ObjectMap(room(), up=[0, 0, 1]))
    track, sightings = localizer._track, localizer._sightings
    objects = local(room(drop=drop))
    sightings.add(objects, None, ALL_AROUND)
    verdict, unseen, expected = track.check(sightings, objects)
    assert expected == 8 and len(unseen) == len(drop) and verdict.missing == missing
    assert verdict.repeated == 10 - len(drop)  # each re-detection of a pair is a repeat


def test_a_tracks_check_reads_a_split_detection_as_a_part_and_a_redetection_as_a_repeat():
    """Without a look, nothing is missing (no map object expected); a second detection by a
    paired object's chair, within its part distance, says nothing against the place."""
    localizer = claimed(ObjectMap(room(), up=[0, 0, 1]))
    track, sightings = localizer._track, localizer._sightings
    lamp = local(room())[2]
    split = lamp.replace(id="lsplit", position=lamp.position + [0.1, 0, 0])
    sightings.add([lamp, split], None, None)
    verdict, unseen, expected = track.check(sightings, [lamp, split])
    assert verdict.supported == [(2, "la2")] and verdict.repeated == 1
    assert verdict.contradicting == [] and verdict.changed == [] and verdict.missing == 0.0
    assert expected is None and len(unseen) == 0 and unseen.dtype.kind == "i"  # (indices)


@pytest.mark.parametrize(
    ("pose", "method"),
    [({}, "tracked/closed-form-4dof+icp"), ({"refine": False}, "tracked/closed-form-4dof"),
     ({"icp_max_points": 50}, "tracked/closed-form-4dof+icp")],
)  # fmt: skip
def test_a_track_is_refitted_on_its_objects_points_with_the_localizers_pose_settings(pose, method):
    """Follow refits the place on its pairs' object points (ICP after the closed form unless
    `refine` is off), each side's points prepared with the Localizer's pose settings."""
    rng = np.random.default_rng(1)
    objects = [o.replace(points=o.position + rng.uniform(-0.25, 0.25, (300, 3))) for o in room()]
    building = ObjectMap(objects, up=[0, 0, 1])
    localizer = Localizer(building, local_up=[0, 0, 1], pose=pose)
    localizer.update(local(objects)[:5])
    assert localizer.update(local(objects)[5:]).status == "localized"
    track, sightings = localizer._track, localizer._sightings
    followed = track.follow(sightings, 3, np.array([0, 0, 1.0]), False)
    assert followed.method == method and followed.fitness == 1.0 and followed.rmse < 1e-6
    assert followed.confidence == track.confidence is not None  # (the claim's, as found)
    assert followed.rank == 1 and followed.outside_prior is None  # (no prior in effect)
    assert track.follow(sightings, 3, np.array([0, 0, 1.0]), True).outside_prior is False
    cfg = localizer.config.pose
    for g, l in followed.pairs:
        for obj in (sightings.found[l][0], building[building.index_of(g)]):
            assert list(_CLOUDS[obj]) == [(cfg.icp_voxel, cfg.icp_max_points, cfg.seed)]
