"""Interoperability with tools semloc did not write (issue 54), on the loopback DDS wire.

A `semloc ros2 node` process is seen by Cyclone DDS's own command-line tools (`cyclonedds ls`,
`typeof`, `subscribe`, shipped with the `cyclonedds` package) with ROS 2's topic and type
names, and a subscriber typed here field by field from the ROS 2 .msg definitions (not from
semloc's wire types), reading classic CDR (XCDR1) only as `rmw_cyclonedds_cpp` does, receives
the poses `semloc bag localize --jsonl` gives for the same bag.  The bag's odometry is read
with `rosbags` (not semloc's bag reader).
"""

# (no `from __future__ import annotations`: cyclonedds reads the IdlStruct fields' types)
import json
import os
import queue
import random
import re
import signal
import subprocess
import sys
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from test_live_node import walk  # noqa: F401  (the fixture)

pytest.importorskip("cyclonedds", reason="the ros2 extra (cyclonedds) is not installed")
pytest.importorskip("rosbags", reason="the ros extra is not installed")

import cyclonedds.idl.types as t  # noqa: E402
from cyclonedds.builtin import BuiltinDataReader, BuiltinTopicDcpsSubscription  # noqa: E402
from cyclonedds.core import Policy, Qos  # noqa: E402
from cyclonedds.domain import DomainParticipant  # noqa: E402
from cyclonedds.idl import IdlStruct  # noqa: E402
from cyclonedds.sub import DataReader, InvalidSample  # noqa: E402
from cyclonedds.topic import Topic  # noqa: E402
from cyclonedds.util import duration  # noqa: E402

pytestmark = pytest.mark.slow  # a node process and the cyclonedds tool on the wire: 5-15 s each

CLI = Path(sys.executable).parent / "cyclonedds"
CLI_ENV = {"COLUMNS": "4000", "PYTHONUNBUFFERED": "1"}  # rich: no truncated names, no wrapping


# The ROS 2 message definitions (Humble), field by field, with ROS 2's DDS type names.
# builtin_interfaces/msg/Time, std_msgs/msg/Header, std_msgs/msg/String
@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: t.int32
    nanosec: t.uint32


@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time
    frame_id: str


@dataclass
class String(IdlStruct, typename="std_msgs::msg::dds_::String_"):
    data: str


# geometry_msgs/msg/{Point, Quaternion, Pose, PoseWithCovariance, PoseWithCovarianceStamped}
@dataclass
class Point(IdlStruct, typename="geometry_msgs::msg::dds_::Point_"):
    x: t.float64
    y: t.float64
    z: t.float64


