"""Coverage in the ROS 2 node on the loopback DDS wire (`--camera-info TOPIC --range M`): each
update says what the camera covered, from the latest CameraInfo placed by `/tf_static` (latched
before the node started) and the odometry; none until a CameraInfo arrives (said once in the
log); none at all without the topic; a played bag gets the answers of `bag localize
--camera-info`."""

from __future__ import annotations

import json
import logging
import random
import threading
import time

import numpy as np
import pytest
from helpers import room
from test_live_node import walk  # noqa: F401  (the fixture)
from test_node_priors import T_ODOM_CAMERA, Robot, running, wait_for

from semloc import ObjectMap
from semloc.cli import main
from semloc.compiling import warm_up
from semloc.io import load_map
from semloc.ros import messages as msgs
from semloc.ros.bag import opened
from semloc.ros2.node import TF_STATIC, LiveNode, NodeSettings, Wire
from semloc.ros2.play import play
from semloc.ros2.wire import to_wire

pytest.importorskip("cyclonedds", reason="the ros2 extra (cyclonedds) is not installed")
pytest.importorskip("rosbags", reason="the ros extra is not installed")

T_CAMERA_OPTICAL = np.array(
    [[0.0, 0.0, 1.0, 0.1], [-1.0, 0.0, 0.0, 0.0], [0.0, -1.0, 0.0, 0.2], [0.0, 0.0, 0.0, 1.0]]
)  # ROS's optical frame (z forward, x right, y down) on a body frame (x forward, z up)


@pytest.fixture(scope="module")
def one_room() -> ObjectMap:
    warm_up()  # the compiled loops loaded (or compiled) before a node answers
    return room(12)


def camera_info(frame: str, width: int = 640, height: int = 480, f: float = 320.0) -> object:
    k = np.array([f, 0.0, width / 2, 0.0, f, height / 2, 0.0, 0.0, 1.0])
    return msgs.new(msgs.CAMERA_INFO, header=msgs.header(0, frame), width=width, height=height,
                    k=k, distortion_model="plumb_bob")  # fmt: skip


def looks_of(node: LiveNode) -> list:
    """The coverage the node passes with each step (recorded on the way through)."""
    looks, step = [], node.stream.step

    def recording(frame, pose, coverage=None):
        looks.append(coverage)
        return step(frame, pose, coverage)

    node.stream.step = recording
    return looks


def publisher(wire: Wire, topic: str, typename: str, latched: bool = False):
    """A writer of `topic` that has found its reader (volatile topics send nothing before)."""
    writer = wire.writer(topic, typename, latched=latched)
    wait_for(lambda: writer.get_matched_subscriptions())
    return writer


def test_the_camera_s_look_from_camera_info_and_a_latched_tf_static(one_room, caplog):
    caplog.set_level(logging.INFO, logger="semloc.ros2")
    domain = random.randrange(100, 200)
    statics = Wire(domain)  # a static transform broadcaster that started first
    transform = msgs.transform(T_CAMERA_OPTICAL, 0, "camera", "camera_optical")
    statics.publish(TF_STATIC, msgs.TF, msgs.new(msgs.TF, transforms=[transform]), latched=True)
    settings = NodeSettings(domain=domain, reliable=True, camera_info="/camera_info", range_m=7.0)
    node = LiveNode(one_room, settings=settings, wire=Wire(domain))
    looks = looks_of(node)
    answers, stop = running(node)
    try:
        robot = Robot(domain, one_room)
        wait_for(lambda: "camera_optical" in node.statics.parent)  # latched: heard on joining
        robot.detect(range(0, 3))
        wait_for(lambda: len(answers) == 1)
        assert looks == [None, None]  # no CameraInfo yet: no coverage
        assert answers[-1].result.support is None or answers[-1].result.support.n_expected is None
        info = publisher(robot.wire, "/camera_info", msgs.CAMERA_INFO)
        info.write(to_wire(camera_info("camera_optical"), msgs.CAMERA_INFO))
        wait_for(lambda: node.camera is not None)
        robot.detect(range(3, 6))  # with a look, a message that adds no object answers too
        wait_for(lambda: len(answers) == 3)
        info.write(to_wire(camera_info("elsewhere"), msgs.CAMERA_INFO))
        wait_for(lambda: node.camera.frame == "elsewhere")
        robot.detect(range(6, 9))
        wait_for(lambda: len(answers) == 4)
    finally:
        stop()
    # 640 x 480 pixels, focal length 320: 90 degrees across
    assert node.camera.fov_deg == pytest.approx((90.0, 2 * np.degrees(np.arctan(0.75))))
    covered = looks[2:4]
    assert all(c is not None for c in covered)
    for look in covered:
        np.testing.assert_allclose(look.pose, T_ODOM_CAMERA @ T_CAMERA_OPTICAL, atol=1e-9)
        assert look.range_m == 7.0 and look.fov_deg == node.camera.fov_deg
    assert [a.result.support is None or a.result.support.n_expected is not None
            for a in answers[1:3]] == [True, True]  # fmt: skip
    assert looks[4:] == [None, None]  # a camera frame no static transform places
    why = "detection messages whose camera no static transform places (used without coverage)"
    assert node.skipped == {why: 2}
    said = [r.getMessage() for r in caplog.records if "no CameraInfo" in r.getMessage()]
    assert said == ["semloc node: no CameraInfo on /camera_info yet; updates without coverage "
                    "until one arrives"]  # fmt: skip


