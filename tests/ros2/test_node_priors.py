"""Priors in the ROS 2 node on the loopback DDS wire: `/initialpose` published to a running
node turns an ambiguous map of two identical rooms into an answer in the room it names, and an
estimate elsewhere gives the outside-prior reason; `--near/--radius` (NodeSettings.prior) from
the start; a malformed point cloud is a warning, never a crash."""

from __future__ import annotations

import random
import threading
import time

import numpy as np
import pytest
from helpers import room

from semloc import ObjectMap, Prior
from semloc.compiling import warm_up
from semloc.priors import OUTSIDE_PRIOR
from semloc.ros import messages as msgs
from semloc.ros2.node import LiveNode, NodeSettings, Wire

pytest.importorskip("cyclonedds", reason="the ros2 extra (cyclonedds) is not installed")
pytest.importorskip("rosbags", reason="the ros extra is not installed")

from semloc.transforms import yaw_pose  # noqa: E402

SHIFT = np.array([30.0, 0.0, 0.0])
T_MAP_ODOM = yaw_pose(0.7, [0.5, 0.5, 0.0])  # the truth: the odometry frame in room A
T_ODOM_CAMERA = yaw_pose(0.3, [2.0, 1.0, 0.0])  # the robot, 2.2 m from the odometry origin
RVIZ = np.diag([0.25, 0.25, 0.0, 0.0, 0.0, 0.06853891945200942])  # 0.5 m, 15 deg


@pytest.fixture(scope="module")
def two_rooms() -> ObjectMap:
    warm_up()  # the compiled loops loaded (or compiled) before a node answers
    a = room(12)
    b = [o.replace(id=o.id.replace("a", "b"), position=o.position + SHIFT) for o in a]
    return ObjectMap([*a, *b], up=[0, 0, 1], name="two rooms")


class Robot:
    """Publishes odometry, detections of room A's objects and pose estimates to a node."""

    def __init__(self, domain: int, world: ObjectMap, points: str | None = None) -> None:
        self.wire, self.world, self.stamp = Wire(domain), world, 10**9
        self.topics = {"/odom": msgs.ODOMETRY, "/detections": msgs.DETECTIONS,
                       "/initialpose": msgs.POSE}  # fmt: skip
        if points is not None:
            self.topics[points] = msgs.POINTS
        writers = [self.wire.writer(t, k) for t, k in self.topics.items()]
        deadline = time.monotonic() + 120  # a hang guard
        while not all(w.get_matched_subscriptions() for w in writers):
            assert time.monotonic() < deadline, "the node was not discovered"
            time.sleep(0.01)

    def detect(self, indices, cloud: object = None) -> None:
        """Objects `indices` of room A detected twice (two messages, camera frame): the front
        end publishes an object from its second detection on, so one answer comes of it."""
        for _ in range(2):
            self._detections(indices, cloud)

    def _detections(self, indices, cloud: object) -> None:
        self.stamp += 10**8
        odom = msgs.new(msgs.ODOMETRY, header=msgs.header(self.stamp, "odom"),
                        child_frame_id="camera")  # fmt: skip
        odom.pose.pose = msgs.pose(T_ODOM_CAMERA)
        self.wire.publish("/odom", msgs.ODOMETRY, odom)
        to_camera = np.linalg.inv(T_MAP_ODOM @ T_ODOM_CAMERA)
        detections = []
        for i in indices:
            obj = self.world[i]  # room A: the first objects
            centre = to_camera[:3, :3] @ obj.position + to_camera[:3, 3]
            box = np.eye(4)
            box[:3, 3] = centre
            hypothesis = msgs.new("vision_msgs/msg/ObjectHypothesis", class_id=obj.label,
                                  score=0.9)  # fmt: skip
            result = msgs.new("vision_msgs/msg/ObjectHypothesisWithPose", hypothesis=hypothesis)
            bbox = msgs.new("vision_msgs/msg/BoundingBox3D", center=msgs.pose(box),
                            size=msgs.vector([0.4, 0.4, 0.4]))  # fmt: skip
            detections.append(msgs.new("vision_msgs/msg/Detection3D", results=[result],
                                       bbox=bbox, header=msgs.header(self.stamp, "camera")))  # fmt: skip
        array = msgs.new(msgs.DETECTIONS, header=msgs.header(self.stamp, "camera"),
                         detections=detections)  # fmt: skip
        self.wire.publish("/detections", msgs.DETECTIONS, array)
        if cloud is not None:
            cloud.header = msgs.header(self.stamp, "camera")
            self.wire.publish(next(t for t, k in self.topics.items() if k == msgs.POINTS),
                              msgs.POINTS, cloud)  # fmt: skip

    def estimate(self, T_map_robot: np.ndarray, frame: str = "map") -> None:
        message = msgs.new(msgs.POSE, header=msgs.header(self.stamp, frame))
        message.pose.pose = msgs.pose(T_map_robot)
        message.pose.covariance = RVIZ.ravel().copy()
        self.wire.publish("/initialpose", msgs.POSE, message)


