"""A position prior from a robot pose estimate in the map: what `/initialpose` says, as a
`semloc.Prior` on the odometry frame's origin (numpy only; `estimate_prior` reads the message's
fields for the ROS 2 node and `semloc bag localize` alike).

`/initialpose` (geometry_msgs/PoseWithCovarianceStamped in the map frame, what RViz's "2D Pose
Estimate" and amcl use) gives the ROBOT's pose in the map, T_map_robot, with a covariance.  A
`Prior` constrains the LOCAL frame's origin, and the node's local frame is the odometry frame
(detections are placed there).  With the robot's pose in the odometry frame, T_odom_robot (the
odometry at the message's stamp), the odometry frame's pose in the map is

    T_map_odom = T_map_robot @ inv(T_odom_robot),  its origin  o = p - w,

where p is the robot's position in the map and w = R_map_odom @ t_odom_robot the robot's
offset from the odometry origin, in the map's axes.  The prior (`odom_prior`):

- **radius** = r + widening, with r = max(`MIN_RADIUS_M`, 3 * sqrt(the larger of the x and
  y variances)): the robot's position error moves the origin by as much;
- **heading** (the odometry frame's x axis about the map's z axis) = the robot's yaw in the
  map minus its yaw in the odometry, within tolerance = 3 * sqrt(yaw variance), at least
  `MIN_HEADING_TOLERANCE_DEG`.  A yaw error δ turns w about the vertical through p, so the
  origin lies on an arc of radius ρ = |w_xy| around p: the radius is widened by the arc's
  chord 2 ρ sin(tolerance / 2);
- when the yaw is unknown (3 sigma above `MAX_HEADING_TOLERANCE_DEG`, e.g. a yaw variance
  left huge by a tool that sets a position only): no heading, and the origin may lie anywhere
  on the circle of radius ρ around p (at the height p_z - w_z), so the prior is centred on
  that circle's centre and its radius widened by ρ.

The pose is taken as the pose of the odometry's moving (child) frame, height included: with
RViz's 2D Pose Estimate (z = 0) the odometry should move the robot's base frame, as for amcl.

`estimate_prior(message, map_frame, odometry)`: the prior of one message, with the odometry at
its stamp (`robot_in_odom`: interpolated where the odometry covers the stamp, else its latest
pose before it, what a live node holds then); an estimate in another frame than the map's, one
before any odometry, or one whose pose or covariance cannot be used is `UnusableEstimate`
naming the kind (the node and the bag count and warn by it).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from semloc.priors import Prior
from semloc.ros.frames import Trajectory
from semloc.ros.messages import matrix, stamp_ns

TOPIC = "/initialpose"
"""The default topic of pose estimates (`ros2 node --initialpose`, `bag localize --initialpose`)."""
MIN_RADIUS_M = 1.0
"""The least radius of a prior from a pose estimate: a covariance of zeros (tools send them)
still leaves room for the error of a right pose."""
MIN_HEADING_TOLERANCE_DEG = 10.0
"""The least heading tolerance (a zero yaw variance is not a perfect heading)."""
MAX_HEADING_TOLERANCE_DEG = 90.0
"""Above this 3-sigma yaw error the heading counts as unknown: the prior has none."""


def odom_prior(T_map_robot: np.ndarray, covariance: Any, T_odom_robot: np.ndarray) -> Prior:
    """The prior on the odometry frame's origin of a robot pose estimate in the map with its
    6x6 covariance (x, y, z, roll, pitch, yaw; ROS order, 36 numbers) and the robot's pose in
    the odometry frame (see the module docstring).  ValueError for a covariance that is not
    36 finite numbers with non-negative x, y and yaw variances."""
    cov = np.asarray(covariance, dtype=float)
    if cov.size != 36 or not np.all(np.isfinite(cov)):
        raise ValueError("the pose covariance must be 36 finite numbers")
    cov = cov.reshape(6, 6)
    var_xy, var_yaw = max(cov[0, 0], cov[1, 1]), cov[5, 5]
    if min(cov[0, 0], cov[1, 1], var_yaw) < 0:
        raise ValueError("the pose covariance has a negative variance")
    T_map_odom = np.asarray(T_map_robot, float) @ np.linalg.inv(np.asarray(T_odom_robot, float))
    p = np.asarray(T_map_robot, float)[:3, 3]
    w = T_map_odom[:3, :3] @ np.asarray(T_odom_robot, float)[:3, 3]
    rho = float(math.hypot(w[0], w[1]))
    radius = max(MIN_RADIUS_M, 3.0 * math.sqrt(var_xy))
    tolerance = math.degrees(3.0 * math.sqrt(var_yaw))
    x_axis = T_map_odom[:3, 0]
    if tolerance > MAX_HEADING_TOLERANCE_DEG or math.hypot(x_axis[0], x_axis[1]) < 1e-9:
        centre = p - np.array([0.0, 0.0, w[2]])
        return Prior(position=centre, radius=radius + rho)
    tolerance = max(tolerance, MIN_HEADING_TOLERANCE_DEG)
    chord = 2.0 * rho * math.sin(math.radians(tolerance) / 2.0)
    heading = math.degrees(math.atan2(x_axis[1], x_axis[0]))
    return Prior(position=T_map_odom[:3, 3], radius=radius + chord, heading=heading,
                 heading_tolerance=tolerance)  # fmt: skip


BEFORE_ODOMETRY = "pose estimates before any odometry"
UNUSABLE = "pose estimates that cannot be used"


def not_in_map(map_frame: str) -> str:
    """The kind of an estimate in another frame than the map's."""
    return f"pose estimates not in the map frame '{map_frame}'"


class UnusableEstimate(ValueError):
    """A pose estimate that gives no prior: `why` is its kind (one of this module's), `detail`
    what was wrong with it (may be empty)."""

    def __init__(self, why: str, detail: str = "") -> None:
        super().__init__(why + (f": {detail}" if detail else ""))
        self.why, self.detail = why, detail


def robot_in_odom(odometry: Trajectory, stamp: int) -> np.ndarray | None:
    """The odometry's pose at `stamp`: interpolated (`Trajectory.at`), else the latest pose
    before `stamp`; None when every pose is later (or there is none)."""
    pose = odometry.at(stamp)
    if pose is not None:
        return pose
    before = int(np.searchsorted(odometry.stamps, stamp, side="right"))
    return None if before == 0 else odometry.poses[before - 1]


def estimate_prior(message: Any, map_frame: str, odometry: Trajectory | None) -> Prior:
    """The prior on the odometry frame's origin of a geometry_msgs/PoseWithCovarianceStamped
    (its frame the map's; an empty frame id counts as the map's), with `odometry` the robot's
    poses in the odometry frame (None: there is no odometry, the detections' frame is the
    local frame and the pose is the robot's there).  `UnusableEstimate` naming the kind."""
    frame = message.header.frame_id
    if frame and frame != map_frame:
        raise UnusableEstimate(not_in_map(map_frame), f"frame '{frame}'")
    T_odom_robot = np.eye(4)
    if odometry is not None:
        found = robot_in_odom(odometry, stamp_ns(message.header.stamp))
        if found is None:
            raise UnusableEstimate(BEFORE_ODOMETRY)
        T_odom_robot = found
    try:
        T_map_robot = matrix(message.pose.pose)
        return odom_prior(T_map_robot, message.pose.covariance, T_odom_robot)
    except ValueError as exc:
        raise UnusableEstimate(UNUSABLE, str(exc)) from None
