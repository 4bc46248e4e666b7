"""ROS 2 messages without ROS: the type store, building, (de)serializing and schema texts.

The messages are those of ROS 2 Humble as `rosbags` ships them, plus `vision_msgs` (not in
its store), registered here from the message definitions of vision_msgs 4 (Humble).  `new`
builds any message with every field defaulted (zeros, empty strings and lists), so callers
name only what they set.  This module and `semloc.ros.bag` / `semloc.ros.mcap_out` are the
only places that import `rosbags` (the `semloc[ros]` extra), and only when first used.
"""

from __future__ import annotations

from functools import cache
from typing import Any

import numpy as np

from semloc.ros.frames import matrix_of, quaternion_of

VISION_MSGS = {
    "vision_msgs/msg/ObjectHypothesis": "string class_id\nfloat64 score\n",
    "vision_msgs/msg/ObjectHypothesisWithPose": (
        "vision_msgs/ObjectHypothesis hypothesis\ngeometry_msgs/PoseWithCovariance pose\n"
    ),
    "vision_msgs/msg/BoundingBox3D": "geometry_msgs/Pose center\ngeometry_msgs/Vector3 size\n",
    "vision_msgs/msg/Detection3D": (
        "std_msgs/Header header\nvision_msgs/ObjectHypothesisWithPose[] results\n"
        "vision_msgs/BoundingBox3D bbox\nstring id\n"
    ),
    "vision_msgs/msg/Detection3DArray": (
        "std_msgs/Header header\nvision_msgs/Detection3D[] detections\n"
    ),
}
"""vision_msgs 4.x (ROS 2 Humble) definitions of the messages semloc reads, comments left out."""

DETECTIONS = "vision_msgs/msg/Detection3DArray"
ODOMETRY = "nav_msgs/msg/Odometry"
POINTS = "sensor_msgs/msg/PointCloud2"
POSE = "geometry_msgs/msg/PoseWithCovarianceStamped"
TF = "tf2_msgs/msg/TFMessage"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
STRING = "std_msgs/msg/String"
MARKERS = "visualization_msgs/msg/MarkerArray"


