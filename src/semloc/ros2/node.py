"""The semloc node on a ROS 2 robot's DDS wire: detections and odometry in, answers out.

`LiveNode` subscribes `vision_msgs/Detection3DArray` (`detections`) and `nav_msgs/Odometry`
(`odom`), puts each detection message into the odometry frame, fuses and localizes it as
`semloc bag localize` does (`semloc.ros.stream.StreamLocalizer`, with the long-run window and
tracking of the `Localizer`), and publishes what `bag localize` writes to its MCAP file
(`semloc.ros.answers.AnswerTopics`): `/semloc/pose`, `/tf` (`map` -> odometry frame),
`/semloc/status` (the answer as JSON), `/semloc/markers` (the matches) and `/semloc/map`
(the map's objects, latched).

Frames, as in a bag: a message in the odometry's child (moving) frame is placed by the
odometry at its stamp, interpolated between the odometry messages around it (the node waits
for the first odometry message after the detection's stamp, at most `MAX_GAP_S`); a message in
the odometry frame is used as it is; without odometry (`odom=None`) every message must be in
one frame.

Points: with a `points` topic (sensor_msgs/PointCloud2 with the fields x, y, z and
`detection`, the index of the detection in the array of the same stamp and frame, as `semloc
bag localize --points` reads and `semloc simulate --bag` writes), each detection message waits
for its cloud (at most `CLOUD_WAIT_S`), the detections carry their points (transformed with
them) and the Localizer uses them, as `bag localize --points` does.  vision_msgs 3 and later
(ROS 2 Galactic, Humble, ...) dropped Detection3D's `source_cloud` field, so the points travel
on a topic of their own.  A cloud that cannot be read is a warning (the message is used
without points), never a crash.

Priors: `NodeSettings.prior` (`--near X Y Z --radius R`) is a prior on the odometry frame's
origin from the start; a message on `initialpose` (geometry_msgs/PoseWithCovarianceStamped in
the map frame, RViz's "2D Pose Estimate") replaces it from the next update on, converted with
the odometry at its stamp (`semloc.ros.initialpose`; it waits for the first odometry).  Each
answer carries the prior in effect (`Answer.prior`, `"prior"` in `/semloc/status`).

Coverage: with a `camera_info` topic (sensor_msgs/CameraInfo of the camera that made the
detections, `--camera-info`), each update says what the camera covered (`semloc.Coverage`:
its field of view from the latest CameraInfo, out to `range_m`, placed in the detections'
frame by the static transforms heard on `/tf_static` and in the odometry frame by the
detections' pose), as `bag localize --camera-info` does, and map objects in plain view that
were not detected count against a place.  Until the first CameraInfo arrives the updates carry
no coverage (said once in the log): a node never waits for a camera that may not publish.
`/tf_static` is read reliable and transient-local, as tf2 does, so transforms latched before
the node started arrive too.  A camera frame no static transform joins to the detections'
frame leaves that update without coverage (counted in `skipped`, as a warning).  Without
`camera_info` no coverage is used.

Problems with the messages (no odometry, other frames, unreadable clouds or poses) are
counted in `skipped` and logged once per kind as warnings (logger `semloc.ros2`).

QoS: subscriptions are best-effort with a deep history by default, which matches both the
best-effort publishers of sensor drivers and reliable ones; `reliable=True` asks for reliable
delivery (it then matches reliable publishers only).  Answers are published reliable; the map
reliable and transient-local, so a viewer that starts later still gets it.
"""

from __future__ import annotations

