"""\"Look there next\" (`semloc.next_look`): an ambiguous answer names the map objects that tell
its places apart, where they lie under each hypothesis, and following it decides."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import room
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import semloc
from semloc import Localizer, Look, ObjectMap, Result, SemanticObject
from semloc.next_look import NextLookConfig
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
    with pytest.raises(ValueError, match=r"'next_look\[0\]' is not a suggestion"):
        Result.from_dict(document)
    assert isinstance(back.next_look[0], Look)


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    seed=st.integers(0, 50),
    shift=st.tuples(st.floats(20, 60), st.floats(-30, 30)),
    yaw=st.floats(-np.pi, np.pi),
    dropped=st.integers(1, 3),
)
def test_every_suggestion_holds_what_it_says(seed, shift, yaw, dropped):
    """Whatever the rooms and where the copy lies: `where[r]` is the object under hypothesis
    r, a separated rank's spot is in reach and no other top hypothesis expects an object of
    the label there, and the gain is the entropy of the outcome (bits)."""
    a = list(room(12, seed=seed))
    turn = yaw_pose(yaw, [shift[0], shift[1], 0.0])
    b = [o.transformed(turn).replace(id=o.id.replace("a", "b")) for o in a[: len(a) - dropped]]
    world = ObjectMap([*a, *b], up=[0, 0, 1], name="two copies")
    result = semloc.localize(world, _view(a, range(5)))
    config = NextLookConfig()
    top = [h for h in result.hypotheses if h.pose is not None][: config.look_hypotheses]
    seen = np.array([o.position for o in _view(a, range(5))])
    for look in result.next_look:
        position = world[world.index_of(look.global_id)].position
        assert look.label == world[world.index_of(look.global_id)].label
        for h in top:
            expected = np.linalg.inv(h.pose) @ np.append(position, 1.0)
            np.testing.assert_allclose(look.where[h.rank], expected[:3], atol=1e-9)
        for rank in look.separates:
            spot = look.where[rank]
            assert np.linalg.norm(seen - spot, axis=1).min() <= config.look_reach
            for other in (h for h in top if h.rank != rank):
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
