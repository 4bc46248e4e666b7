"""\"Look there next\" (`semloc.next_look`): an ambiguous answer names the map objects that tell
its places apart, where they lie under each hypothesis, and following it decides."""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers import room
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import semloc
from semloc import Localizer, Look, ObjectMap, Result, SemanticObject
from semloc.next_look import WIDER_REACH, NextLookConfig, next_look
from semloc.transforms import pose_error, yaw_pose

SHIFT = np.array([40.0, 0.0, 0.0])
TRUTH = yaw_pose(0.3, [0.5, 0.5, 0.0])
MISSING = 2  # copy B lacks the last objects of copy A


def _world(missing: int) -> tuple[ObjectMap, list]:
    a = list(room(12))
    b = [o.replace(id=o.id.replace("a", "b"), position=o.position + SHIFT) for o in a]
    return ObjectMap([*a, *b[: len(b) - missing]], up=[0, 0, 1], name="two copies"), a


def _view(a: list, indices) -> ObjectMap:
    inverse = np.linalg.inv(TRUTH)
    objects = [a[i].transformed(inverse).replace(id=f"l{k}", seen=k) for k, i in enumerate(indices)]
    return ObjectMap(objects, up=[0, 0, 1], name="view of A")


def _rank_at(result: Result, pose: np.ndarray) -> int:
    return next(h.rank for h in result.hypotheses if pose_error(h.pose, pose)[1] < 0.05)


def test_an_ambiguous_answer_names_the_objects_that_tell_its_places_apart():
    world, a = _world(MISSING)
    result = semloc.localize(world, _view(a, range(5)))
    assert result.status == "ambiguous"
    looks = result.next_look
    assert looks, "an ambiguous answer with a telling object nearby suggests it"
    best = looks[0]
    assert best.global_id in {o.id for o in a[-MISSING:]}  # what copy B lacks
    rank_a = _rank_at(result, TRUTH)
    rank_b = _rank_at(result, yaw_pose(0.3, TRUTH[:3, 3] + SHIFT))
    assert rank_a in best.separates and rank_b not in best.separates
    position = world[world.index_of(best.global_id)].position
    for h in result.hypotheses[: len(best.where)]:  # where it lies under each hypothesis
        expected = np.linalg.inv(h.pose) @ np.append(position, 1.0)
        np.testing.assert_allclose(best.where[h.rank], expected[:3], atol=1e-9)
    assert 0.05 <= best.gain <= np.log2(len(result.hypotheses) + 1)
    assert [look.gain for look in looks] == sorted((look.gain for look in looks), reverse=True)


def test_following_the_suggestions_decides_the_place():
    world, a = _world(MISSING)
    localizer = Localizer(world, local_up=[0, 0, 1])
    result = localizer.update(list(_view(a, range(5))))
    looks = 0
    while result.status == "ambiguous" and looks < 3:
        look = result.next_look[0]
        rank_a = _rank_at(result, TRUTH)
        assert rank_a in look.separates  # (here every suggestion is about the true copy)
        seen = world[world.index_of(look.global_id)]  # the robot looks there and finds it
        found = seen.transformed(np.linalg.inv(TRUTH)).replace(
            id=f"looked{looks}", position=look.where[rank_a], seen=9 + looks
        )
        result = localizer.update([found])
        looks += 1
    assert result.status == "localized", result.reason
    assert pose_error(result.pose, TRUTH)[1] < 0.05


def test_identical_copies_have_nothing_to_suggest():
    world, a = _world(0)
    result = semloc.localize(world, _view(a, range(5)))
    assert result.status == "ambiguous"
    assert result.next_look == []


@pytest.mark.parametrize("indices", [range(12), range(1)])
def test_only_an_ambiguous_answer_has_suggestions(indices):
    world, a = _world(MISSING)
    result = semloc.localize(ObjectMap(a, up=[0, 0, 1], name="A"), _view(a, indices))
    assert result.status in ("localized", "failed")
    assert result.next_look == [] and result.to_dict()["next_look"] == []


