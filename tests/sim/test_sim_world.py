"""Generated worlds: deterministic per seed, furnished as specified, with repeated instances."""

from __future__ import annotations

from collections import Counter

import numpy as np
import pytest

from semloc.sim.shapes import STYLES, model
from semloc.sim.world import SIZES, generate_world


def _signature(world):
    return [(o.id, o.label, o.style, o.room, np.round(o.pose, 9).tobytes()) for o in world.objects]


def test_same_seed_gives_the_same_world():
    a, b = generate_world(4, "small"), generate_world(4, "small")
    assert _signature(a) == _signature(b)
    assert a.summary() == b.summary()
    assert all(np.array_equal(m.vertices, n.vertices) for m, n in zip(a.background, b.background))


def test_different_seeds_give_different_worlds():
    assert _signature(generate_world(1, "small")) != _signature(generate_world(2, "small"))


@pytest.mark.parametrize(("size", "lo", "hi"), [("tiny", 10, 25), ("small", 30, 80)])
def test_sizes_have_the_expected_number_of_objects(size, lo, hi):
    world = generate_world(0, size)
    assert len(world.rooms) == SIZES[size]
    assert lo <= len(world.objects) <= hi


def test_a_building_has_hundreds_of_objects():
    world = generate_world(0, "building")
    assert len(world.objects) >= 200
    assert {r.kind for r in world.rooms} >= {"classroom", "meeting", "office", "bedroom", "kitchen"}


def test_classrooms_and_meeting_rooms_repeat_identical_chairs():
    for seed in range(3):
        world = generate_world(seed, "small")
        for room in world.rooms:
            if room.kind in ("classroom", "meeting"):
                chairs = Counter(
                    o.style for o in world.objects if o.room == room.index and o.label == "chair"
                )
                assert max(chairs.values()) >= 4, (seed, room.kind, chairs)


def test_objects_stay_inside_their_rooms():
    world = generate_world(5, "medium")
    for obj in world.objects:
        room = world.rooms[obj.room]
        lo, hi = obj.footprint()
        assert np.all(lo >= np.asarray(room.lo) - 1e-6) and np.all(
            hi <= np.asarray(room.hi) + 1e-6
        ), obj


def test_consecutive_rooms_of_the_walk_share_a_door():
    world = generate_world(0, "medium")
    order = world.walk_order()
    assert sorted(order) == list(range(len(world.rooms)))
    for a, b in zip(order, order[1:]):
        assert world.door_between(a, b) is not None


def test_every_class_has_several_distinct_styles():
    for label, styles in STYLES.items():
        meshes = [model(label, s).mesh for s in range(len(styles))]
        assert len(meshes) >= 2, label
        for a, b in zip(meshes, meshes[1:]):
            different = a.vertices.shape != b.vertices.shape or not np.allclose(
                a.vertices, b.vertices
            )
            assert different, label


def test_bad_sizes_are_rejected():
    with pytest.raises(ValueError, match="unknown world size"):
        generate_world(0, "huge")
    with pytest.raises(ValueError):
        generate_world(0, 0)
