"""A bag played onto the loopback DDS wire into the live node: the same answers as
`semloc bag localize`, published as ROS 2 messages with ROS 2 names and byte layouts."""

from __future__ import annotations

import json
import random
import threading
import time

import numpy as np
import pytest

from semloc.cli import main
from semloc.io import load_map
from semloc.ros import messages as msgs
from semloc.ros2.node import LiveNode, NodeSettings, Wire
from semloc.ros2.play import play
from semloc.ros2.wire import dds_typename, idl_type, to_wire, topic_name

pytest.importorskip("cyclonedds", reason="the ros2 extra (cyclonedds) is not installed")
pytest.importorskip("rosbags", reason="the ros extra is not installed")


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


@pytest.mark.parametrize(("points", "jsonl"), [(None, "out.jsonl"),
                                               ("/detections/points", "points.jsonl")])  # fmt: skip
def test_a_played_bag_gets_the_answers_of_bag_localize(walk, points, jsonl):
    """Boxes only, and with the detections' points (`--points`, as `bag localize --points`)."""
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
        counts = play(walk / "walk.mcap", player_wire, rate=4.0)
        expected = [json.loads(line) for line in (walk / jsonl).read_text().splitlines()]
        deadline = time.monotonic() + 30
        while len(answers) < len(expected) and time.monotonic() < deadline:
            time.sleep(0.05)
    finally:
        done.set()
        thread.join(10)
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
    time.sleep(0.2)
    heard = [json.loads(s.data) for s in statuses.take(N=1000)]
    assert [h["status"] for h in heard] == [a.result.status for a in answers]
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
            deadline = time.monotonic() + 60
            while len(answers) < len(expected) and time.monotonic() < deadline:
                time.sleep(0.05)
        finally:
            done.set()
            thread.join(10)
    finally:
        server.stop()
    assert [a.result.status for a in answers] == [e["result"]["status"] for e in expected]
    for got, line in zip(answers, expected):
        if line["result"]["pose"] is not None:
            np.testing.assert_allclose(got.result.pose, line["result"]["pose"], atol=1e-5)