def test_suggestions_round_trip_through_json():
    world, a = _world(MISSING)
    result = semloc.localize(world, _view(a, range(5)))
    document = result.to_dict()
    assert document["next_look"][0]["global_id"] == result.next_look[0].global_id
    assert set(document["next_look"][0]) == {"label", "global_id", "where", "separates", "gain"}
    back = Result.from_dict(document)
    assert [look.to_dict() for look in back.next_look] == document["next_look"]
    document["next_look"][0]["where"] = {"1": [0, "x", 0]}
    with pytest.raises(ValueError, match=r"'next_look\[0\].where.1\[1\]' must be a valid number"):
        Result.from_dict(document)
    assert isinstance(back.next_look[0], Look)


@settings(max_examples=15, suppress_health_check=[HealthCheck.too_slow])
@given(
    seed=st.integers(0, 50),
    shift=st.tuples(st.floats(20, 60), st.floats(-30, 30)),
    yaw=st.floats(-np.pi, np.pi),
    dropped=st.integers(1, 3),
)
def test_every_suggestion_holds_what_it_says(seed, shift, yaw, dropped):
    """Whatever the rooms and where the copy lies: a suggestion weighs two or more of the top
    hypotheses (its `where`), `where[r]` is the object under hypothesis r, a separated rank's
    spot is within the widest reach and no other weighed hypothesis expects an object of the
    label there, and the gain is the entropy of the outcome (bits)."""
    a = list(room(12, seed=seed))
    turn = yaw_pose(yaw, [shift[0], shift[1], 0.0])
    b = [o.transformed(turn).replace(id=o.id.replace("a", "b")) for o in a[: len(a) - dropped]]
    world = ObjectMap([*a, *b], up=[0, 0, 1], name="two copies")
    result = semloc.localize(world, _view(a, range(5)))
    config = NextLookConfig()
    top = {h.rank: h for h in result.hypotheses if h.pose is not None}
    seen = np.array([o.position for o in _view(a, range(5))])
    for look in result.next_look:
        position = world[world.index_of(look.global_id)].position
        assert look.label == world[world.index_of(look.global_id)].label
        weighed = [top[rank] for rank in look.where]
        assert 2 <= len(weighed) <= config.look_hypotheses and set(look.separates) <= set(top)
        for h in weighed:
            expected = np.linalg.inv(h.pose) @ np.append(position, 1.0)
            np.testing.assert_allclose(look.where[h.rank], expected[:3], atol=1e-9)
        for rank in look.separates:
            spot = look.where[rank]
            assert np.linalg.norm(seen - spot, axis=1).min() <= WIDER_REACH * config.look_reach
            for other in (h for h in weighed if h.rank != rank):
                at = other.pose[:3, :3] @ spot + other.pose[:3, 3]
                near = np.linalg.norm(world.positions - at, axis=1) <= config.look_tolerance
                assert look.label not in set(world.labels[near])
        assert 0 < look.gain <= np.log2(len(look.separates) + 1) + 1e-9


def test_a_look_that_sees_more_telling_objects_comes_first():
    """Equal gains: the spot with two objects the other copy lacks beats a nearer spot with
    one (a look sees an area, not one object)."""
    seen = [("chair", [0, 0]), ("table", [1.5, 0.3]), ("cabinet", [0.2, 2.1]),
            ("bookshelf", [2.4, 2.6]), ("sofa", [1.0, 3.8])]  # fmt: skip
    extra = [("tv", [-2.5, 1.0]), ("lamp", [5.5, 1.0]), ("plant", [6.2, 1.8])]
    a = [SemanticObject(f"a{i}", label, [x, y, 0.5]) for i, (label, (x, y)) in
         enumerate(seen + extra)]  # fmt: skip
    b = [o.replace(id=o.id.replace("a", "b"), position=o.position + SHIFT) for o in a[:5]]
    world = ObjectMap([*a, *b], up=[0, 0, 1], name="copy without tv, lamp and plant")
    result = semloc.localize(world, _view(a, range(5)))
    assert result.status == "ambiguous"
    labels = [look.label for look in result.next_look]
    assert set(labels) == {"tv", "lamp", "plant"}
    assert len({round(look.gain, 6) for look in result.next_look}) == 1  # equal gains
    assert labels[0] in {"lamp", "plant"} and labels[-1] == "tv"


