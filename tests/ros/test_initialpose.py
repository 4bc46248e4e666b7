"""A robot pose estimate in the map (`/initialpose`) as a prior on the odometry frame's origin
(`semloc.ros.initialpose.odom_prior`): the true origin is always within it, the radius and
heading follow the documented rule, bad covariances are refused; and the point-cloud decoder
the bag reader and the node share."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from semloc.ros.bag import cloud_points
from semloc.ros.initialpose import (
    MAX_HEADING_TOLERANCE_DEG,
    MIN_HEADING_TOLERANCE_DEG,
    MIN_RADIUS_M,
    odom_prior,
)
from semloc.transforms import yaw_pose

RVIZ = np.diag([0.25, 0.25, 0.0, 0.0, 0.0, 0.06853891945200942])
"""The covariance RViz's "2D Pose Estimate" sends (0.5 m, 15 deg)."""


def covariance(sigma_xy: float, sigma_yaw_deg: float) -> np.ndarray:
    return np.diag([sigma_xy**2, sigma_xy**2, 0, 0, 0, math.radians(sigma_yaw_deg) ** 2])


def test_rviz_estimate_of_a_robot_away_from_the_odometry_origin():
    T_map_odom = yaw_pose(0.9, [4.0, -2.0, 0.0])  # the truth the prior must hold
    T_odom_robot = yaw_pose(-0.4, [3.0, 4.0, 0.0])  # 5 m from the odometry origin
    prior = odom_prior(T_map_odom @ T_odom_robot, RVIZ.ravel(), T_odom_robot)
    np.testing.assert_allclose(prior.position, [4.0, -2.0, 0.0], atol=1e-9)
    assert prior.heading == pytest.approx(math.degrees(0.9))
    assert prior.heading_tolerance == pytest.approx(45.0)  # 3 sigma of 15 deg
    chord = 2 * 5.0 * math.sin(math.radians(45.0) / 2)  # the origin's arc for +-45 deg of yaw
    assert prior.radius == pytest.approx(1.5 + chord)  # 3 sigma of 0.5 m, widened
    assert prior.contains(T_map_odom)


def test_without_a_heading_the_prior_is_the_circle_the_origin_may_lie_on():
    T_map_odom = yaw_pose(2.0, [1.0, 1.0, 0.5])
    T_odom_robot = yaw_pose(0.3, [3.0, 4.0, 0.2])
    T_map_robot = T_map_odom @ T_odom_robot
    prior = odom_prior(T_map_robot, covariance(0.1, 60.0), T_odom_robot)  # 180 deg: unknown
    assert prior.heading is None
    np.testing.assert_allclose(prior.position, T_map_robot[:3, 3] - [0, 0, 0.2], atol=1e-9)
    assert prior.radius == pytest.approx(MIN_RADIUS_M + 5.0)
    for yaw in np.linspace(-math.pi, math.pi, 13):  # whatever the robot's true yaw
        truth = yaw_pose(yaw, T_map_robot[:3, 3]) @ np.linalg.inv(T_odom_robot)
        assert prior.contains(truth, metres=1e-9)
        assert np.linalg.norm(truth[:3, 3] - prior.position) == pytest.approx(5.0)