def running(node: LiveNode):
    answers, done = [], threading.Event()
    thread = threading.Thread(target=node.spin, args=(done.is_set, answers.append), daemon=True)
    thread.start()

    def stop() -> None:
        done.set()
        thread.join(10)

    return answers, stop


def wait_for(condition, seconds: float = 120.0) -> None:
    deadline = time.monotonic() + seconds
    while not condition():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.02)


def test_initialpose_decides_between_two_rooms_and_a_wrong_one_is_outside(two_rooms):
    domain = random.randrange(100, 200)
    settings = NodeSettings(domain=domain, reliable=True)
    node = LiveNode(two_rooms, settings=settings, wire=Wire(domain))
    answers, stop = running(node)
    try:
        robot = Robot(domain, two_rooms)
        robot.detect(range(0, 3))
        robot.detect(range(3, 6))
        wait_for(lambda: len(answers) == 2)
        assert answers[-1].result.status == "ambiguous"  # two identical rooms
        assert node.stream.localizer.prior is None
        robot.estimate(T_MAP_ODOM @ T_ODOM_CAMERA)  # RViz: "the robot is here", in room A
        wait_for(lambda: node.stream.localizer.prior is not None)
        prior = node.stream.localizer.prior
        assert prior.contains(T_MAP_ODOM) and prior.heading == pytest.approx(np.degrees(0.7))
        robot.detect(range(6, 9))
        wait_for(lambda: len(answers) == 3)
        found = answers[-1].result
        assert found.status == "localized", found.reason
        np.testing.assert_allclose(found.pose, T_MAP_ODOM, atol=0.02)
        assert all(g.startswith("a") for g, _ in found.hypotheses[0].pairs)
        # an estimate in room B, 4 m from where B's copy of the view would put the robot
        elsewhere = yaw_pose(0.0, SHIFT + [3.0, 3.0, 0.0]) @ T_MAP_ODOM @ T_ODOM_CAMERA
        robot.estimate(elsewhere)
        wait_for(lambda: node.stream.localizer.prior != prior)
        robot.detect(range(9, 12))
        wait_for(lambda: len(answers) == 4)
        outside = answers[-1].result
        assert outside.status == "ambiguous" and outside.reason.startswith(OUTSIDE_PRIOR)
        assert outside.hypotheses[0].outside_prior is True
        robot.estimate(np.eye(4), frame="odom")  # not in the map frame: skipped, named
        wait_for(lambda: any("not in the map frame" in why for why in node.skipped))
    finally:
        stop()


def test_near_and_radius_hold_from_the_start_and_a_bad_cloud_is_a_warning(two_rooms, caplog):
    domain = random.randrange(100, 200)
    near = Prior(position=T_MAP_ODOM[:3, 3] + [0.5, -0.5, 0.0], radius=1.5)
    settings = NodeSettings(domain=domain, reliable=True, prior=near, points="/points")
    node = LiveNode(two_rooms, settings=settings, wire=Wire(domain))
    answers, stop = running(node)
    try:
        robot = Robot(domain, two_rooms, points="/points")
        bad = msgs.cloud(0, "camera", np.zeros((4, 3)), np.zeros(4))
        bad.width = 1000  # says 1000 points, holds 4
        robot.detect(range(0, 4), cloud=bad)
        robot.detect(range(4, 8), cloud=msgs.cloud(0, "camera", np.zeros((0, 3)), np.zeros(0)))
        wait_for(lambda: len(answers) == 2)
    finally:
        stop()
    assert answers[-1].result.status == "localized"
    np.testing.assert_allclose(answers[-1].result.pose, T_MAP_ODOM, atol=0.02)
    assert node.skipped == {"point clouds that cannot be read (used without points)": 2}
    [warning] = [r.getMessage() for r in caplog.records if r.name == "semloc.ros2"]
    assert "point cloud data holds 64 bytes, not 1000 x 16" in warning