# --- the widening rules (issue 59): built from the rules, on hand-made places -----------------
def _places(
    offsets: list[float], lamps: dict[int, float], plants: tuple[float, ...] = ()
) -> tuple[ObjectMap, list]:
    """A table at each offset along x (a place, and a hypothesis putting the local table
    there), a lamp `lamps[i]` metres beside the table of place i, and plants at `plants`."""
    objects = [SemanticObject(f"t{i}", "table", [x, 0.0, 0.5]) for i, x in enumerate(offsets)]
    objects += [SemanticObject(f"lamp{i}", "lamp", [offsets[i] + d, 0.0, 0.5])
                for i, d in lamps.items()]  # fmt: skip
    objects += [SemanticObject(f"plant{i}", "plant", [x, 0.0, 0.5]) for i, x in enumerate(plants)]
    hypotheses = [
        semloc.Hypothesis(rank=i + 1, score=1.0, pairs=[(f"t{i}", "l0")],
                          pose=yaw_pose(0.0, [x, 0.0, 0.0]), confidence=0.2)
        for i, x in enumerate(offsets)
    ]  # fmt: skip
    return ObjectMap(objects, up=[0, 0, 1], name="places"), hypotheses


def _suggest(world: ObjectMap, hypotheses: list) -> list[Look]:
    return next_look(hypotheses, world, ["table"], np.array([[0.0, 0.0, 0.5]]))


@pytest.mark.parametrize("lamps, weighed", [((0, 2, 3, 4), [1, 2]), ((0, 3, 4), [1, 2, 3])])
def test_when_no_spot_tells_all_places_apart_the_best_few_are_told_apart(lamps, weighed):
    """A lamp beside places 1, 3, 4 and 5: every lamp spot is expected by another of the best
    five, four and three, none by place 2: the suggestion tells rank 1 from rank 2, weighing
    those two.  Without the lamp of place 3 it tells the best three apart."""
    world, hypotheses = _places([0.0, 20.0, 40.0, 60.0, 80.0], dict.fromkeys(lamps, 3.0))
    looks = _suggest(world, hypotheses)
    assert looks, "an ambiguous answer with two places that a look tells apart gets a suggestion"
    assert looks[0].label == "lamp" and looks[0].separates == [1]
    assert sorted(looks[0].where) == weighed


def test_a_rival_outside_the_prior_is_weighed_when_one_place_lies_inside():
    world, hypotheses = _places([0.0, 20.0], {0: 3.0})
    hypotheses[0].outside_prior, hypotheses[1].outside_prior = False, True
    looks = _suggest(world, hypotheses)
    assert looks and looks[0].separates == [1] and sorted(looks[0].where) == [1, 2]


@pytest.mark.parametrize("distance", [12.0, 30.0])
def test_a_telling_spot_beyond_reach_is_suggested(distance):
    """Nothing within `look_reach` (8 m) tells the places apart; a lamp 12 or 30 m off does
    (within `WIDER_REACH` x reach)."""
    world, hypotheses = _places([0.0, 100.0], {0: distance})
    looks = _suggest(world, hypotheses)
    assert [look.global_id for look in looks] == ["lamp0"]
    np.testing.assert_allclose(looks[0].where[1], [distance, 0.0, 0.5])


def test_the_nearer_widening_comes_first():
    """A lamp 12 m off and two plants 25 m off each tell the places apart; the two plants
    would be seen by one look, but a robot looks nearer first: within twice the reach the
    lamp alone is suggested."""
    world, hypotheses = _places([0.0, 100.0], {0: 12.0}, plants=(25.0, 25.5))
    assert [look.global_id for look in _suggest(world, hypotheses)] == ["lamp0"]


def test_no_suggestion_beyond_the_widest_reach():
    world, hypotheses = _places([0.0, 100.0], {0: WIDER_REACH * NextLookConfig().look_reach + 1})
    assert _suggest(world, hypotheses) == []


def test_a_suggestion_within_reach_weighs_every_top_place():
    """What the widening must not change: a spot that tells rank 1 from all the others is
    suggested over all of them."""
    world, hypotheses = _places([0.0, 20.0, 40.0], {0: 3.0})
    looks = _suggest(world, hypotheses)
    assert looks[0].separates == [1] and sorted(looks[0].where) == [1, 2, 3]