import logging
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from semloc.coverage import Coverage
from semloc.localizer import LocalizerConfig
from semloc.maps import ObjectMap
from semloc.priors import Prior
from semloc.ros import messages as msgs
from semloc.ros.answers import MAP_TOPIC, MATCHES_TOPIC, OUTPUT_TOPICS, AnswerTopics, Frames
from semloc.ros.bag import CLOUD_WAIT_NS, MAX_GAP_S, NO_CLASS, cloud_points, detection_frame
from semloc.ros.camera import Camera, CameraCoverage, CameraError, StaticFrames
from semloc.ros.frames import Trajectory
from semloc.ros.initialpose import TOPIC as INITIALPOSE_TOPIC
from semloc.ros.initialpose import UnusableEstimate, estimate_prior
from semloc.ros.replay import Answer
from semloc.ros.stream import DetectionFrame, StreamLocalizer
from semloc.ros2.wire import idl_type, to_wire, topic_name

MARKERS_TOPIC = "/semloc/markers"
TOPIC_RENAMES = {MATCHES_TOPIC: MARKERS_TOPIC}
"""The bag's topic names that the node publishes under another name."""
HISTORY = 200
TF_STATIC = "/tf_static"
DEFAULT_RANGE_M = 5.0
"""How far (m) the detector finds objects reliably, by default (as `bag localize --range`)."""
CLOUD_WAIT_S = CLOUD_WAIT_NS / 1e9
"""Seconds a detection message waits for its point cloud (with a `points` topic)."""
log = logging.getLogger("semloc.ros2")


@dataclass(frozen=True)
class NodeSettings:
    """Topics, frames, the DDS domain, the subscriptions' reliability and the prior: the
    detections' points on `points` (None: none), pose estimates on `initialpose` (None: not
    read), `prior` on the odometry frame's origin from the start, the CameraInfo of the
    detections' camera on `camera_info` (None: no coverage) and how far it sees (`range_m`)."""

    detections: str = "/detections"
    odom: str | None = "/odom"
    domain: int = 0
    map_frame: str = "map"
    reliable: bool = False
    points: str | None = None
    initialpose: str | None = INITIALPOSE_TOPIC
    prior: Prior | None = None
    camera_info: str | None = None
    range_m: float = DEFAULT_RANGE_M


class Wire:
    """One DDS participant with readers and writers of ROS 2 topics."""

    def __init__(self, domain: int) -> None:
        from cyclonedds.domain import DomainParticipant

        self.participant = DomainParticipant(domain)
        self._writers: dict[str, Any] = {}

    @staticmethod
    def qos(reliable: bool, latched: bool = False, depth: int = HISTORY) -> Any:
        from cyclonedds.core import Policy, Qos
        from cyclonedds.util import duration

        reliability = (
            Policy.Reliability.Reliable(duration(seconds=1))
            if reliable
            else Policy.Reliability.BestEffort
        )
        durability = Policy.Durability.TransientLocal if latched else Policy.Durability.Volatile
        return Qos(reliability, durability, Policy.History.KeepLast(depth),
                   Policy.DataRepresentation(use_cdrv0_representation=True))  # fmt: skip

    def reader(self, topic: str, typename: str, reliable: bool, latched: bool = False) -> Any:
        """`latched`: also the messages published before it joined (transient-local)."""
        from cyclonedds.sub import DataReader
        from cyclonedds.topic import Topic

        dds_topic = Topic(self.participant, topic_name(topic), idl_type(typename))
        return DataReader(self.participant, dds_topic, qos=self.qos(reliable, latched))

    def writer(self, topic: str, typename: str, latched: bool = False) -> Any:
        from cyclonedds.pub import DataWriter
        from cyclonedds.topic import Topic

        if topic not in self._writers:
            dds_topic = Topic(self.participant, topic_name(topic), idl_type(typename))
            qos = self.qos(True, latched, depth=1 if latched else HISTORY)
            self._writers[topic] = DataWriter(self.participant, dds_topic, qos=qos)
        return self._writers[topic]

    def publish(self, topic: str, typename: str, message: Any, latched: bool = False) -> None:
        self.writer(topic, typename, latched).write(to_wire(message, typename))


def samples(reader: Any) -> list[Any]:
    """The messages a reader holds (taken), without the notices of writers that left."""
    from cyclonedds.sub import InvalidSample

    return [m for m in reader.take(N=HISTORY) if not isinstance(m, InvalidSample)]