@cache
def typestore() -> Any:
    """The Humble type store of `rosbags` with vision_msgs registered."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    types: dict = {}
    for name, text in VISION_MSGS.items():
        types.update(get_types_from_msg(text, name))
    store.register(types)
    return store


def known(typename: str) -> bool:
    """Whether `typename` is in the type store."""
    return typename in typestore().types


def new(typename: str, **fields: Any) -> Any:
    """A message of `typename` with `fields` set and every other field at its default."""
    store = typestore()
    msgdef = store.get_msgdef(typename)
    values = {name: _default(store, desc) for name, desc in msgdef.fields if name not in fields}
    return msgdef.cls(**values, **fields)


def _default(store: Any, desc: tuple) -> Any:
    from rosbags.interfaces import Nodetype

    kind, detail = desc
    if kind == Nodetype.NAME:
        return new(detail)
    if kind == Nodetype.BASE:
        return _base_default(detail[0])
    if kind == Nodetype.SEQUENCE:
        inner = detail[0]
        if inner[0] == Nodetype.BASE and inner[1][0] != "string":
            return np.zeros(0, dtype=_NUMPY[inner[1][0]])
        return []
    inner, count = detail
    if inner[0] == Nodetype.BASE and inner[1][0] != "string":
        return np.zeros(count, dtype=_NUMPY[inner[1][0]])
    return [_default(store, inner) for _ in range(count)]


_NUMPY = {"bool": np.bool_, "byte": np.uint8, "char": np.uint8, "int8": np.int8,
          "uint8": np.uint8, "int16": np.int16, "uint16": np.uint16, "int32": np.int32,
          "uint32": np.uint32, "int64": np.int64, "uint64": np.uint64,
          "float32": np.float32, "float64": np.float64}  # fmt: skip


def _base_default(kind: str) -> Any:
    if kind == "string":
        return ""
    if kind == "bool":
        return False
    return 0.0 if kind.startswith("float") else 0


def serialize(message: Any, typename: str) -> bytes:
    """CDR bytes of a message (little endian, as rosbag2 stores them)."""
    return bytes(typestore().serialize_cdr(message, typename))


def deserialize(data: bytes | memoryview, typename: str) -> Any:
    """The message of CDR bytes; ValueError (or another exception of rosbags) if they are bad."""
    return typestore().deserialize_cdr(data, typename)


def schema_text(typename: str) -> str:
    """The ros2msg schema of a type: its definition followed by those of every type it uses."""
    return typestore().generate_msgdef(typename, ros_version=2)[0]


# Geometry ---------------------------------------------------------------------------------
def stamp(ns: int) -> Any:
    """builtin_interfaces/Time of nanoseconds."""
    return new("builtin_interfaces/msg/Time", sec=int(ns // 10**9), nanosec=int(ns % 10**9))


def stamp_ns(time: Any) -> int:
    """Nanoseconds of a builtin_interfaces/Time."""
    return int(time.sec) * 10**9 + int(time.nanosec)


def header(ns: int, frame: str) -> Any:
    return new("std_msgs/msg/Header", stamp=stamp(ns), frame_id=frame)


def point(xyz: Any) -> Any:
    x, y, z = (float(v) for v in xyz)
    return new("geometry_msgs/msg/Point", x=x, y=y, z=z)


def vector(xyz: Any) -> Any:
    x, y, z = (float(v) for v in xyz)
    return new("geometry_msgs/msg/Vector3", x=x, y=y, z=z)


def pose(T: np.ndarray) -> Any:
    """geometry_msgs/Pose of a 4x4 matrix."""
    x, y, z, w = quaternion_of(T[:3, :3])
    orientation = new("geometry_msgs/msg/Quaternion", x=x, y=y, z=z, w=w)
    return new("geometry_msgs/msg/Pose", position=point(T[:3, 3]), orientation=orientation)


def matrix(pose_msg: Any) -> np.ndarray:
    """4x4 matrix of a geometry_msgs/Pose (or Transform: translation + rotation)."""
    position = getattr(pose_msg, "position", None) or pose_msg.translation
    q = getattr(pose_msg, "orientation", None) or pose_msg.rotation
    return matrix_of((position.x, position.y, position.z), (q.x, q.y, q.z, q.w))


def transform(T: np.ndarray, ns: int, parent: str, child: str) -> Any:
    """geometry_msgs/TransformStamped of a 4x4 matrix (the child frame's pose in the parent)."""
    x, y, z, w = quaternion_of(T[:3, :3])
    rotation = new("geometry_msgs/msg/Quaternion", x=x, y=y, z=z, w=w)
    moved = new("geometry_msgs/msg/Transform", translation=vector(T[:3, 3]), rotation=rotation)
    return new("geometry_msgs/msg/TransformStamped", header=header(ns, parent),
               child_frame_id=child, transform=moved)  # fmt: skip


# Point clouds -----------------------------------------------------------------------------
POINT_FIELDS = ("x", "y", "z", "detection")
"""The fields of the per-detection point clouds semloc writes: float32 x, y, z and the float32
index of the detection (in the Detection3DArray of the same stamp) the point belongs to."""

_DATATYPES = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}


def cloud(ns: int, frame: str, points: np.ndarray, detection: np.ndarray) -> Any:
    """sensor_msgs/PointCloud2 of points (N, 3) labelled by detection index (N,)."""
    block = np.zeros((len(points), 4), dtype="<f4")
    block[:, :3], block[:, 3] = points, detection
    fields = [
        new("sensor_msgs/msg/PointField", name=name, offset=4 * i, datatype=7, count=1)
        for i, name in enumerate(POINT_FIELDS)
    ]
    return new(
        POINTS, header=header(ns, frame), height=1, width=len(points), fields=fields,
        is_bigendian=False, point_step=16, row_step=16 * len(points),
        data=np.frombuffer(block.tobytes(), dtype=np.uint8), is_dense=True,
    )  # fmt: skip


def cloud_fields(msg: Any, names: tuple[str, ...]) -> dict[str, np.ndarray]:
    """The named fields of a PointCloud2 as float arrays; ValueError naming what is wrong."""
    layout = {f.name: f for f in msg.fields}
    missing = [n for n in names if n not in layout]
    if missing:
        raise ValueError(f"point cloud has no field {missing[0]!r} (has {sorted(layout)})")
    count = int(msg.width) * int(msg.height)
    step = int(msg.point_step)
    data = np.asarray(msg.data, dtype=np.uint8)
    if step <= 0 or len(data) < count * step:
        raise ValueError(f"point cloud data holds {len(data)} bytes, not {count} x {step}")
    rows = data[: count * step].reshape(count, step)
    out = {}
    for name in names:
        field = layout[name]
        kind = _DATATYPES.get(int(field.datatype))
        if kind is None or int(field.offset) + int(kind[1]) > step:
            raise ValueError(f"point cloud field {name!r} has an unusable type or offset")
        dtype = np.dtype(kind).newbyteorder(">" if msg.is_bigendian else "<")
        raw = rows[:, int(field.offset) : int(field.offset) + dtype.itemsize]
        out[name] = np.ascontiguousarray(raw).view(dtype).reshape(count).astype(float)
    return out