def test_a_spot_already_looked_at_is_not_suggested():
    """A lamp beside place 1 tells it from place 2, unless a lamp was seen within
    `look_tolerance` of where place 1 puts it: what that spot shows is already evidence."""
    world, hypotheses = _places([0.0, 100.0], {0: 3.0})
    tolerance = NextLookConfig().look_tolerance

    def suggest(offset: float) -> list[Look]:
        seen = np.array([[0.0, 0.0, 0.5], [3.0, offset, 0.5]])
        return next_look(hypotheses, world, ["table", "lamp"], seen)

    assert suggest(tolerance) == []
    assert [(look.global_id, look.separates) for look in suggest(tolerance + 0.01)] == [
        ("lamp0", [1])
    ]


def test_a_spot_exactly_at_the_reach_is_within_it():
    """A lamp exactly `look_reach` from the table seen tells place 1 from both others in the
    first search (all three weighed), not in a widened one."""
    world, hypotheses = _places([0.0, 20.0, 40.0], {0: NextLookConfig().look_reach})
    looks = _suggest(world, hypotheses)
    assert [look.global_id for look in looks] == ["lamp0"] and sorted(looks[0].where) == [1, 2, 3]


def test_a_suggestion_exactly_at_the_least_gain_is_kept():
    """Four equally likely places (no confidences): telling one from the rest gains
    H(1/4, 3/4) bits; with that as the least gain the first search keeps it."""
    world, hypotheses = _places([0.0, 20.0, 40.0, 60.0], {0: 3.0})
    for h in hypotheses:
        h.confidence = None
    gain = -sum(p * math.log2(p) for p in [0.25, 0.75])
    config = NextLookConfig(look_min_gain=gain)
    looks = next_look(hypotheses, world, ["table"], np.array([[0.0, 0.0, 0.5]]), config)
    assert sorted(looks[0].where) == [1, 2, 3, 4] and looks[0].gain == gain


def test_the_places_inside_the_prior_are_weighed_when_two_lie_inside():
    world, hypotheses = _places([0.0, 20.0, 40.0], {0: 3.0})
    for h, outside in zip(hypotheses, [False, False, True]):
        h.outside_prior = outside
    looks = _suggest(world, hypotheses)
    assert looks[0].separates == [1] and sorted(looks[0].where) == [1, 2]


def test_the_best_two_are_told_apart_within_reach_before_the_search_widens():
    """Places 1 and 3 both have a lamp 3 m off (no spot tells the best three apart); a plant
    12 m behind place 1 would tell it too, but only a wider look reaches it: within
    `look_reach` the lamp alone tells the best two apart."""
    world, hypotheses = _places([0.0, 20.0, 40.0], {0: 3.0, 2: 3.0}, plants=(-12.0,))
    looks = _suggest(world, hypotheses)
    assert [look.global_id for look in looks] == ["lamp0"] and sorted(looks[0].where) == [1, 2]


def test_the_second_widening_reaches_twice_the_reach():
    """A lamp 12 m off (within twice the reach) is suggested alone; two plants 17 m off
    would be seen by one look, but lie beyond twice the reach."""
    world, hypotheses = _places([0.0, 100.0], {0: 12.0}, plants=(17.0, 17.5))
    assert [look.global_id for look in _suggest(world, hypotheses)] == ["lamp0"]


def test_the_widest_search_takes_any_gain():
    """One place is all but sure: telling it from the other gains far less than
    `look_min_gain`, yet an ambiguous answer still gets the one look that tells them apart."""
    world, hypotheses = _places([0.0, 100.0], {0: 3.0})
    hypotheses[0].confidence, hypotheses[1].confidence = 0.999, 0.001
    looks = _suggest(world, hypotheses)
    assert [look.global_id for look in looks] == ["lamp0"]
    assert 0 < looks[0].gain < NextLookConfig().look_min_gain


def test_equal_gains_are_ordered_by_what_one_look_sees_then_by_distance():
    """Three spots tell place 1 apart, 2 m apart each (`look_sight`): the middle one sees all
    three; of the two that see two, the nearer comes first.  At most `suggestions`."""
    world, hypotheses = _places([0.0, 100.0], {0: 3.0}, plants=(5.0, 7.0))
    looks = _suggest(world, hypotheses)
    assert [look.global_id for look in looks] == ["plant0", "lamp0", "plant1"]
    config = NextLookConfig(suggestions=2)
    looks = next_look(hypotheses, world, ["table"], np.array([[0.0, 0.0, 0.5]]), config)
    assert [look.global_id for look in looks] == ["plant0", "lamp0"]


