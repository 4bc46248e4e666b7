"""Reading recorded runs: rosbag2 folders (sqlite3 or MCAP storage) and bare `.mcap` / `.db3`
files, through `rosbags` (no ROS installation).

`topics(path)` lists what a bag holds and what semloc can use of it.  `Run` reads a run for
`semloc bag localize`: the odometry first (a `Trajectory` of the child frame in the odometry
frame), then the detection messages in order as `DetectionFrame`s, each with the pose of its
frame in the odometry frame, and with the points of a `sensor_msgs/PointCloud2` topic where
one is given (fields x, y, z and `detection`, the index of the detection in the array of the
same stamp), and the robot pose estimates of an `--initialpose` topic (`estimates`).  Every problem (no such file, not a bag, truncated, a missing topic, a topic of
another type, undecodable messages, frames that do not connect) is a `BagError` naming the
file and what is wrong.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from semloc.maps import MapError
from semloc.ros import messages as msgs
from semloc.ros.camera import Camera, CameraCoverage, CameraError, StaticFrames
from semloc.ros.frames import Trajectory, matrix_of
from semloc.ros.initialpose import TOPIC as INITIALPOSE_TOPIC
from semloc.ros.stream import BoxDetection, DetectionFrame

USES = {msgs.DETECTIONS: "--detections", msgs.ODOMETRY: "--odom", msgs.POINTS: "--points",
        msgs.POSE: "--initialpose", msgs.CAMERA_INFO: "--camera-info"}  # fmt: skip
"""The message types semloc reads, and the option of `semloc bag localize` that takes them."""

MAX_GAP_S = 0.5
"""Odometry further than this from a detection message (or a gap this long) gives no pose."""
CLOUD_WAIT_NS = 10**9
"""A detection message waits this long (log time) for its point cloud."""


class BagError(MapError):
    """A bag that cannot be read as asked: one line naming the file and the problem."""


@dataclass(frozen=True)
class Topic:
    """One topic of a bag: name, message type, message count, the option that reads it."""

    name: str
    msgtype: str
    count: int

    @property
    def use(self) -> str | None:
        return USES.get(self.msgtype)


@dataclass(frozen=True)
class Odometry:
    """The odometry of a run: its frame, the moving (child) frame, and the child's poses."""

    frame: str
    child: str
    trajectory: Trajectory


@contextmanager
def opened(path: Path) -> Iterator[Any]:
    """A rosbags reader of `path`, or a BagError naming the file."""
    from rosbags.rosbag2 import Reader

    path = Path(path)
    if not path.exists():
        raise BagError(f"{path}: no such file or folder")
    try:
        reader = Reader(path)
        reader.open()
    except Exception as exc:  # rosbags raises many kinds on bad files
        raise BagError(f"{path}: not a readable ROS 2 bag ({_why(exc)})") from None
    try:
        yield reader
    finally:
        reader.close()


def _why(exc: BaseException) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text[:200]


def topics(path: Path) -> tuple[list[Topic], float]:
    """The topics of a bag (by name) and its duration in seconds."""
    with opened(path) as reader:
        found: dict[str, Topic] = {}
        for conn in reader.connections:
            old = found.get(conn.topic)
            count = conn.msgcount + (old.count if old else 0)
            found[conn.topic] = Topic(conn.topic, conn.msgtype, count)
        duration = reader.duration / 1e9 if reader.message_count else 0.0
    return sorted(found.values(), key=lambda t: t.name), duration


