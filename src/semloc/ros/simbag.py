"""A simulated walk as a ROS 2 bag (`semloc simulate OUT --bag` writes it as OUT/walk.mcap).

One message per keyframe on each topic, 10 per second from stamp 1 s:

- `/detections` (vision_msgs/Detection3DArray, frame `camera`): each detection as the
  gravity-aligned box of its points (`semloc.io.geometry.upright_box` in the odometry frame,
  expressed in the camera frame), its class as the one hypothesis with the detector's score;
- `/odom` (nav_msgs/Odometry, `odom` -> `camera`): the camera pose the simulated odometry
  estimated (with its drift), the frame the local map is fused in;
- `/detections/points` (sensor_msgs/PointCloud2, frame `camera`): the detections' points with
  the field `detection` (index in the array of the same stamp);
- `/camera_info` (sensor_msgs/CameraInfo, frame `camera`, the optical frame), when the
  camera's intrinsics are given: its image size and focal lengths.
"""

from __future__ import annotations

import numpy as np

from semloc.io.geometry import upright_box
from semloc.ros import messages as msgs
from semloc.ros.mcap_out import McapSink
from semloc.sim.noise import Detection
from semloc.sim.scenario import SimulatedSequence
from semloc.sim.sensor import Intrinsics

DETECTIONS_TOPIC = "/detections"
ODOM_TOPIC = "/odom"
POINTS_TOPIC = "/detections/points"
CAMERA_INFO_TOPIC = "/camera_info"
START_NS = 10**9
PERIOD_NS = 10**8  # 10 Hz
UP = np.array([0.0, 0.0, 1.0])


def walk_bag(seq: SimulatedSequence, intrinsics: Intrinsics | None = None) -> bytes:
    """The MCAP file of `seq`'s walk (see the module docstring)."""
    if seq.recording is None:
        raise ValueError("this sequence has no recording to write as a bag")
    sink = McapSink()
    for i, kf in enumerate(seq.keyframes):
        stamp = START_NS + i * PERIOD_NS
        detections = seq.recording.detections[kf.index]
        odom = msgs.new(msgs.ODOMETRY, header=msgs.header(stamp, "odom"), child_frame_id="camera")
        odom.pose.pose = msgs.pose(kf.T_odom_camera)
        sink.write(ODOM_TOPIC, msgs.ODOMETRY, stamp, odom)
        boxes = [_detection(stamp, d, kf.T_odom_camera) for d in detections]
        array = msgs.new(msgs.DETECTIONS, header=msgs.header(stamp, "camera"), detections=boxes)
        sink.write(DETECTIONS_TOPIC, msgs.DETECTIONS, stamp, array)
        points = [np.asarray(d.points, dtype=float).reshape(-1, 3) for d in detections]
        index = np.concatenate([np.full(len(p), j) for j, p in enumerate(points)] or [[]])
        xyz = np.concatenate(points) if points else np.zeros((0, 3))
        sink.write(POINTS_TOPIC, msgs.POINTS, stamp, msgs.cloud(stamp, "camera", xyz, index))
        if intrinsics is not None:
            sink.write(CAMERA_INFO_TOPIC, msgs.CAMERA_INFO, stamp, _camera_info(stamp, intrinsics))
    return sink.getvalue()


def _camera_info(stamp: int, K: Intrinsics) -> object:
    k = [K.fx, 0.0, K.cx, 0.0, K.fy, K.cy, 0.0, 0.0, 1.0]
    return msgs.new(msgs.CAMERA_INFO, header=msgs.header(stamp, "camera"), width=K.width,
                    height=K.height, k=np.array(k), distortion_model="plumb_bob")  # fmt: skip


def _detection(stamp: int, det: Detection, T_odom_camera: np.ndarray) -> object:
    R, t = T_odom_camera[:3, :3], T_odom_camera[:3, 3]
    centre, size, rotation = upright_box(np.asarray(det.points, float) @ R.T + t, UP)
    T_box = np.eye(4)
    T_box[:3, :3], T_box[:3, 3] = R.T @ rotation, R.T @ (centre - t)
    hypothesis = msgs.new("vision_msgs/msg/ObjectHypothesis", class_id=det.label,
                          score=float(det.score))  # fmt: skip
    result = msgs.new("vision_msgs/msg/ObjectHypothesisWithPose", hypothesis=hypothesis)
    result.pose.pose = msgs.pose(T_box)
    box = msgs.new("vision_msgs/msg/BoundingBox3D", center=msgs.pose(T_box), size=msgs.vector(size))
    return msgs.new("vision_msgs/msg/Detection3D", header=msgs.header(stamp, "camera"),
                    results=[result], bbox=box)  # fmt: skip