def test_two_objects_of_a_label_look_tolerance_apart_are_two_spots():
    world, hypotheses = _places(
        [0.0, 100.0], {}, plants=(5.0, 5.0 + NextLookConfig().look_tolerance)
    )
    assert [look.global_id for look in _suggest(world, hypotheses)] == ["plant0", "plant1"]


def test_a_one_object_map_can_tell_two_places_apart():
    """A lamp 3 m beside place 1 of a map holding nothing else tells it from place 2."""
    world = ObjectMap([SemanticObject("lamp", "lamp", [3.0, 0.0, 0.5])], up=[0, 0, 1])
    _, hypotheses = _places([0.0, 20.0], {})
    looks = _suggest(world, hypotheses)
    assert [(look.global_id, look.separates) for look in looks] == [("lamp", [1])]


@pytest.mark.parametrize("suggestions", [0, 1])
def test_at_most_the_configured_suggestions(suggestions):
    world, hypotheses = _places([0.0, 100.0], {0: 3.0}, plants=(5.0, 7.0))
    config = NextLookConfig(suggestions=suggestions)
    looks = next_look(hypotheses, world, ["table"], np.array([[0.0, 0.0, 0.5]]), config)
    assert len(looks) == suggestions


def test_the_second_widening_weighs_the_best_two():
    """A lamp 12 m beside place 1 of three: only the search widened to twice the reach finds
    it, and that search weighs the best two places."""
    world, hypotheses = _places([0.0, 100.0, 200.0], {0: 12.0})
    looks = _suggest(world, hypotheses)
    assert [look.global_id for look in looks] == ["lamp0"] and sorted(looks[0].where) == [1, 2]


def test_the_gain_weighs_the_places_by_their_confidences_normalised():
    """Confidences 0.2, 0.2 and none: the place without one weighs nothing, the two others
    half each, so telling place 1 apart gains 1 bit."""
    world, hypotheses = _places([0.0, 20.0, 40.0], {0: 3.0})
    hypotheses[2].confidence = None
    looks = _suggest(world, hypotheses)
    assert looks[0].separates == [1] and looks[0].gain == pytest.approx(1.0)


def test_a_telling_object_beside_the_second_place_is_found_through_its_pose():
    world, hypotheses = _places([0.0, 20.0], {1: 3.0})
    looks = _suggest(world, hypotheses)
    assert [(look.global_id, look.separates) for look in looks] == [("lamp1", [2])]
    assert sorted(looks[0].where) == [1, 2]


def test_a_spot_below_the_least_gain_does_not_hide_the_spots_after_it():
    """Place 3 is all but ruled out: its lamp (listed first in the map) tells too little, the
    plant beside place 1 tells enough, in the first search over all three places."""
    world, hypotheses = _places([0.0, 20.0, 40.0], {2: 3.0}, plants=(-3.0,))
    for h, confidence in zip(hypotheses, [0.96, 0.035, 0.005]):
        h.confidence = confidence
    looks = _suggest(world, hypotheses)
    assert [look.global_id for look in looks] == ["plant0"]
    assert sorted(looks[0].where) == [1, 2, 3]


@pytest.mark.parametrize("apart", [0.5, 0.99])
def test_two_objects_of_a_label_within_look_tolerance_are_one_spot(apart):
    """Plants 0.5 m apart beside place 1 are one spot: the nearer is suggested, and the look
    after it is the lamp, another spot."""
    world, hypotheses = _places([0.0, 100.0], {0: -4.0}, plants=(5.0, 5.0 + apart))
    assert [look.global_id for look in _suggest(world, hypotheses)] == ["plant0", "lamp0"]


def test_no_posed_hypothesis_has_nothing_to_suggest():
    world, hypotheses = _places([0.0, 20.0], {0: 3.0})
    for h in hypotheses:
        h.pose = None
    assert _suggest(world, hypotheses) == [] and _suggest(world, []) == []
