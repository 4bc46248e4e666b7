"""The parts of the ROS glue: quaternions and odometry lookup, box sampling, the streaming
relocalizer without ROS, message (de)serialization round trips (property tests), and the
core / CLI imports that must not load the extras."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

import semloc
from semloc.results import Hypothesis
from semloc.ros.frames import Trajectory, covariance, matrix_of, quaternion_of
from semloc.ros.stream import BoxDetection, DetectionFrame, StreamLocalizer, box_surface

finite = st.floats(-50, 50, allow_nan=False)
quats = st.lists(st.floats(-1, 1, allow_nan=False), min_size=4, max_size=4).filter(
    lambda q: np.linalg.norm(q) > 0.1
)


@given(st.lists(finite, min_size=3, max_size=3), quats)
def test_quaternion_matrix_round_trip(t, q):
    T = matrix_of(t, q)
    again = matrix_of(T[:3, 3], quaternion_of(T[:3, :3]))
    assert np.allclose(T, again, atol=1e-9)
    assert np.allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-9)


def test_a_zero_or_non_finite_quaternion_is_refused():
    for q in ([0, 0, 0, 0], [np.nan, 0, 0, 1]):
        with pytest.raises(ValueError):
            matrix_of([0, 0, 0], q)


@given(st.floats(0, 1), quats, quats)
def test_trajectory_interpolates_between_its_poses(s, q0, q1):
    A, B = matrix_of([0, 0, 0], q0), matrix_of([2, -1, 0.5], q1)
    track = Trajectory([10**9, 2 * 10**9], [A, B], max_gap_ns=2 * 10**9)
    stamp = 10**9 + int(s * 10**9)
    T = track.at(stamp)
    assert np.allclose(T[:3, 3], (1 - s) * A[:3, 3] + s * B[:3, 3], atol=1e-6)
    assert np.allclose(track.at(10**9), A) and np.allclose(track.at(2 * 10**9), B)
    rotation_to_a = Rotation.from_matrix(A[:3, :3].T @ T[:3, :3]).magnitude()
    assert rotation_to_a <= Rotation.from_matrix(A[:3, :3].T @ B[:3, :3]).magnitude() + 1e-6


def test_trajectory_has_no_answer_far_from_its_stamps_or_across_gaps():
    track = Trajectory([0, 10**8, 5 * 10**9], [np.eye(4)] * 3, max_gap_ns=5 * 10**8)
    assert track.at(2 * 10**9) is None  # inside a 4.9 s gap
    assert track.at(-(10**9)) is None and track.at(7 * 10**9) is None
    assert track.at(5 * 10**7) is not None and track.at(5 * 10**9 + 10**8) is not None


@given(st.lists(st.floats(0.05, 3), min_size=3, max_size=3), quats,
       st.lists(finite, min_size=3, max_size=3))  # fmt: skip
@settings(max_examples=40)
def test_box_surface_points_lie_on_the_box_surface(size, q, centre):
    T = matrix_of(centre, q)
    points = box_surface(T[:3, 3], np.array(size), T[:3, :3])
    local = (points - T[:3, 3]) @ T[:3, :3]
    half = np.array(size) / 2
    assert len(points) == 26
    assert np.all(np.abs(local) <= half + 1e-9)
    on_face = np.isclose(np.abs(local), half, atol=1e-9).any(axis=1)
    assert on_face.all()
    assert np.allclose(local.min(axis=0), -half) and np.allclose(local.max(axis=0), half)


def test_covariance_grows_with_the_residual_and_shrinks_with_pairs():
    centres = np.array([[0, 0, 0], [2, 0, 0], [0, 2, 0], [2, 2, 1.0]])
    pairs = [("g", "l")] * 4
    tight = covariance(Hypothesis(0, 1.0, pairs, np.eye(4), residual=0.05), centres)
    loose = covariance(Hypothesis(0, 1.0, pairs, np.eye(4), residual=0.2), centres)
    few = covariance(Hypothesis(0, 1.0, pairs[:2], np.eye(4), residual=0.05), centres[:2])
    assert np.all(np.diag(loose) > np.diag(tight))
    assert np.all(np.diag(few) > np.diag(tight))
    assert np.allclose(tight, np.diag(np.diag(tight)))


def test_the_stream_localizer_localizes_boxes_without_ros():
    from helpers import room

    gmap = room(12)
    T = matrix_of([1.5, -2.0, 0.0], Rotation.from_euler("z", 40, degrees=True).as_quat())
    inverse = np.linalg.inv(T)
    stream = StreamLocalizer(gmap, use_points=False)
    answers = []
    for k in range(3):  # every object seen three times: published after two detections
        dets = [BoxDetection(o.label, inverse[:3, :3] @ o.position + inverse[:3, 3], (0.5, 0.5, 0.8))
                for o in gmap]  # fmt: skip
        result = stream.step(DetectionFrame(k, "odom", dets), np.eye(4))
        answers.append(result)
    assert answers[0] is None  # nothing published yet
    assert answers[1] is not None and answers[1].status == "localized"
    assert np.allclose(answers[1].pose, T, atol=1e-3)
    assert all(o.points is None for o in stream.local_map())


def test_detections_are_validated():
    with pytest.raises(semloc.MapError):
        BoxDetection("", [0, 0, 0], [1, 1, 1])
    with pytest.raises(semloc.MapError):
        BoxDetection("chair", [0, np.inf, 0], [1, 1, 1])


def test_importing_the_cli_and_the_ros_package_loads_no_ros_or_dsg_package():
    code = ("import sys, semloc.cli, semloc.ros, semloc.ros.bag, semloc.ros.answers; "
            "print(','.join(m for m in sys.modules if m.split('.')[0] in "
            "('rosbags', 'mcap', 'spark_dsg')))")  # fmt: skip
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""


@pytest.mark.parametrize(
    "args, absent",
    [
        (["bag", "info", "x.mcap"], "rosbags"),
        (
            ["bag", "localize", "x.mcap", "--map", "m.json", "--detections", "/d", "-o", "o.mcap"],
            "mcap",
        ),  # fmt: skip
        (["simulate", "out", "--bag"], "rosbags"),
    ],
)
def test_a_missing_ros_extra_is_named_in_one_line(args, absent, monkeypatch, capsys, tmp_path):
    from semloc.cli import extras, main

    monkeypatch.chdir(tmp_path)
    real = extras.missing
    monkeypatch.setattr(extras, "missing", lambda module: module == absent or real(module))
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{absent} is not installed" in err
    assert "pip install 'semloc[ros]'" in err and not (tmp_path / "out").exists()


# Messages (need the extra) ----------------------------------------------------------------
rosbags = pytest.importorskip("rosbags")
from semloc.ros import messages as msgs  # noqa: E402
from semloc.ros.bag import detection_from_msg  # noqa: E402


@given(st.lists(st.tuples(finite, finite, finite), max_size=40),
       st.integers(0, 5), st.integers(0, 2**40))  # fmt: skip
@settings(max_examples=30)
def test_point_clouds_round_trip(points, detections, stamp):
    xyz = np.asarray(points, dtype=np.float32).reshape(-1, 3)
    index = np.arange(len(xyz)) % (detections + 1)
    cloud = msgs.cloud(stamp, "camera", xyz, index)
    again = msgs.deserialize(msgs.serialize(cloud, msgs.POINTS), msgs.POINTS)
    fields = msgs.cloud_fields(again, msgs.POINT_FIELDS)
    assert np.array_equal(np.column_stack([fields[c] for c in "xyz"]), xyz.astype(float))
    assert np.array_equal(fields["detection"], index)
    assert msgs.stamp_ns(again.header.stamp) == stamp


@given(st.text(min_size=1, max_size=20).filter(lambda s: s.strip()), st.floats(0.01, 1),
       st.lists(finite, min_size=3, max_size=3), quats,
       st.lists(st.floats(0.01, 5), min_size=3, max_size=3))  # fmt: skip
@settings(max_examples=40)
def test_detections_round_trip_through_cdr(label, score, centre, q, size):
    T = matrix_of(centre, q)
    hyp = msgs.new("vision_msgs/msg/ObjectHypothesis", class_id=label, score=score)
    other = msgs.new("vision_msgs/msg/ObjectHypothesis", class_id="other", score=score / 2)
    results = [msgs.new("vision_msgs/msg/ObjectHypothesisWithPose", hypothesis=h)
               for h in (other, hyp)]  # fmt: skip
    box = msgs.new("vision_msgs/msg/BoundingBox3D", center=msgs.pose(T), size=msgs.vector(size))
    det = msgs.new("vision_msgs/msg/Detection3D", results=results, bbox=box)
    array = msgs.new(msgs.DETECTIONS, header=msgs.header(5, "cam"), detections=[det])
    again = msgs.deserialize(msgs.serialize(array, msgs.DETECTIONS), msgs.DETECTIONS)
    found = detection_from_msg(again.detections[0], None)
    assert found is not None and found.label == label.strip()
    assert np.allclose(found.centre, T[:3, 3]) and np.allclose(found.rotation, T[:3, :3])
    assert np.allclose(found.size, size)


def test_a_detection_without_a_class_is_skipped_and_an_unset_orientation_is_upright():
    box = msgs.new("vision_msgs/msg/BoundingBox3D", size=msgs.vector((1, 2, 3)))  # w = 0
    assert detection_from_msg(msgs.new("vision_msgs/msg/Detection3D", bbox=box), None) is None
    hyp = msgs.new("vision_msgs/msg/ObjectHypothesis", class_id="sofa", score=0.5)
    result = msgs.new("vision_msgs/msg/ObjectHypothesisWithPose", hypothesis=hyp)
    det = detection_from_msg(
        msgs.new("vision_msgs/msg/Detection3D", bbox=box, results=[result]), None
    )
    assert det is not None and np.allclose(det.rotation, np.eye(3))


def test_a_node_built_on_rclpy_messages_gets_the_same_detections():
    """`detection_from_msg` reads fields only: rclpy's messages (here stand-ins with the same
    fields) give the detections rosbags' do, which is what a live node relies on."""
    from types import SimpleNamespace as M

    T = matrix_of([1.0, 2.0, 0.5], Rotation.from_euler("z", 30, degrees=True).as_quat())
    x, y, z, w = quaternion_of(T[:3, :3])
    fake = M(
        results=[M(hypothesis=M(class_id="chair", score=0.8))],
        bbox=M(center=M(position=M(x=1.0, y=2.0, z=0.5), orientation=M(x=x, y=y, z=z, w=w)),
               size=M(x=0.5, y=0.6, z=0.9)),
    )  # fmt: skip
    hyp = msgs.new("vision_msgs/msg/ObjectHypothesis", class_id="chair", score=0.8)
    real = msgs.new(
        "vision_msgs/msg/Detection3D",
        results=[msgs.new("vision_msgs/msg/ObjectHypothesisWithPose", hypothesis=hyp)],
        bbox=msgs.new("vision_msgs/msg/BoundingBox3D", center=msgs.pose(T),
                      size=msgs.vector((0.5, 0.6, 0.9))),
    )  # fmt: skip
    a, b = detection_from_msg(fake), detection_from_msg(real)
    assert a.label == b.label == "chair" and a.score == b.score
    for field in ("centre", "size", "rotation"):
        assert np.allclose(getattr(a, field), getattr(b, field))