def test_without_a_camera_info_topic_no_coverage_and_no_readers(one_room):
    domain = random.randrange(100, 200)
    node = LiveNode(one_room, settings=NodeSettings(domain=domain, reliable=True),
                    wire=Wire(domain))  # fmt: skip
    looks = looks_of(node)
    answers, stop = running(node)
    try:
        Robot(domain, one_room).detect(range(0, 4))
        wait_for(lambda: len(answers) == 1)
    finally:
        stop()
    assert looks == [None, None] and node.camera is None
    assert node._camera_info is None and node._tf_static is None


@pytest.mark.slow
def test_a_played_bag_gets_the_answers_of_bag_localize_with_camera_info(walk, tmp_path):  # noqa: F811
    """The CameraInfo is heard before the first detection message (published once ahead, as a
    running camera driver would have), so every update carries the look `bag localize` gives
    it: the same statuses, poses and negative evidence."""
    expected_path = tmp_path / "looks.jsonl"
    argv = ["bag", "localize", str(walk / "walk.mcap"), "--map",
            str(walk / "global_reconstruction.json"), "--detections", "/detections", "--odom",
            "/odom", "--camera-info", "/camera_info", "--range", "6", "-o",
            str(tmp_path / "looks.mcap"), "--jsonl", str(expected_path)]  # fmt: skip
    assert main(argv) == 0
    expected = [json.loads(line)["result"] for line in expected_path.read_text().splitlines()]
    domain = random.randrange(100, 200)
    settings = NodeSettings(domain=domain, reliable=True, camera_info="/camera_info", range_m=6.0)
    node = LiveNode(load_map(walk / "global_reconstruction.json"), settings=settings,
                    wire=Wire(domain))  # fmt: skip
    answers, done = [], threading.Event()
    thread = threading.Thread(target=node.spin, args=(done.is_set, answers.append), daemon=True)
    thread.start()
    try:
        player = Wire(domain)
        with opened(walk / "walk.mcap") as reader:
            conn = next(c for c in reader.connections if c.topic == "/camera_info")
            _, _, raw = next(reader.messages(connections=[conn]))
        first = msgs.deserialize(raw, msgs.CAMERA_INFO)
        publisher(player, "/camera_info", msgs.CAMERA_INFO).write(to_wire(first, msgs.CAMERA_INFO))
        wait_for(lambda: node.camera is not None)
        play(walk / "walk.mcap", player, rate=4.0)
        deadline = time.monotonic() + 180  # a hang guard: ends at the last answer
        while len(answers) < len(expected) and time.monotonic() < deadline:
            time.sleep(0.05)
    finally:
        done.set()
        thread.join(60)
    assert len(answers) == len(expected) and node.skipped == {}
    for got, line in zip(answers, expected):
        assert got.result.status == line["status"]
        got_support = got.result.support.to_dict() if got.result.support else None
        assert got_support == line["support"]
        if line["pose"] is not None:
            np.testing.assert_allclose(got.result.pose, line["pose"], atol=1e-6)
    assert any(line["support"] and line["support"]["n_expected"] for line in expected)
