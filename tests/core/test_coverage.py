"""The sensor's coverage (`semloc.coverage`): what a look shows, and the negative evidence of
what a place predicts in it that nobody saw."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from semloc import Coverage
from semloc.coverage import Looks, checked_coverage, expected_unseen
from semloc.transforms import yaw_rotation

CAMERA = np.array([[0.0, 0, 1, 0], [-1, 0, 0, 0], [0, -1, 0, 0], [0, 0, 0, 1]])
"""A camera at the origin looking along +x (its +z), x right = -y, y down = -z."""


def test_a_look_shows_what_lies_ahead_within_its_range_and_field_of_view():
    look = Coverage(CAMERA, 5.0, (90.0, 60.0))
    points = [[3, 0, 0], [3, 2.9, 0], [3, 3.1, 0], [-3, 0, 0], [5.1, 0, 0], [3, 0, 2.0]]
    assert look.covers(points).tolist() == [True, True, False, False, False, False]
    assert look.covers([[3.9, 0, 0]], range_share=0.8).tolist() == [True]
    assert look.covers([[4.1, 0, 0]], range_share=0.8).tolist() == [False]
    assert look.covers([[3, 2.9, 0]], margin_deg=5.0).tolist() == [False]  # 44 deg off axis


def test_a_look_without_field_of_view_shows_all_around():
    look = Coverage(np.eye(4), 2.0)
    assert look.covers([[0, 0, -1.9], [1, 1, 1], [2, 0, 1]]).tolist() == [True, True, False]


@given(
    yaw=st.floats(-np.pi, np.pi),
    xyz=st.tuples(*[st.floats(-50, 50)] * 3),
    depth=st.floats(0.1, 3.5),  # (at 0.9 to the side: 4.7 m of the 5 m range)
    side=st.floats(-0.9, 0.9),
)
@settings(max_examples=60)
def test_any_posed_look_shows_points_on_its_axis_and_not_behind(yaw, xyz, depth, side):
    pose = np.eye(4)
    pose[:3, :3] = yaw_rotation(yaw)
    pose[:3, 3] = xyz
    pose = pose @ CAMERA
    look = Coverage(pose, 5.0, (120.0, 90.0))
    ahead = pose @ [side * depth, 0, depth, 1]  # within 42 deg of the axis
    behind = pose @ [0, 0, -depth, 1]
    assert look.covers([ahead[:3], behind[:3]]).tolist() == [True, False]


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"pose": np.eye(3), "range_m": 1.0}, "4x4"),
        ({"pose": 2 * np.eye(4), "range_m": 1.0}, "rigid"),
        ({"pose": np.eye(4), "range_m": 0.0}, "positive"),
        ({"pose": np.eye(4), "range_m": float("nan")}, "finite"),
        ({"pose": np.eye(4), "range_m": 1.0, "fov_deg": (0.0, 30.0)}, "fov_deg"),
        ({"pose": np.eye(4), "range_m": 1.0, "fov_deg": (30.0,)}, "fov_deg"),
    ],
)
def test_a_bad_coverage_is_refused_with_what_is_wrong(kwargs, message):
    with pytest.raises(ValueError, match=message):
        Coverage(**kwargs)


def test_coverage_round_trips_through_its_dict_and_refuses_unknown_fields():
    look = Coverage(CAMERA, 4.0, (90.0, 60.0))
    again = Coverage.from_dict(look.to_dict())
    assert np.array_equal(again.pose, look.pose) and again.fov_deg == (90.0, 60.0)
    assert checked_coverage(look.to_dict()).range_m == 4.0
    assert checked_coverage(None) is None
    with pytest.raises(ValueError, match="unknown fields"):
        Coverage.from_dict({**look.to_dict(), "range": 3})
    with pytest.raises(ValueError, match="range_m"):
        Coverage.from_dict({"pose": np.eye(4).tolist()})
    with pytest.raises(TypeError, match="semloc.Coverage"):
        checked_coverage("wide")


def _map_in_front() -> tuple[np.ndarray, np.ndarray]:
    """Four map objects ahead of the camera: two chairs side by side, a table, a lamp."""
    positions = np.array([[2.0, -0.5, 0], [2.0, 1.5, 0], [3.0, -1.5, 0], [3.5, 0.5, 0]])
    return positions, np.full(4, 0.5)


def test_the_objects_a_place_puts_in_view_that_nobody_detected_are_unseen():
    positions, sizes = _map_in_front()
    look = Coverage(CAMERA, 5.0, (120.0, 90.0))
    allowance = np.full(4, 0.6)
    local = [(positions[0], np.array([0, 1])), (positions[3], np.array([3]))]
    expected, unseen = expected_unseen(np.eye(4), [look], positions, sizes, local, allowance)
    assert expected.tolist() == [0, 1, 2, 3] and unseen.tolist() == [1, 2]


def test_a_detection_accounts_for_one_map_object_only_and_a_moved_one_for_its_old_place():
    positions, sizes = _map_in_front()
    look = Coverage(CAMERA, 5.0, (120.0, 90.0))
    allowance = np.full(4, 0.6)
    moved_chair = (np.array([2.0, 0.5, 0]), np.array([0, 1]))  # 1 m from both chairs
    _, unseen = expected_unseen(np.eye(4), [look], positions, sizes, [moved_chair], allowance)
    assert unseen.tolist() in ([1, 2, 3], [0, 2, 3])  # one chair accounted, not both
    far_chair = (np.array([2.0, 5.0, 0]), np.array([0, 1]))  # 3.5 m from the nearer chair
    _, unseen = expected_unseen(np.eye(4), [look], positions, sizes, [far_chair], allowance)
    assert unseen.tolist() == [0, 1, 2, 3]
    near = Looks(move_m=4.0)
    _, unseen = expected_unseen(np.eye(4), [look], positions, sizes, [far_chair], allowance, near)
    assert unseen.tolist() == [0, 2, 3]


def test_an_object_behind_two_others_is_not_expected():
    positions = np.array([[1.0, 0, 0], [2.0, 0, 0], [3.0, 0, 0]])
    look = Coverage(CAMERA, 5.0, (120.0, 90.0))
    expected, _ = expected_unseen(
        np.eye(4), [look], positions, np.full(3, 0.6), [], np.full(3, 0.6)
    )
    assert expected.tolist() == [0, 1]  # the third stands behind two
    expected, _ = expected_unseen(
        np.eye(4), [look], positions, np.full(3, 0.6), [], np.full(3, 0.6), Looks(max_in_front=2)
    )
    assert expected.tolist() == [0, 1, 2]


def test_a_look_elsewhere_or_no_look_expects_nothing():
    positions, sizes = _map_in_front()
    away = np.eye(4)
    away[:3, 3] = [-20, 0, 0]
    look = Coverage(away @ CAMERA, 5.0, (120.0, 90.0))
    expected, unseen = expected_unseen(np.eye(4), [look], positions, sizes, [], np.full(4, 0.6))
    assert expected.tolist() == [] and unseen.tolist() == []
    expected, unseen = expected_unseen(np.eye(4), [], positions, sizes, [], np.full(4, 0.6))
    assert expected.tolist() == [] and unseen.tolist() == []


# The rules at their boundaries ----------------------------------------------------------------
def test_a_look_shows_a_point_exactly_at_its_range_and_its_field_of_view_s_edges():
    look = Coverage(CAMERA, 5.0, (90.0, 90.0))
    on_edges = [[5, 0, 0], [3, 3, 0], [3, 0, 3]]  # at the range, 45 deg to the side and up
    beyond = [[5.01, 0, 0], [3, 3.01, 0], [3, 0, 3.01]]
    assert look.covers(on_edges).tolist() == [True, True, True]
    assert look.covers(beyond).tolist() == [False, False, False]
    narrow = Coverage(CAMERA, 5.0, (90.0, 60.0))  # 30 deg up and down
    assert narrow.covers([[3, 0, 1.6]]).tolist() == [True]  # 28 deg up
    assert narrow.covers([[3, 0, 1.6]], margin_deg=5.0).tolist() == [False]  # 2 deg inside 25


@pytest.mark.parametrize(
    "pose",
    [
        np.diag([1.2, 1.2, 1.2, 1.0]),  # a scaled rotation, a rigid last row
        np.array([[1.0, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [1, 0, 0, 1]]),  # a bad last row
    ],
)
def test_a_pose_that_is_not_rigid_is_refused_whichever_part_is_wrong(pose):
    with pytest.raises(ValueError, match=r"^coverage pose must be a rigid transform"):
        Coverage(pose, 1.0)


def test_a_coverage_accepts_what_is_valid_at_its_bounds_and_stores_floats():
    nearly = np.eye(4)
    nearly[0, 1] = 1e-6  # a rotation as a float32 camera driver sends it
    assert Coverage(nearly, 1.0).range_m == 1.0
    assert Coverage(np.eye(4), 1.0, (0.5, 360.0)).fov_deg == (0.5, 360.0)
    with pytest.raises(ValueError, match="fov_deg"):
        Coverage(np.eye(4), 1.0, (360.5, 30.0))
    look = Coverage(np.eye(4, dtype=int).tolist(), 5)
    assert isinstance(look.pose, np.ndarray) and look.pose.dtype == float
    assert type(look.range_m) is float
    assert look.to_dict() == {"pose": np.eye(4).tolist(), "range_m": 5.0, "fov_deg": None}


def test_a_coverage_that_is_not_one_is_refused_with_what_it_is():
    with pytest.raises(ValueError, match=r"^coverage must be an object, got list$"):
        Coverage.from_dict([1, 2])
    with pytest.raises(ValueError, match=r"^coverage is malformed \("):
        Coverage.from_dict({"pose": np.eye(4).tolist(), "range_m": 1.0, "fov_deg": 5})
    with pytest.raises(TypeError, match=r"^coverage must be a semloc.Coverage, got str$"):
        checked_coverage("wide")


def test_no_look_expects_nothing_as_indices_that_index_the_map():
    positions, sizes = _map_in_front()
    expected, unseen = expected_unseen(np.eye(4), [], positions, sizes, [], np.full(4, 0.6))
    assert positions[expected].shape == (0, 3) and positions[unseen].shape == (0, 3)


def test_a_hypothesis_elsewhere_in_the_map_expects_the_objects_it_puts_in_view():
    positions, sizes = _map_in_front()
    shift = np.array([10.0, 5.0, 0.0])
    pose = np.eye(4)
    pose[:3, 3] = shift  # T_global_local: the local frame's origin at (10, 5, 0)
    look = Coverage(CAMERA, 5.0, (120.0, 90.0))
    local = [(positions[0], np.array([0, 1])), (positions[3], np.array([3]))]
    expected, unseen = expected_unseen(
        pose, [look], positions + shift, sizes, local, np.full(4, 0.6)
    )
    assert expected.tolist() == [0, 1, 2, 3] and unseen.tolist() == [1, 2]


def test_only_the_map_objects_worth_testing_are_expected_and_every_look_counts():
    positions, sizes = _map_in_front()
    look = Coverage(CAMERA, 5.0, (120.0, 90.0))
    args = (np.eye(4), [look], positions, sizes, [], np.full(4, 0.6))
    assert expected_unseen(*args, near=np.array([1, 3]))[0].tolist() == [1, 3]
    right, left = np.eye(4), np.eye(4)
    right[:3, :3], left[:3, :3] = yaw_rotation(-np.pi / 8), yaw_rotation(np.pi / 8)
    looks = [
        Coverage(right @ CAMERA, 5.0, (40.0, 40.0)),
        Coverage(left @ CAMERA, 5.0, (40.0, 40.0)),
    ]
    shown = [expected_unseen(np.eye(4), [look], *args[2:])[0].tolist() for look in looks]
    assert shown == [[0, 2], [1, 3]]  # each look shows two objects
    assert expected_unseen(np.eye(4), looks, *args[2:])[0].tolist() == [0, 1, 2, 3]  # both looks


def test_an_object_near_the_edge_of_the_view_is_expected_only_within_the_margin():
    positions = np.array([[3.0, 2.9, 0]])  # 44 deg off the axis of a 90 deg view
    look = Coverage(CAMERA, 6.0, (90.0, 90.0))
    args = (np.eye(4), [look], positions, np.full(1, 0.5), [], np.full(1, 0.6))
    assert expected_unseen(*args)[0].tolist() == []  # default margin: 5 deg
    assert expected_unseen(*args, Looks(margin_deg=0.0))[0].tolist() == [0]


def test_a_detection_within_its_allowance_accounts_for_its_nearest_candidate():
    positions, sizes = _map_in_front()
    look = Coverage(CAMERA, 5.0, (120.0, 90.0))
    allowance = np.full(4, 0.5)
    # exactly at the allowance from chair 0: accounted even when no move is allowed
    at_edge = (positions[0] + [0.5, 0, 0], np.array([0]))
    _, unseen = expected_unseen(
        np.eye(4), [look], positions, sizes, [at_edge], allowance, Looks(move_m=0.4)
    )
    assert unseen.tolist() == [1, 2, 3]
    # a detection without candidates accounts for nothing and does not stop the others
    nothing = (np.array([2.0, 0.0, 0.0]), np.array([], dtype=int))
    _, unseen = expected_unseen(
        np.eye(4), [look], positions, sizes, [nothing, (positions[3], np.array([3]))], allowance
    )
    assert unseen.tolist() == [0, 1, 2]
    # chair 0 is seen twice at its place: the other chair is not taken for a moved chair 0
    beside = (positions[0] + [0.3, 0, 0], np.array([1, 0]))
    on_it = (positions[0], np.array([0]))
    _, unseen = expected_unseen(np.eye(4), [look], positions, sizes, [beside, on_it], allowance)
    assert unseen.tolist() == [1, 2, 3]


def test_a_moved_object_exactly_the_plausible_move_away_accounts_for_its_old_place():
    positions, sizes = _map_in_front()
    look = Coverage(CAMERA, 5.0, (120.0, 90.0))
    far_chair = (np.array([2.0, 5.0, 0]), np.array([0, 1]))  # 3.5 m from chair 1
    _, unseen = expected_unseen(
        np.eye(4), [look], positions, sizes, [far_chair], np.full(4, 0.6), Looks(move_m=3.5)
    )
    assert unseen.tolist() == [0, 2, 3]


def test_what_stands_in_front_is_judged_from_the_sensor_s_own_position():
    # the camera 2 m behind the local origin; three objects in a row ahead of it
    behind = np.eye(4)
    behind[:3, 3] = [-2.0, 0, 0]
    look = Coverage(behind @ CAMERA, 8.0, (120.0, 90.0))
    positions = np.array([[0.0, 0, 0], [1.0, 0, 0], [2.0, 0, 0]])
    expected, _ = expected_unseen(
        np.eye(4), [look], positions, np.full(3, 0.6), [], np.full(3, 0.6)
    )
    assert expected.tolist() == [0, 1]


@pytest.mark.parametrize(
    ("blocker", "size", "shadows"),
    [
        ([0.3, 0, 0], 0.5, False),  # 0.3 m from the sensor: too near to count
        ([0.31, 0, 0], 0.5, True),
        ([2.7, 0, 0], 0.5, False),  # 0.3 m before the target: part of it
        ([2.69, 0, 0], 0.5, True),
        ([1.5, 0.25, 0], 0.5, False),  # off the ray by exactly half its diagonal
        ([1.5, 0.24, 0], 0.5, True),
        ([1.5, 0.5, 0], 0.4, False),  # half of 0.4 m
        ([1.5, 0.2, 0], float("nan"), True),  # an unknown size counts as 0.5 m
        ([1.5, 0.3, 0], float("nan"), False),
    ],
)
def test_an_object_stands_in_front_of_a_target_by_the_rule(blocker, size, shadows):
    positions = np.array([[3.0, 0, 0], blocker])
    look = Coverage(CAMERA, 5.0, (120.0, 90.0))
    expected, _ = expected_unseen(
        np.eye(4), [look], positions, np.array([0.5, size]), [], np.full(2, 0.6),
        Looks(max_in_front=0),
    )  # fmt: skip
    assert (0 not in expected.tolist()) == shadows


def test_what_stands_in_front_of_a_near_target_is_judged_along_the_ray_in_metres():
    # a target 0.9 m ahead, an object 0.32 m ahead on the same ray: in front of it
    positions = np.array([[0.9, 0, 0], [0.32, 0, 0]])
    look = Coverage(CAMERA, 5.0, (120.0, 90.0))
    expected, _ = expected_unseen(
        np.eye(4), [look], positions, np.full(2, 0.5), [], np.full(2, 0.6), Looks(max_in_front=0)
    )
    assert 0 not in expected.tolist()
