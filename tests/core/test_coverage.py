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
@settings(max_examples=60, deadline=None)
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
