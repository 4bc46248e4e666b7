"""A position prior from a robot pose estimate in the map: what `/initialpose` says, as a
`semloc.Prior` on the odometry frame's origin (numpy only; the ROS 2 node reads the message).

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
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from semloc.priors import Prior

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