class Run:
    """A recorded run read for localization (see the module docstring)."""

    def __init__(self, reader: Any, path: Path, detections: str, odom: str | None,
                 points: str | None, initialpose: str | None = None,
                 camera_info: str | None = None, range_m: float = 5.0) -> None:  # fmt: skip
        """`initialpose`: the topic of pose estimates (None: none read); the default topic
        (`semloc.ros.initialpose.TOPIC`) may be absent from the bag, another must be there.
        `camera_info`: a CameraInfo topic whose camera made the detections: each update then
        says what it covered (`semloc.ros.camera`, placed by `/tf_static` when the bag has
        it), out to `range_m`."""
        self.reader, self.path = reader, Path(path)
        self.detections = self._connections(detections, msgs.DETECTIONS, "--detections")
        self.odom = None if odom is None else self._connections(odom, msgs.ODOMETRY, "--odom")
        self.points = None if points is None else self._connections(points, msgs.POINTS, "--points")
        self.initialpose: list[Any] = []
        if initialpose is not None and (
            initialpose != INITIALPOSE_TOPIC
            or any(c.topic == initialpose and c.msgcount for c in reader.connections)
        ):
            self.initialpose = self._connections(initialpose, msgs.POSE, "--initialpose")
        self.camera_info = (
            None
            if camera_info is None
            else self._connections(camera_info, msgs.CAMERA_INFO, "--camera-info")
        )
        self.range_m = range_m
        self.skipped: dict[str, int] = {}
        self.warnings: dict[str, int] = {}
        """Pose estimates left out, by kind (`semloc.ros.initialpose`): said as warnings."""

    def _connections(self, topic: str, msgtype: str, option: str) -> list[Any]:
        conns = [c for c in self.reader.connections if c.topic == topic]
        if not conns:
            names = sorted({c.topic for c in self.reader.connections})
            raise BagError(f"{self.path}: no topic {topic} ({option}); it has {', '.join(names)}")
        wrong = [c.msgtype for c in conns if c.msgtype != msgtype]
        if wrong:
            raise BagError(f"{self.path}: topic {topic} holds {wrong[0]}; {option} needs {msgtype}")
        if not sum(c.msgcount for c in conns):
            raise BagError(f"{self.path}: topic {topic} ({option}) has no messages")
        return conns

    def messages(self, conns: list[Any]) -> Iterator[tuple[str, int, Any]]:
        """(topic, log time, decoded message) in log-time order; BagError on bad data."""
        stream = self.reader.messages(connections=conns)
        index = 0
        while True:
            try:
                conn, log_time, raw = next(stream)
            except StopIteration:
                return
            except Exception as exc:
                raise BagError(f"{self.path}: cannot read the messages ({_why(exc)})") from None
            try:
                message = msgs.deserialize(raw, conn.msgtype)
            except Exception as exc:
                raise BagError(
                    f"{self.path}: message {index} on {conn.topic} is not a valid "
                    f"{conn.msgtype} ({_why(exc)})"
                ) from None
            index += 1
            yield conn.topic, int(log_time), message

    def odometry(self) -> Odometry | None:
        """The odometry of the run (None without an odometry topic)."""
        if self.odom is None:
            return None
        stamps, poses, frames = [], [], set()
        for topic, log_time, message in self.messages(self.odom):
            frames.add((message.header.frame_id, message.child_frame_id))
            stamps.append(msgs.stamp_ns(message.header.stamp) or log_time)
            try:
                poses.append(msgs.matrix(message.pose.pose))
            except ValueError as exc:
                raise BagError(f"{self.path}: odometry on {topic}: {exc}") from None
        if len(frames) > 1:
            shown = ", ".join(f"{a} -> {b}" for a, b in sorted(frames)[:3])
            raise BagError(f"{self.path}: odometry changes frames ({shown}); one pair expected")
        frame, child = frames.pop()
        return Odometry(frame, child, Trajectory(stamps, poses, int(MAX_GAP_S * 1e9)))

    def camera(self) -> CameraCoverage | None:
        """What the camera of `--camera-info` covers (None without the topic): its first
        CameraInfo, placed by the bag's static transforms (`/tf_static`, when present)."""
        if self.camera_info is None:
            return None
        try:
            _, _, info = next(self.messages(self.camera_info))
            camera = Camera.of(info)
        except CameraError as exc:
            raise BagError(f"{self.path}: --camera-info: {exc}") from None
        static = [c for c in self.reader.connections
                  if c.topic == "/tf_static" and c.msgtype == msgs.TF and c.msgcount]  # fmt: skip
        frames = StaticFrames(m for _, _, m in self.messages(static)) if static else StaticFrames()
        return CameraCoverage(camera, frames, self.range_m)

    def first_frame(self) -> str | None:
        """The frame of the first detection message (None for a run without one)."""
        for frame in self.frames():
            return frame.frame
        return None

    def odometry_moving(self, frame: str) -> str | None:
        """An odometry topic of the bag (not read for the run) whose moving (child) frame is
        `frame`, from its first message: detections in `frame` move with the sensor, and
        without that odometry they are taken as fixed in one frame.  None when no odometry
        topic of the bag moves `frame`."""
        for conn in self.reader.connections:
            if conn.msgtype != msgs.ODOMETRY or not conn.msgcount:
                continue
            for _, _, message in self.messages([conn]):
                if message.child_frame_id == frame:
                    return conn.topic
                break
        return None

    def estimates(self) -> list[tuple[int, Any]]:
        """(log time, message) of the pose estimates, in log-time order (none without a topic)."""
        if not self.initialpose:
            return []
        return [(log_time, message) for _, log_time, message in self.messages(self.initialpose)]

    def frames(self) -> Iterator[DetectionFrame]:
        """The detection messages in log-time order (with their points when `--points`)."""
        for _, frame in self.timed_frames():
            yield frame

    def timed_frames(self) -> Iterator[tuple[int, DetectionFrame]]:
        """(log time, frame) of the detection messages (`frames`)."""
        conns = self.detections + (self.points or [])
        waiting: deque[tuple[int, Any]] = deque()  # (log time, detection message)
        clouds: dict[tuple[int, str], Any] = {}
        for _, log_time, message in self.messages(conns):
            if self.points is not None and message.__msgtype__ == msgs.POINTS:
                clouds[(msgs.stamp_ns(message.header.stamp), message.header.frame_id)] = message
            else:
                waiting.append((log_time, message))
            while waiting and (
                self.points is None
                or _key(waiting[0][1]) in clouds
                or log_time - waiting[0][0] > CLOUD_WAIT_NS
            ):
                first_log, detections = waiting.popleft()
                cloud = clouds.pop(_key(detections), None)
                yield first_log, self._frame(detections, first_log, cloud)
                _drop_older(clouds, msgs.stamp_ns(detections.header.stamp) - CLOUD_WAIT_NS)
        for first_log, detections in waiting:
            yield first_log, self._frame(detections, first_log, clouds.pop(_key(detections), None))

    def _frame(self, message: Any, log_time: int, cloud: Any) -> DetectionFrame:
        try:
            points = {} if cloud is None else cloud_points(cloud, len(message.detections))
        except ValueError as exc:
            raise BagError(f"{self.path}: --points: {exc}") from None
        frame, dropped = detection_frame(message, points, log_time)
        if dropped:
            self.skipped[NO_CLASS] = self.skipped.get(NO_CLASS, 0) + dropped
        return frame


