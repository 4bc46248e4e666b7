"""What the camera covered from ROS messages (`semloc.ros.camera`): CameraInfo's field of view
and static TF's chain from the detections' frame to the camera's optical frame."""

from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("rosbags", reason="rosbags (the ros extra) is not installed")

from semloc.ros import messages as msgs  # noqa: E402
from semloc.ros.camera import Camera, CameraCoverage, CameraError, StaticFrames  # noqa: E402
from semloc.transforms import yaw_pose  # noqa: E402

OPTICAL = np.array([[0.0, 0, 1, 0], [-1, 0, 0, 0], [0, -1, 0, 0], [0, 0, 0, 1]])
"""base_link (x forward, z up) -> camera_optical (z forward, x right, y down)."""


def info(width=640, height=480, fx=320.0, fy=240.0, frame="camera_optical"):
    k = np.array([fx, 0.0, width / 2, 0.0, fy, height / 2, 0.0, 0.0, 1.0])
    return msgs.new(msgs.CAMERA_INFO, header=msgs.header(0, frame), width=width, height=height,
                    k=k)  # fmt: skip


def static(*transforms):
    return msgs.new(msgs.TF, transforms=[msgs.transform(T, 0, parent, child)
                                         for parent, child, T in transforms])  # fmt: skip


def test_the_field_of_view_comes_from_the_image_size_and_focal_lengths():
    camera = Camera.of(info())
    assert camera.frame == "camera_optical"
    assert camera.fov_deg == pytest.approx((90.0, 90.0))
    assert Camera.of(info(fx=640 / (2 * math.tan(math.radians(30))))).fov_deg[0] == pytest.approx(
        60
    )
    with pytest.raises(CameraError, match="no field of view"):
        Camera.of(info(fx=0.0))


def test_static_tf_chains_the_camera_into_the_detections_frame():
    mount = yaw_pose(0.0, [0.2, 0.0, 1.0])  # base_link -> camera_link
    frames = StaticFrames([static(("base_link", "camera_link", mount)),
                           static(("camera_link", "camera_optical", OPTICAL))])  # fmt: skip
    np.testing.assert_allclose(frames.transform("base_link", "camera_optical"), mount @ OPTICAL)
    np.testing.assert_allclose(frames.transform("camera_optical", "base_link"),
                               np.linalg.inv(mount @ OPTICAL), atol=1e-12)  # fmt: skip
    with pytest.raises(CameraError, match="joins 'odom' and 'camera_optical'"):
        frames.transform("odom", "camera_optical")


def test_the_look_points_where_the_camera_looks():
    mount = yaw_pose(0.0, [0.2, 0.0, 1.0])
    frames = StaticFrames([static(("base_link", "camera_optical", mount @ OPTICAL))])
    coverage = CameraCoverage(Camera.of(info()), frames, 5.0)
    robot = yaw_pose(math.pi / 2, [10.0, 0.0, 0.0])  # odom -> base_link, facing +y
    look = coverage.at(robot, "base_link")
    assert look.covers([[10.0, 3.0, 1.0], [10.0, -3.0, 1.0], [13.0, 0.0, 1.0]]).tolist() == [
        True,
        False,
        False,
    ]
    same = CameraCoverage(Camera.of(info(frame="base_link")), StaticFrames(), 5.0)
    np.testing.assert_allclose(same.at(robot, "base_link").pose, robot)