@dataclass
class Quaternion(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
    x: t.float64
    y: t.float64
    z: t.float64
    w: t.float64


@dataclass
class Pose(IdlStruct, typename="geometry_msgs::msg::dds_::Pose_"):
    position: Point
    orientation: Quaternion


@dataclass
class PoseWithCovariance(IdlStruct, typename="geometry_msgs::msg::dds_::PoseWithCovariance_"):
    pose: Pose
    covariance: t.array[t.float64, 36]


@dataclass
class PoseWithCovarianceStamped(
    IdlStruct, typename="geometry_msgs::msg::dds_::PoseWithCovarianceStamped_"
):
    header: Header
    pose: PoseWithCovariance


# geometry_msgs/msg/{Vector3, Transform, TransformStamped}, tf2_msgs/msg/TFMessage
@dataclass
class Vector3(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
    x: t.float64
    y: t.float64
    z: t.float64


@dataclass
class Transform(IdlStruct, typename="geometry_msgs::msg::dds_::Transform_"):
    translation: Vector3
    rotation: Quaternion


@dataclass
class TransformStamped(IdlStruct, typename="geometry_msgs::msg::dds_::TransformStamped_"):
    header: Header
    child_frame_id: str
    transform: Transform


@dataclass
class TFMessage(IdlStruct, typename="tf2_msgs::msg::dds_::TFMessage_"):
    transforms: t.sequence[TransformStamped]


XCDR1_ONLY = Qos(
    Policy.Reliability.Reliable(duration(seconds=1)),
    Policy.History.KeepLast(1000),
    Policy.DataRepresentation(use_cdrv0_representation=True),
)
"""A reader as `rmw_cyclonedds_cpp` makes one: classic CDR only (and reliable, deep)."""


def matrix(position, orientation) -> np.ndarray:
    """A 4x4 pose from a position and a unit quaternion (x, y, z, w)."""
    x, y, z, w = orientation.x, orientation.y, orientation.z, orientation.w
    T = np.eye(4)
    T[:3, :3] = [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                 [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                 [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]  # fmt: skip
    T[:3, 3] = [position.x, position.y, position.z]
    return T


def stamp_ns(header) -> int:
    return header.stamp.sec * 1_000_000_000 + header.stamp.nanosec


def lines(stream) -> queue.Queue:
    """The lines of a process's output stream, as they come (read by a thread)."""
    got: queue.Queue = queue.Queue()

    def read():
        for line in stream:
            got.put(line)

    threading.Thread(target=read, daemon=True).start()
    return got


def until(condition, seconds: float, step: float = 0.05) -> bool:
    """Poll `condition()` until it is true or `seconds` have passed; its last value."""
    deadline = time.monotonic() + seconds
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(step)
    return True


@contextmanager
def running_node(walk: Path):  # noqa: F811
    """A `semloc ros2 node` process (reliable subscriptions) on a random domain: the domain."""
    domain = random.randrange(100, 200)  # apart from other runs on this machine
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    node = subprocess.Popen([sys.executable, "-m", "semloc", "ros2", "node", "--map",
                             str(walk / "global_reconstruction.json"), "--domain", str(domain),
                             "--reliable"], env=env, text=True, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)  # fmt: skip
    out = lines(node.stdout)
    try:
        first = out.get(timeout=180)
        assert "semloc node on domain" in first, first
        yield domain
    finally:
        node.send_signal(signal.SIGINT)
        try:
            _, err = node.communicate(timeout=120)
        except subprocess.TimeoutExpired:
            node.kill()
            _, err = node.communicate()
    assert node.returncode == 130 and "Traceback" not in err, err


def cli(*args: str, seconds: float = 60) -> str:
    """The output of a bounded run of the `cyclonedds` command-line tool."""
    assert '<NetworkInterface name="lo"/>' in os.environ["CYCLONEDDS_URI"]  # loopback only
    run = subprocess.run([str(CLI), *args, "--suppress-progress-bar", "--color", "none"],
                         env={**os.environ, **CLI_ENV}, capture_output=True, text=True,
                         timeout=seconds)  # fmt: skip
    assert run.returncode == 0, run.stdout + run.stderr
    return run.stdout


def listed(listing: str) -> dict[str, tuple[str, set[str]]]:
    """`cyclonedds ls`'s tables: topic -> (type name, {"Writers", "Readers"})."""
    found: dict[str, tuple[str, set[str]]] = {}
    topic = None
    for line in listing.splitlines():
        if m := re.search(r"─ (rt/\S+) ─", line):
            topic = m.group(1)
            found.setdefault(topic, ("", set()))
        elif topic and (m := re.search(r"Typename\s*│\s*(\S+)", line)):
            found[topic] = (m.group(1), found[topic][1])
        elif topic and (m := re.search(r"│\s+(Writers|Readers)\s", line)):
            found[topic][1].add(m.group(1))
    return found


NODE_TOPICS = {
    "rt/semloc/pose": ("geometry_msgs::msg::dds_::PoseWithCovarianceStamped_", "Writers"),
    "rt/semloc/status": ("std_msgs::msg::dds_::String_", "Writers"),
    "rt/tf": ("tf2_msgs::msg::dds_::TFMessage_", "Writers"),
    "rt/semloc/markers": ("visualization_msgs::msg::dds_::MarkerArray_", "Writers"),
    "rt/semloc/map": ("visualization_msgs::msg::dds_::MarkerArray_", "Writers"),
    "rt/detections": ("vision_msgs::msg::dds_::Detection3DArray_", "Readers"),
    "rt/odom": ("nav_msgs::msg::dds_::Odometry_", "Readers"),
    "rt/initialpose": ("geometry_msgs::msg::dds_::PoseWithCovarianceStamped_", "Readers"),
}

POSE_IDL = [  # what `cyclonedds typeof` must rebuild, whitespace aside: the .msg definitions
    "module geometry_msgs { module msg { module dds_ {",
    "@final struct Time_ { long sec; unsigned long nanosec; };",
    "@final struct Header_ { builtin_interfaces::msg::dds_::Time_ stamp; string frame_id; };",
    "@final struct Point_ { double x; double y; double z; };",
    "@final struct Quaternion_ { double x; double y; double z; double w; };",
    "@final struct Pose_ { geometry_msgs::msg::dds_::Point_ position; "
    "geometry_msgs::msg::dds_::Quaternion_ orientation; };",
    "@final struct PoseWithCovariance_ { geometry_msgs::msg::dds_::Pose_ pose; "
    "double covariance[36]; };",
    "@final struct PoseWithCovarianceStamped_ { std_msgs::msg::dds_::Header_ header; "
    "geometry_msgs::msg::dds_::PoseWithCovariance_ pose; };",
]


@pytest.fixture
def cyclonedds_cli():
    if not CLI.exists():
        pytest.skip(f"the cyclonedds command-line tool is not installed ({CLI})")
    return CLI


def test_cyclonedds_ls_and_typeof_see_ros2_names(walk, cyclonedds_cli):  # noqa: F811
    """Before any message: the node's publishers and subscriptions exist from the start (as a
    ROS 2 node's), under `rt/<topic>` with `<pkg>::msg::dds_::<Type>_` type names."""
    with running_node(walk) as domain:
        seen: dict = {}

        def all_listed() -> bool:
            seen.update(listed(cli("ls", "--domain-id", str(domain), "--runtime", "2")))
            return all(seen.get(topic, ("", set()))[0] == typename and kind in seen[topic][1]
                       for topic, (typename, kind) in NODE_TOPICS.items())  # fmt: skip

        assert until(all_listed, 120, step=0.5), seen
        idl: list[str] = []

        def rebuilt() -> bool:
            out = cli("typeof", "rt/semloc/pose", "--domain-id", str(domain), "--runtime", "2")
            idl.append(" ".join(out.split()))
            return all(part in idl[-1] for part in POSE_IDL)

        assert until(rebuilt, 120, step=0.5), idl[-1]
        assert idl[-1].count("struct PoseWithCovarianceStamped_ ") == 1  # one type definition


def test_cyclonedds_subscribe_and_a_subscriber_from_the_msg_definitions_get_the_answers(
    walk,  # noqa: F811
    cyclonedds_cli,
):
    """`cyclonedds subscribe rt/semloc/status` prints the node's answers; a reader of the types
    above, XCDR1 only, gets every pose and map -> odom transform of `semloc bag localize
    --jsonl` on the same bag (within 1e-6, matched by stamp)."""
    from rosbags.highlevel import AnyReader

    expected = {round(line["stamp"] * 1e9): line["result"]
                for line in map(json.loads, (walk / "out.jsonl").read_text().splitlines())}  # fmt: skip
    answered = {stamp for stamp, result in expected.items() if result["pose_is_answer"]}
    assert len(answered) > 5
    odometry: dict[int, tuple[str, np.ndarray]] = {}  # stamp -> (child frame, T_odom_child)
    with AnyReader([walk / "walk.mcap"]) as bag:
        for connection, _, raw in bag.messages([c for c in bag.connections if c.topic == "/odom"]):
            m = bag.deserialize(raw, connection.msgtype)
            odometry[stamp_ns(m.header)] = (m.child_frame_id,
                                            matrix(m.pose.pose.position, m.pose.pose.orientation))  # fmt: skip

    with running_node(walk) as domain:
        participant = DomainParticipant(domain)
        poses = DataReader(participant, Topic(participant, "rt/semloc/pose",
                                              PoseWithCovarianceStamped), qos=XCDR1_ONLY)  # fmt: skip
        tf = DataReader(participant, Topic(participant, "rt/tf", TFMessage), qos=XCDR1_ONLY)
        subscriptions = BuiltinDataReader(participant, BuiltinTopicDcpsSubscription)
        subscriber = subprocess.Popen(
            [str(CLI), "subscribe", "rt/semloc/status", "--domain-id", str(domain), "--runtime",
             "2", "--qos", "scan-random", "--type", "scan-random", "--suppress-progress-bar",
             "--color", "none"], env={**os.environ, **CLI_ENV}, text=True,
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT)  # fmt: skip
        printed = lines(subscriber.stdout)
        heard: list[str] = []
        try:
            others: set = set()

            def cli_subscribed() -> bool:  # the CLI's reader on rt/semloc/status is discovered
                others.update(s.key for s in subscriptions.take(N=100)
                              if s.topic_name == "rt/semloc/status"
                              and s.participant_key != participant.guid)  # fmt: skip
                return bool(others)

            assert until(lambda: poses.get_matched_publications()
                         and tf.get_matched_publications(), 120), "no writer matched"  # fmt: skip
            assert until(cli_subscribed, 120), "cyclonedds subscribe did not subscribe"
            env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
            played = subprocess.run([sys.executable, "-m", "semloc", "ros2", "play",
                                     str(walk / "walk.mcap"), "--domain", str(domain)],
                                    env=env, capture_output=True, text=True, timeout=120)  # fmt: skip
            assert played.returncode == 0 and "/detections 24" in played.stdout, played.stderr
            got: dict[int, PoseWithCovarianceStamped] = {}
            transforms: dict[int, TransformStamped] = {}

            def all_poses() -> bool:
                for m in poses.take(N=1000):
                    if not isinstance(m, InvalidSample):
                        got[stamp_ns(m.header)] = m
                for m in tf.take(N=1000):
                    if not isinstance(m, InvalidSample):
                        for f in m.transforms:
                            if f.header.frame_id == "map":
                                transforms[stamp_ns(f.header)] = f
                return len(got) >= len(answered) and len(transforms) >= len(answered)

            until(all_poses, 180)

            def status_printed() -> bool:
                while not printed.empty():
                    heard.append(printed.get())
                return any('"status": "' in line for line in heard)

            until(status_printed, 120)
        finally:
            subscriber.send_signal(signal.SIGINT)
            try:
                subscriber.communicate(timeout=60)
            except subprocess.TimeoutExpired:
                subscriber.kill()
                subscriber.communicate()
    while not printed.empty():
        heard.append(printed.get())
    output = "".join(heard)

    # cyclonedds subscribe: the node's answers as std_msgs/String, the JSON of bag localize's
    statuses = [json.loads(m) for m in re.findall(r"data='(\{.*\})'", output)]
    assert statuses and "String_(" in output, output
    for status in statuses:
        assert status["status"] == expected[round(status["stamp"] * 1e9)]["status"]

    # the subscriber from the .msg definitions: every pose, in frame map, equal to bag localize's
    assert set(got) == answered and set(transforms) == answered
    for stamp, message in got.items():
        assert message.header.frame_id == "map"
        child, T_odom_sensor = odometry[stamp]
        T_map_odom = np.asarray(expected[stamp]["pose"])
        pose = message.pose.pose
        np.testing.assert_allclose(matrix(pose.position, pose.orientation),
                                   T_map_odom @ T_odom_sensor, atol=1e-6)  # fmt: skip
        covariance = np.asarray(message.pose.covariance).reshape(6, 6)
        assert np.all(np.isfinite(covariance)) and np.all(np.diag(covariance) >= 0)
        assert covariance[0, 0] > 0 and covariance[1, 1] > 0
        np.testing.assert_allclose(covariance, covariance.T, atol=1e-12)
        frame = transforms[stamp]
        assert frame.child_frame_id == "odom" and child == "camera"
        np.testing.assert_allclose(matrix(frame.transform.translation, frame.transform.rotation),
                                   T_map_odom, atol=1e-6)  # fmt: skip