NO_CLASS = "detections without a class or a finite box"
"""What a detection left out is counted as (`semloc bag localize`, the ROS 2 node)."""


def detection_frame(
    message: Any, points: dict[int, np.ndarray], fallback_stamp: int = 0
) -> tuple[DetectionFrame, int]:
    """The DetectionFrame of a Detection3DArray (its stamp, else `fallback_stamp`; its frame,
    else its first detection's), with the points of detection i from `points[i]`; and how
    many detections were left out (no class or no finite box)."""
    stamp = msgs.stamp_ns(message.header.stamp) or fallback_stamp
    frame = message.header.frame_id or next(
        (d.header.frame_id for d in message.detections if d.header.frame_id), ""
    )
    detections = [
        detection_from_msg(det, points.get(i)) for i, det in enumerate(message.detections)
    ]
    kept = [d for d in detections if d is not None]
    return DetectionFrame(stamp, frame, kept), len(detections) - len(kept)


def cloud_points(cloud: Any, count: int) -> dict[int, np.ndarray]:
    """The points of each detection (by index, of `count`) in a sensor_msgs/PointCloud2 with
    the fields x, y, z and `detection` (`msgs.POINT_FIELDS`); points that are not finite or
    name no detection are left out.  ValueError naming what is wrong with the cloud."""
    fields = msgs.cloud_fields(cloud, msgs.POINT_FIELDS)
    xyz = np.column_stack([fields["x"], fields["y"], fields["z"]])
    detection = fields["detection"]
    finite = np.all(np.isfinite(xyz), axis=1) & np.isfinite(detection)
    index = np.round(np.where(finite, detection, -1)).astype(np.int64)
    keep = finite & (index >= 0) & (index < count)
    xyz, index = xyz[keep], index[keep]
    return {int(i): xyz[index == i] for i in np.unique(index)}


def _key(message: Any) -> tuple[int, str]:
    return msgs.stamp_ns(message.header.stamp), message.header.frame_id


def _drop_older(clouds: dict[tuple[int, str], Any], stamp: int) -> None:
    for key in [k for k in clouds if k[0] < stamp]:
        del clouds[key]


def detection_from_msg(det: Any, points: np.ndarray | None = None) -> BoxDetection | None:
    """A BoxDetection of a vision_msgs Detection3D (label: the best hypothesis's `class_id`;
    an orientation left all zeros counts as axis-aligned), or None when it has no hypothesis
    with a class or its box is not finite.  Reads fields only, so it takes the messages of
    rosbags and of rclpy alike."""
    results = [r for r in det.results if r.hypothesis.class_id.strip()]
    if not results:
        return None
    best = max(results, key=lambda r: r.hypothesis.score)
    box = det.bbox
    p, q = box.center.position, box.center.orientation
    quaternion = (q.x, q.y, q.z, q.w) if (q.x, q.y, q.z, q.w) != (0, 0, 0, 0) else (0, 0, 0, 1)
    try:
        T = matrix_of((p.x, p.y, p.z), quaternion)
        score = float(best.hypothesis.score)
        return BoxDetection(best.hypothesis.class_id.strip(), T[:3, 3],
                            (box.size.x, box.size.y, box.size.z), T[:3, :3],
                            score if np.isfinite(score) else None, points)  # fmt: skip
    except (ValueError, MapError):  # not finite
        return None