@settings(max_examples=60)
@given(
    st.floats(-math.pi, math.pi), st.floats(-math.pi, math.pi),
    st.lists(st.floats(-20, 20), min_size=3, max_size=3),
    st.lists(st.floats(-20, 20), min_size=2, max_size=2),
    st.floats(0.0, 2.0), st.floats(0.0, 40.0), st.floats(-1, 1), st.floats(-1, 1),
    st.floats(-1, 1),
)  # fmt: skip
def test_the_true_origin_is_within_the_prior_of_any_estimate_within_3_sigma(
    map_yaw, odom_yaw, origin, robot_xy, sigma_xy, sigma_yaw, ex, ey, eyaw
):
    """An estimate off by up to 3 sigma in x, y (each) and yaw: the prior holds the truth
    (x and y errors within 3 sigma each may add up to 3 sigma * sqrt 2: the test keeps the
    position error within the radius's 3 sigma)."""
    T_map_odom = yaw_pose(map_yaw, origin)
    T_odom_robot = yaw_pose(odom_yaw, [*robot_xy, 0.0])
    T_map_robot = T_map_odom @ T_odom_robot
    tolerance = max(3 * sigma_yaw, MIN_HEADING_TOLERANCE_DEG)
    error = yaw_pose(math.radians(eyaw * tolerance), [0, 0, 0])
    estimate = T_map_robot @ error
    estimate[:3, 3] += np.array([ex, ey, 0.0]) / math.sqrt(2) * max(3 * sigma_xy, MIN_RADIUS_M)
    prior = odom_prior(estimate, covariance(sigma_xy, sigma_yaw), T_odom_robot)
    assert prior.contains(T_map_odom, metres=1e-6, degrees=1e-6)
    assert (prior.heading is None) == (3 * sigma_yaw > MAX_HEADING_TOLERANCE_DEG)


@pytest.mark.parametrize(
    ("cov", "message"),
    [
        (np.zeros(35), "36 finite numbers"),
        (np.full(36, np.nan), "36 finite numbers"),
        (np.diag([-1.0, 0, 0, 0, 0, 0]).ravel(), "negative variance"),
        (np.diag([0, 0, 0, 0, 0, -0.1]).ravel(), "negative variance"),
    ],
)
def test_a_covariance_that_says_nothing_is_refused(cov, message):
    with pytest.raises(ValueError, match=message):
        odom_prior(np.eye(4), cov, np.eye(4))


def test_zero_covariance_keeps_the_least_radius_and_tolerance():
    prior = odom_prior(yaw_pose(0.0, [1, 2, 0]), np.zeros(36), np.eye(4))
    assert prior.radius == MIN_RADIUS_M and prior.heading_tolerance == MIN_HEADING_TOLERANCE_DEG


class _Field:
    def __init__(self, name, offset, datatype=7):
        self.name, self.offset, self.datatype, self.count = name, offset, datatype, 1


class _Cloud:
    def __init__(self, block: np.ndarray, fields=None, width=None):
        self.fields = fields or [_Field(n, 4 * i) for i, n in enumerate("xyz")] + [
            _Field("detection", 12)
        ]
        self.width, self.height = len(block) if width is None else width, 1
        self.point_step, self.is_bigendian = 16, False
        self.data = np.frombuffer(block.astype("<f4").tobytes(), dtype=np.uint8)


def test_cloud_points_groups_by_detection_and_drops_what_names_none():
    block = np.array([[1, 2, 3, 0], [4, 5, 6, 1], [7, 8, 9, 1], [0, 0, np.nan, 0],
                      [1, 1, 1, 5], [2, 2, 2, np.nan], [3, 3, 3, -1]])  # fmt: skip
    found = cloud_points(_Cloud(block), count=2)
    assert sorted(found) == [0, 1]
    np.testing.assert_allclose(found[0], [[1, 2, 3]])
    np.testing.assert_allclose(found[1], [[4, 5, 6], [7, 8, 9]])


def test_malformed_clouds_raise_value_errors_naming_the_problem():
    block = np.zeros((3, 4))
    with pytest.raises(ValueError, match="no field 'detection'"):
        cloud_points(_Cloud(block, fields=[_Field(n, 4 * i) for i, n in enumerate("xyz")]), 2)
    with pytest.raises(ValueError, match="holds 48 bytes, not 10 x 16"):
        cloud_points(_Cloud(block, width=10), 2)
    bad_type = [_Field(n, 4 * i) for i, n in enumerate("xyz")] + [_Field("detection", 12, 99)]
    with pytest.raises(ValueError, match="unusable type"):
        cloud_points(_Cloud(block, fields=bad_type), 2)
