"""A bag played onto the loopback DDS wire into the live node: the same answers as
`semloc bag localize` (and, for a bag with an /initialpose message, the same prior in effect),
published as ROS 2 messages with ROS 2 names and byte layouts."""

from __future__ import annotations

import json
import random
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from semloc import schema
from semloc.cli import main
from semloc.io import load_map
from semloc.ros import messages as msgs
from semloc.ros.bag import opened
from semloc.ros.mcap_out import McapSink
from semloc.ros.simbag import PERIOD_NS, START_NS
from semloc.ros2.node import LiveNode, NodeSettings, Wire
from semloc.ros2.play import play
from semloc.ros2.wire import dds_typename, idl_type, to_wire, topic_name

pytestmark = pytest.mark.slow  # a live node on the wire: 30-60 s waits

pytest.importorskip("cyclonedds", reason="the ros2 extra (cyclonedds) is not installed")
pytest.importorskip("rosbags", reason="the ros extra is not installed")


ESTIMATE_AT = 2
"""The keyframe after whose messages the estimate bag holds a pose estimate on /initialpose."""
RVIZ = np.diag([0.25, 0.25, 0.0, 0.0, 0.0, 0.06853891945200942]).ravel()  # 0.5 m, 15 deg


def with_estimate(walk: Path) -> Path:
    """walk.mcap with one /initialpose message (map frame, RViz's covariance): the robot's true
    pose at keyframe ESTIMATE_AT (the odometry there, placed by the ground truth), stamped as
    that odometry, recorded half a period after it (written with semloc's own MCAP writer)."""
    truth = np.asarray(json.loads((walk / "ground_truth.json").read_text())["T_global_local"])
    sink, pending = McapSink(), None
    with opened(walk / "walk.mcap") as reader:
        for conn, log_time, raw in reader.messages():
            if pending is not None and log_time > pending[0]:
                sink.write("/initialpose", msgs.POSE, *pending)
                pending = None
            message = msgs.deserialize(raw, conn.msgtype)
            sink.write(conn.topic, conn.msgtype, log_time, message)
            if conn.topic == "/odom" and log_time == START_NS + ESTIMATE_AT * PERIOD_NS:
                estimate = msgs.new(msgs.POSE, header=msgs.header(log_time, "map"))
                estimate.pose.pose = msgs.pose(truth @ msgs.matrix(message.pose.pose))
                estimate.pose.covariance = RVIZ.copy()
                pending = (log_time + PERIOD_NS // 2, estimate)
    path = walk / "estimate.mcap"
    path.write_bytes(sink.getvalue())
    return path


@pytest.fixture(scope="module")
def walk(tmp_path_factory):
    out = tmp_path_factory.mktemp("walk")
    argv = ["simulate", str(out), "--bag", "--no-snapshots", "--seed", "0", "--size", "small",
            "--keyframes", "24", "--resolution", "120x90"]  # fmt: skip
    assert main(argv) == 0
    argv = ["bag", "localize", str(out / "walk.mcap"), "--map",
            str(out / "global_reconstruction.json"), "--detections", "/detections",
            "--odom", "/odom", "-o", str(out / "out.mcap"), "--jsonl", str(out / "out.jsonl")]  # fmt: skip
    assert main(argv) == 0
    with_points = [*argv[:-4], "--points", "/detections/points", "-o", str(out / "points.mcap"),
                   "--jsonl", str(out / "points.jsonl")]  # fmt: skip
    assert main(with_points) == 0
    estimate = [*argv[:-4], "-o", str(out / "estimate.out.mcap"), "--jsonl",
                str(out / "estimate.jsonl")]  # fmt: skip
    estimate[2] = str(with_estimate(out))
    assert main(estimate) == 0
    return out


def test_ros2_names_and_byte_layouts():
    assert topic_name("/semloc/pose") == "rt/semloc/pose"
    assert dds_typename(msgs.POSE) == "geometry_msgs::msg::dds_::PoseWithCovarianceStamped_"
    T = np.eye(4)
    T[:3, 3] = [1.5, -2.0, 0.25]
    marker = msgs.new("visualization_msgs/msg/Marker", header=msgs.header(7, "map"), ns="x",
                      id=3, pose=msgs.pose(T), points=[msgs.point([1, 2, 3])], text="chair")  # fmt: skip
    for message, typename in ((msgs.new(msgs.MARKERS, markers=[marker]), msgs.MARKERS),
                              (msgs.transform(T, 9, "map", "odom"), "geometry_msgs/msg/TransformStamped")):  # fmt: skip
        wire = to_wire(message, typename)
        assert type(wire) is idl_type(typename)
        assert wire.serialize() == msgs.serialize(message, typename)  # classic CDR, as rosbag2


@pytest.mark.parametrize(("bag", "points", "jsonl", "rate"), [
    ("walk.mcap", None, "out.jsonl", 4.0),
    ("walk.mcap", "/detections/points", "points.jsonl", 4.0),
    ("estimate.mcap", None, "estimate.jsonl", 1.0),
])  # fmt: skip
def test_a_played_bag_gets_the_answers_of_bag_localize(walk, bag, points, jsonl, rate):
    """Boxes only, with the detections' points (`--points`, as `bag localize --points`), and
    with a pose estimate on /initialpose (the prior in effect, in the answers and the status,
    is the bag's; played at the recorded pace, so the estimate arrives between the two
    detection messages it lies between, as recorded)."""
    domain = random.randrange(100, 200)  # apart from other runs on this machine
    global_map = load_map(walk / "global_reconstruction.json")
    node_wire, player_wire, listener = Wire(domain), Wire(domain), Wire(domain)
    poses = listener.reader("/semloc/pose", msgs.POSE, reliable=True)
    statuses = listener.reader("/semloc/status", msgs.STRING, reliable=True)
    settings = NodeSettings(domain=domain, reliable=True, points=points)
    node = LiveNode(global_map, settings=settings, wire=node_wire)
    answers, done = [], threading.Event()
    thread = threading.Thread(target=node.spin, args=(done.is_set, answers.append), daemon=True)
    thread.start()
    try:
        counts = play(walk / bag, player_wire, rate=rate)
        expected = [json.loads(line) for line in (walk / jsonl).read_text().splitlines()]
        deadline = time.monotonic() + 180  # a hang guard: ends at the last answer
        while len(answers) < len(expected) and time.monotonic() < deadline:
            time.sleep(0.05)
    finally:
        done.set()
        thread.join(60)
    assert counts["/detections"] == 24 and counts["/odom"] == 24
    assert len(answers) == len(expected) and node.skipped == {}
    assert node.stream.use_points == (points is not None)
    assert all((o.points is not None) == (points is not None) for o in node.stream.local_map())
    for got, line in zip(answers, expected):
        assert got.stamp / 1e9 == pytest.approx(line["stamp"], abs=1e-9)
        assert got.result.status == line["result"]["status"]
        if line["result"]["pose"] is None:
            assert got.result.pose is None
        else:
            np.testing.assert_allclose(got.result.pose, line["result"]["pose"], atol=1e-6)
        assert (None if got.prior is None else got.prior.to_dict()) == line["result"]["prior"]
    heard: list[dict] = []
    deadline = time.monotonic() + 60  # a hang guard: ends when every answer was heard
    while len(heard) < len(answers) and time.monotonic() < deadline:
        heard += [json.loads(s.data) for s in statuses.take(N=1000)]
        time.sleep(0.05)
    assert [h["status"] for h in heard] == [a.result.status for a in answers]
    assert [schema.problems(h, schema.StatusAnswer) for h in heard] == [[]] * len(heard)
    assert [h["prior"] for h in heard] == [line["result"]["prior"] for line in expected]
    if bag == "estimate.mcap":  # no prior before the estimate, its prior after it
        assert counts["/initialpose"] == 1
        after = [a.stamp > START_NS + ESTIMATE_AT * PERIOD_NS for a in answers]
        assert [a.prior is not None for a in answers] == after and any(after)
        assert [h["prior"] for h in heard].count(None) == after.count(False)
    localized = sum(a.result.status == "localized" for a in answers)
    assert len(poses.take(N=1000)) == localized > 0


def test_the_node_localizes_through_semloc_serve(walk):
    pytest.importorskip("fastapi", reason="the serve extra is not installed")
    from semloc.client import Client
    from semloc.ros2.remote import RemoteLocalizer
    from semloc.serve.app import create_app
    from semloc.serve.server import ThreadedServer
    from semloc.serve.service import Service
    from semloc.serve.store import open_store

    server = ThreadedServer(create_app(Service(open_store(walk / "store"))))
    try:
        client = Client(server.url)
        client.put_map("walk", load_map(walk / "global_reconstruction.json"))
        served_map = client.get_map("walk")
        remote = RemoteLocalizer(client.session("walk", up=(0, 0, 1)), served_map)
        domain = random.randrange(100, 200)
        node = LiveNode(served_map, settings=NodeSettings(domain=domain, reliable=True),
                        wire=Wire(domain), localizer=remote)  # fmt: skip
        answers, done = [], threading.Event()
        thread = threading.Thread(target=node.spin, args=(done.is_set, answers.append))
        thread.start()
        try:
            play(walk / "walk.mcap", Wire(domain), rate=0.0)
            expected = [json.loads(line) for line in (walk / "out.jsonl").read_text().splitlines()]
            deadline = time.monotonic() + 180  # a hang guard: ends at the last answer
            while len(answers) < len(expected) and time.monotonic() < deadline:
                time.sleep(0.05)
        finally:
            done.set()
            thread.join(60)
    finally:
        server.stop()
    assert [a.result.status for a in answers] == [e["result"]["status"] for e in expected]
    for got, line in zip(answers, expected):
        if line["result"]["pose"] is not None:
            np.testing.assert_allclose(got.result.pose, line["result"]["pose"], atol=1e-5)