class WireSink:
    """The `AnswerTopics` sink of the node: messages published instead of written to a file."""

    def __init__(self, wire: Wire) -> None:
        """The writers of every answer topic are made here, before the first answer (as a ROS 2
        node creates its publishers): `ros2 topic list` and `cyclonedds ls` show the topics,
        with their types, from the start."""
        self.wire = wire
        self.counts: dict[str, int] = {}
        for topic, typename in OUTPUT_TOPICS.items():
            topic = TOPIC_RENAMES.get(topic, topic)
            wire.writer(topic, typename, latched=topic == MAP_TOPIC)

    def write(self, topic: str, typename: str, stamp_ns: int, message: Any) -> None:
        topic = TOPIC_RENAMES.get(topic, topic)
        self.wire.publish(topic, typename, message, latched=topic == MAP_TOPIC)
        self.counts[topic] = self.counts.get(topic, 0) + 1


class LiveNode:
    """Detections and odometry from the wire, answers onto it (see the module docstring)."""

    def __init__(
        self,
        global_map: ObjectMap,
        config: LocalizerConfig | None = None,
        settings: NodeSettings | None = None,
        wire: Wire | None = None,
        localizer: Any = None,
    ) -> None:
        """`localizer`: what localizes instead of a new `Localizer` (e.g. a
        `semloc.ros2.remote.RemoteLocalizer` for a `semloc serve` session)."""
        self.settings = settings or NodeSettings()
        self.wire = wire or Wire(self.settings.domain)
        s = self.settings
        self.stream = StreamLocalizer(global_map, config, use_points=s.points is not None,
                                      localizer=localizer)  # fmt: skip
        if s.prior is not None:
            self.stream.localizer.set_prior(s.prior)
        self.global_map = global_map
        self.sink = WireSink(self.wire)
        self._topics: AnswerTopics | None = None
        self._detections = self.wire.reader(s.detections, msgs.DETECTIONS, s.reliable)
        self._odom = None if s.odom is None else self.wire.reader(s.odom, msgs.ODOMETRY, s.reliable)
        self._points = (
            None if s.points is None else self.wire.reader(s.points, msgs.POINTS, s.reliable)
        )
        self._initialpose = (
            None if s.initialpose is None else self.wire.reader(s.initialpose, msgs.POSE, s.reliable)
        )  # fmt: skip
        self._camera_info = (
            None if s.camera_info is None
            else self.wire.reader(s.camera_info, msgs.CAMERA_INFO, s.reliable)
        )  # fmt: skip
        self._tf_static = (
            None if s.camera_info is None
            else self.wire.reader(TF_STATIC, msgs.TF, reliable=True, latched=True)
        )  # fmt: skip
        self.camera: Camera | None = None  # from the latest CameraInfo that gave one
        self.statics = StaticFrames()
        self._said_no_camera = False
        self._estimate: Any = None  # the latest pose estimate not yet applied
        self._clouds: dict[tuple[int, str], Any] = {}  # (stamp, frame) -> cloud message
        self._waiting: deque[tuple[float, Any]] = deque()  # (received, detection message)
        self._frames: dict[int, DetectionFrame] = {}  # id(message) -> its frame, once built
        self._stamps: list[int] = []
        self._poses: list[np.ndarray] = []
        self._odom_frames: tuple[str, str] | None = None
        self._fixed: str | None = None
        self.skipped: dict[str, int] = {}
        self.answers = 0

    def spin(self, until: Callable[[], bool], on_answer: Callable[[Answer], None] | None = None):
        """Answer messages until `until()` is true (checked every millisecond or so)."""
        while not until():
            if not self.poll(on_answer):
                time.sleep(0.001)

    def poll(self, on_answer: Callable[[Answer], None] | None = None) -> int:
        """Take what arrived and answer what can be placed; the number of answers."""
        if self._odom is not None:
            for message in samples(self._odom):
                self._add_odometry(message)
        if self._initialpose is not None:
            for message in samples(self._initialpose):
                self._estimate = message  # the latest estimate wins
        self._read_camera()
        if self._points is not None:
            for message in samples(self._points):
                self._clouds[(msgs.stamp_ns(message.header.stamp), message.header.frame_id)] = (
                    message
                )
        for message in samples(self._detections):
            self._waiting.append((time.monotonic(), message))
        answered = 0
        while True:
            self._apply_estimate_when_due()  # (before each detection: in stamp order)
            if not self._waiting:
                break
            received, message = self._waiting[0]
            waited = time.monotonic() - received
            frame = self._frame(message, waited)
            if frame is None:
                break  # its point cloud has not arrived yet
            pose, ready = self._pose(frame, waited)
            if not ready:
                break
            self._waiting.popleft()
            del self._frames[id(message)]
            if pose is None:
                continue
            result = self.stream.step(frame, pose, self._coverage(frame, pose))
            if result is None:
                continue
            answer = Answer(frame.stamp, frame.frame, self._odom_frame(frame), pose, result,
                            self.stream.localizer.prior)  # fmt: skip
            self._publish(answer)
            answered += 1
            if on_answer is not None:
                on_answer(answer)
        return answered

    def _publish(self, answer: Answer) -> None:
        if self._topics is None:
            frames = Frames(self.settings.map_frame, answer.odom_frame, answer.frame)
            self._topics = AnswerTopics(self.sink, self.global_map, frames)
        self._topics.write(answer.stamp, answer.result, answer.T_odom_sensor,
                           self.stream.local_map())  # fmt: skip
        self.answers += 1

    def _add_odometry(self, message: Any) -> None:
        frames = (message.header.frame_id, message.child_frame_id)
        if self._odom_frames is not None and frames != self._odom_frames:
            self._skip("odometry messages in other frames than the first")
            return
        self._odom_frames = frames
        try:
            pose = msgs.matrix(message.pose.pose)
        except ValueError:
            self._skip("odometry messages without a valid pose")
            return
        self._stamps.append(msgs.stamp_ns(message.header.stamp))
        self._poses.append(pose)
        if len(self._stamps) > 4 * HISTORY:  # a bounded trajectory: the newest poses
            del self._stamps[:HISTORY], self._poses[:HISTORY]

    def _frame(self, message: Any, waited_s: float) -> DetectionFrame | None:
        """The message's detections with their points (None while its cloud may still come)."""
        found = self._frames.get(id(message))
        if found is not None:
            return found
        points: dict[int, np.ndarray] = {}
        if self._points is not None:
            key = (msgs.stamp_ns(message.header.stamp), message.header.frame_id)
            cloud = self._clouds.pop(key, None)
            if cloud is None and waited_s <= CLOUD_WAIT_S:
                return None
            for old in [k for k in self._clouds if k[0] < key[0] - CLOUD_WAIT_NS]:
                del self._clouds[old]
            if cloud is None:
                self._skip(
                    f"detection messages without their point cloud within {CLOUD_WAIT_S:g} s"
                )
            else:
                try:
                    points = cloud_points(cloud, len(message.detections))
                except ValueError as exc:
                    self._skip("point clouds that cannot be read (used without points)", str(exc))
        frame, dropped = detection_frame(message, points)
        if dropped:
            self._skip(NO_CLASS, count=dropped)
        self._frames[id(message)] = frame
        return frame

    def _read_camera(self) -> None:
        """The static transforms and the latest usable CameraInfo that arrived."""
        if self._tf_static is not None:
            for message in samples(self._tf_static):
                self.statics.add(message)
        if self._camera_info is None:
            return
        for message in samples(self._camera_info):
            try:
                camera = Camera.of(message)
            except CameraError as exc:
                self._skip("camera info messages without a field of view", str(exc))
                continue
            if camera != self.camera:
                h, v = camera.fov_deg
                log.info("coverage from %s: camera frame '%s', field of view %.0f x %.0f deg, "
                         "range %g m", self.settings.camera_info, camera.frame, h, v,
                         self.settings.range_m)  # fmt: skip
            self.camera = camera

    def _coverage(self, frame: DetectionFrame, pose: np.ndarray) -> Coverage | None:
        """What the camera covered at this message (None: no camera info topic, none heard
        yet, or a camera no static transform places)."""
        if self._camera_info is None:
            return None
        if self.camera is None:
            if not self._said_no_camera:
                log.info("semloc node: no CameraInfo on %s yet; updates without coverage until "
                         "one arrives", self.settings.camera_info)  # fmt: skip
                self._said_no_camera = True
            return None
        look = CameraCoverage(self.camera, self.statics, self.settings.range_m)
        try:
            return look.at(pose, frame.frame)
        except CameraError as exc:
            self._skip("detection messages whose camera no static transform places (used "
                       "without coverage)", str(exc))  # fmt: skip
            return None

    def _apply_estimate_when_due(self) -> None:
        """Apply the pending pose estimate once no waiting detection is stamped before it: a
        detection made before the estimate is answered without it, however late it is read
        (a busy node may take both in one poll), as `bag localize` reads a bag in order."""
        if self._estimate is not None:
            stamp = msgs.stamp_ns(self._estimate.header.stamp)
            if all(msgs.stamp_ns(m.header.stamp) >= stamp for _, m in self._waiting):
                self._apply_estimate()

    def _apply_estimate(self) -> None:
        """The pending pose estimate as the prior from the next update on, once the odometry
        places the robot (see `semloc.ros.initialpose`)."""
        if self._odom is not None and not self._stamps:
            return  # waits for the first odometry
        message, self._estimate = self._estimate, None
        odometry = None
        if self._odom is not None:
            odometry = Trajectory(self._stamps, self._poses, int(MAX_GAP_S * 1e9))
        try:
            prior = estimate_prior(message, self.settings.map_frame, odometry)
        except UnusableEstimate as exc:
            self._skip(exc.why, exc.detail)
            return
        self.stream.localizer.set_prior(prior)
        log.info("prior from %s: %s", self.settings.initialpose, prior.to_dict())

    def _pose(self, frame: DetectionFrame, waited_s: float) -> tuple[np.ndarray | None, bool]:
        """(pose of the frame in the odometry frame or None to skip it, whether decided)."""
        if self._odom is None:
            self._fixed = self._fixed if self._fixed is not None else frame.frame
            if frame.frame != self._fixed:
                self._skip(f"messages not in the first frame '{self._fixed}' (no odometry)")
                return None, True
            return np.eye(4), True
        if self._odom_frames is None:
            if waited_s > MAX_GAP_S:
                self._skip(f"detection messages without odometry within {MAX_GAP_S:g} s")
                return None, True
            return None, False
        parent, child = self._odom_frames
        if frame.frame == parent:
            return np.eye(4), True
        if frame.frame != child:
            self._skip(f"messages in frame '{frame.frame}' (odometry: {parent} -> {child})")
            return None, True
        if self._stamps[-1] < frame.stamp and waited_s <= MAX_GAP_S:
            return None, False  # the odometry after it has not arrived yet
        pose = Trajectory(self._stamps, self._poses, int(MAX_GAP_S * 1e9)).at(frame.stamp)
        if pose is None:
            self._skip(f"detection messages without odometry within {MAX_GAP_S:g} s")
        return pose, True

    def _odom_frame(self, frame: DetectionFrame) -> str:
        return frame.frame if self._odom_frames is None else self._odom_frames[0]

    def _skip(self, why: str, detail: str = "", count: int = 1) -> None:
        """Count a kind of problem (`why`); the first of each kind is logged as a warning
        (with its `detail`)."""
        if why not in self.skipped:
            log.warning("semloc node: skipped %s%s", why, f": {detail}" if detail else "")
        self.skipped[why] = self.skipped.get(why, 0) + count
