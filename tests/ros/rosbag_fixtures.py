"""Small ROS 2 bags the tests build with rosbags' own writer (sqlite3 or MCAP storage): a robot
drives past the objects of a map and detects the near ones as boxes."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from semloc.maps import ObjectMap
from semloc.ros import messages as msgs

T_MAP_ODOM = np.array([[0.0, -1.0, 0.0, 2.0], [1.0, 0.0, 0.0, -1.0], [0.0, 0.0, 1.0, 0.0],
                       [0.0, 0.0, 0.0, 1.0]])  # fmt: skip
"""The true pose of the odometry frame in the map (a quarter turn and a shift)."""


def robot_poses(n: int) -> list[np.ndarray]:
    """T_odom_base along a gentle arc."""
    poses = []
    for k in range(n):
        yaw = 0.05 * k
        T = np.eye(4)
        T[:3, :3] = [[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]]
        T[:3, 3] = [0.3 * k, 0.1 * k, 0.0]
        poses.append(T)
    return poses


def detection(label: str, T_box: np.ndarray, size, stamp: int, frame: str, score=0.9):
    hyp = msgs.new("vision_msgs/msg/ObjectHypothesis", class_id=label, score=score)
    result = msgs.new("vision_msgs/msg/ObjectHypothesisWithPose", hypothesis=hyp)
    box = msgs.new("vision_msgs/msg/BoundingBox3D", center=msgs.pose(T_box), size=msgs.vector(size))
    return msgs.new("vision_msgs/msg/Detection3D", header=msgs.header(stamp, frame),
                    results=[result], bbox=box)  # fmt: skip


def messages(global_map: ObjectMap, n: int = 12, frame: str = "base", radius: float = 100.0,
             points: bool = False):  # fmt: skip
    """(topic, type, stamp, message) of a drive past `global_map`: /odom and /detections, and
    with `points` /points (each detection's map points, or points in its box)."""
    out = []
    T_odom_map = np.linalg.inv(T_MAP_ODOM)
    for k, T_odom_base in enumerate(robot_poses(n)):
        stamp = 10**9 + k * 10**8
        odom = msgs.new(msgs.ODOMETRY, header=msgs.header(stamp, "odom"), child_frame_id="base")
        odom.pose.pose = msgs.pose(T_odom_base)
        out.append(("/odom", msgs.ODOMETRY, stamp, odom))
        T_base_map = np.linalg.inv(T_odom_base) @ T_odom_map
        dets, clouds = [], []
        for obj in global_map:
            T = np.eye(4)
            T[:3, 3] = obj.position
            T_box = T_base_map @ T
            if np.linalg.norm(T_box[:3, 3]) < radius:
                size = obj.size if obj.size is not None else (0.5, 0.5, 0.8)
                dets.append(detection(obj.label, T_box, size, stamp, frame))
                cloud = obj.points if obj.points is not None else _inside(obj.position, size, k)
                clouds.append(cloud @ T_base_map[:3, :3].T + T_base_map[:3, 3])
        array = msgs.new(msgs.DETECTIONS, header=msgs.header(stamp, frame), detections=dets)
        out.append(("/detections", msgs.DETECTIONS, stamp, array))
        if points:
            index = np.concatenate([np.full(len(c), i) for i, c in enumerate(clouds)])
            cloud = msgs.cloud(stamp, frame, np.concatenate(clouds), index)
            out.append(("/points", msgs.POINTS, stamp, cloud))
    return out


def _inside(centre, size, seed: int) -> np.ndarray:
    """60 points spread in a box (a depth camera's view of the object)."""
    rng = np.random.default_rng(seed)
    return np.asarray(centre) + rng.uniform(-0.5, 0.5, (60, 3)) * np.asarray(size)


def write_bag(path: Path, records, storage: str = "mcap") -> Path:
    """A rosbag2 folder of `records` (topic, type, stamp, message) in `storage`."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    store = msgs.typestore()
    with Writer(path, version=9, storage_plugin=plugin) as writer:
        conns = {}
        for topic, typename, stamp, message in records:
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, typename, typestore=store)
            writer.write(conns[topic], stamp, msgs.serialize(message, typename))
    return path
