"""`semloc simulate --bag`, `semloc bag info` and `semloc bag localize` end to end: a simulated
walk written as a bag localizes as the in-process Localizer does on the same detections, the
answers read back as MCAP with their topics and schemas, bags built by rosbags (sqlite3 and
MCAP storage) localize, and bad bags end in one line, exit 2 and nothing written."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

pytest.importorskip("rosbags")
pytest.importorskip("mcap")

from rosbag_fixtures import T_MAP_ODOM, messages, write_bag  # noqa: E402

import semloc  # noqa: E402
from semloc import Prior  # noqa: E402
from semloc.cli import main  # noqa: E402
from semloc.ros import messages as msgs  # noqa: E402
from semloc.ros.answers import OUTPUT_TOPICS  # noqa: E402
from semloc.sim.noise import DetectionNoise  # noqa: E402
from semloc.sim.scenario import simulate_sequence  # noqa: E402
from semloc.transforms import pose_error  # noqa: E402

SIM = dict(seed=0, size="small", keyframes=24, resolution="120x90")
RVIZ = np.diag([0.25, 0.25, 0.0, 0.0, 0.0, 0.06853891945200942]).ravel()  # 0.5 m, 15 deg


@pytest.fixture(scope="module")
def walk(tmp_path_factory):
    out = tmp_path_factory.mktemp("walk")
    argv = ["simulate", str(out), "--bag", "--no-snapshots", "--seed", str(SIM["seed"]),
            "--size", SIM["size"], "--keyframes", str(SIM["keyframes"]),
            "--resolution", SIM["resolution"]]  # fmt: skip
    assert main(argv) == 0
    return out


@pytest.fixture(scope="module")
def localized(walk):
    argv = ["bag", "localize", str(walk / "walk.mcap"), "--map",
            str(walk / "global_reconstruction.json"), "--detections", "/detections",
            "--odom", "/odom", "--points", "/detections/points", "-o", str(walk / "out.mcap"),
            "--jsonl", str(walk / "out.jsonl")]  # fmt: skip
    assert main(argv) == 0
    return walk


def _lines(path):
    return [json.loads(line) for line in path.read_text().splitlines()]


def test_simulate_bag_lists_its_topics(walk, capsys):
    capsys.readouterr()
    assert main(["bag", "info", str(walk / "walk.mcap")]) == 0
    out = capsys.readouterr().out
    for topic, use in (("/detections ", "--detections"), ("/odom", "--odom"),
                       ("/detections/points", "--points")):  # fmt: skip
        line = next(line for line in out.splitlines() if topic in line)
        assert use in line and f" {SIM['keyframes']} " in line


def test_bag_answers_equal_the_in_process_localizer_on_the_same_detections(localized):
    seq = simulate_sequence(SIM["seed"], SIM["size"], "all", "walk", n_keyframes=SIM["keyframes"],
                            resolution=(120, 90), noise=DetectionNoise())  # fmt: skip
    gmap = semloc.load_map(localized / "global_reconstruction.json")
    loc = semloc.Localizer(gmap, local_up=[0, 0, 1])
    expected = [(1.0 + 0.1 * i, loc.update(kf.objects))
                for i, kf in enumerate(seq.keyframes) if kf.objects]  # fmt: skip
    lines = _lines(localized / "out.jsonl")
    assert [round(line["stamp"], 6) for line in lines] == [round(s, 6) for s, _ in expected]
    for line, (_, result) in zip(lines, expected, strict=True):
        got = line["result"]
        assert got["status"] == result.status
        assert [h["pairs"] for h in got["hypotheses"]] == [
            [{"global": g, "local": lid} for g, lid in h.pairs] for h in result.hypotheses
        ]
        if result.pose is None:
            assert got["pose"] is None
        else:
            assert np.allclose(got["pose"], result.pose, atol=1e-6)
        assert len(got["steps"]) == 1 and "labels" in got and "changes" in got


def test_bag_localization_of_the_simulated_walk_is_accurate(localized):
    truth = np.asarray(json.loads((localized / "ground_truth.json").read_text())["T_global_local"])
    last = _lines(localized / "out.jsonl")[-1]["result"]
    assert last["status"] == "localized"
    rotation, translation = pose_error(np.asarray(last["pose"]), truth)
    assert rotation < 2.0 and translation < 0.1


def test_the_mcap_output_reads_back_with_its_topics_and_schemas(localized):
    from mcap.reader import make_reader

    with open(localized / "out.mcap", "rb") as handle:
        reader = make_reader(handle)
        summary = reader.get_summary()
        channels = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
        assert channels == OUTPUT_TOPICS
        assert all(s.encoding == "ros2msg" for s in summary.schemas.values())
        decoded, frames = {}, set()
        for schema, channel, message in reader.iter_messages():
            decoded.setdefault(channel.topic, msgs.deserialize(message.data, schema.name))
            if channel.topic == "/tf":
                tf = msgs.deserialize(message.data, schema.name)
                frames |= {(t.header.frame_id, t.child_frame_id) for t in tf.transforms}
    status = json.loads(decoded["/semloc/status"].data)
    assert {"stamp", "status", "confidence", "reason", "changes", "next_look"} <= set(status)
    assert status["next_look"] == [] or status["status"] == "ambiguous"
    pose = decoded["/semloc/pose"]
    assert pose.header.frame_id == "map"
    cov = np.asarray(pose.pose.covariance).reshape(6, 6)
    assert np.all(np.diag(cov) > 0) and np.allclose(cov, cov.T)
    assert ("map", "odom") in frames and ("odom", "camera") in frames
    assert len(decoded["/semloc/map"].markers) == 2 * len(
        semloc.load_map(localized / "global_reconstruction.json")
    )


def test_every_line_and_status_is_the_one_answer_schema(localized):
    """The `--jsonl` lines are `schema.BagLine`s and every `/semloc/status` a
    `schema.StatusAnswer` (the localize JSON at its stamp, as the ROS 2 node publishes it)."""
    from mcap.reader import make_reader

    from semloc import schema

    lines = _lines(localized / "out.jsonl")
    assert [schema.problems(line, schema.BagLine) for line in lines] == [[]] * len(lines)
    with open(localized / "out.mcap", "rb") as handle:
        statuses = [json.loads(msgs.deserialize(m.data, s.name).data)
                    for s, c, m in make_reader(handle).iter_messages(topics=["/semloc/status"])]  # fmt: skip
    assert len(statuses) == len(lines)
    assert [schema.problems(s, schema.StatusAnswer) for s in statuses] == [[]] * len(lines)
    for status, line in zip(statuses, lines):
        assert status["stamp"] == line["stamp"] and status["status"] == line["result"]["status"]
        assert status["hypotheses"] == line["result"]["hypotheses"][:3]  # pairs: a list


@pytest.mark.parametrize("storage", ["sqlite3", "mcap"])
@pytest.mark.parametrize("points", [False, True])
def test_bags_built_by_rosbags_localize(tmp_path, storage, points):
    from helpers import room

    gmap = room(14)
    semloc.save_map(gmap, tmp_path / "map.json")
    bag = write_bag(tmp_path / "run", messages(gmap, points=points), storage)
    argv = ["bag", "localize", str(bag), "--map", str(tmp_path / "map.json"),
            "--detections", "/detections", "--odom", "/odom", "-o", str(tmp_path / "o.mcap"),
            "--jsonl", str(tmp_path / "o.jsonl")]  # fmt: skip
    assert main(argv + (["--points", "/points"] if points else [])) == 0
    last = _lines(tmp_path / "o.jsonl")[-1]["result"]
    assert last["status"] == "localized"
    rotation, translation = pose_error(np.asarray(last["pose"]), T_MAP_ODOM)
    assert rotation < 1.0 and translation < 0.05


def _one_error_line(capsys, *fragments):
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("semloc: error: "), err
    for fragment in fragments:
        assert fragment in err, err


def _localize(bag, walk, out, *extra):
    return main(["bag", "localize", str(bag), "--map", str(walk / "global_reconstruction.json"),
                 "-o", str(out), *extra])  # fmt: skip


@pytest.mark.parametrize(
    "options, fragments",
    [
        (["--detections", "/nothing"], ["no topic /nothing", "--detections"]),
        (["--detections", "/odom"], ["/odom holds nav_msgs/msg/Odometry", "Detection3DArray"]),
        (["--detections", "/detections", "--odom", "/detections"], ["--odom needs"]),
        (["--detections", "/detections", "--points", "/odom"], ["--points needs"]),
    ],
)
def test_wrong_topics_end_in_one_line(walk, tmp_path, capsys, options, fragments):
    capsys.readouterr()
    out = tmp_path / "o.mcap"
    assert _localize(walk / "walk.mcap", walk, out, *options) == 2
    _one_error_line(capsys, "walk.mcap", *fragments)
    assert not out.exists()


def test_truncated_and_non_bags_end_in_one_line(walk, tmp_path, capsys):
    data = (walk / "walk.mcap").read_bytes()
    cases = {"cut.mcap": data[: len(data) // 2], "text.mcap": b"not a bag\n", "empty.db3": b""}
    for name, content in cases.items():
        (tmp_path / name).write_bytes(content)
        capsys.readouterr()
        out = tmp_path / "o.mcap"
        code = _localize(tmp_path / name, walk, out, "--detections", "/detections", "--jsonl",
                         str(tmp_path / "o.jsonl"))  # fmt: skip
        assert code == 2, name
        _one_error_line(capsys, name)
        assert not out.exists() and not (tmp_path / "o.jsonl").exists()
    capsys.readouterr()
    assert main(["bag", "info", str(tmp_path / "missing.mcap")]) == 2
    _one_error_line(capsys, "missing.mcap", "no such file")


def test_detections_in_a_frame_the_odometry_does_not_give_are_refused(tmp_path, capsys):
    from helpers import room

    gmap = room(8)
    semloc.save_map(gmap, tmp_path / "map.json")
    bag = write_bag(tmp_path / "run", messages(gmap, frame="lidar"), "mcap")
    capsys.readouterr()
    argv = ["bag", "localize", str(bag), "--map", str(tmp_path / "map.json"),
            "--detections", "/detections", "--odom", "/odom", "-o", str(tmp_path / "o.mcap")]  # fmt: skip
    assert main(argv) == 2
    _one_error_line(capsys, "frame 'lidar'", "'odom' -> 'base'")
    assert not (tmp_path / "o.mcap").exists()


def test_detections_without_odometry_near_them_are_refused(tmp_path, capsys):
    from helpers import room

    gmap = room(8)
    semloc.save_map(gmap, tmp_path / "map.json")
    records = messages(gmap)
    for topic, _, stamp, message in records:  # the odometry 100 s later than the detections
        if topic == "/odom":
            message.header.stamp = msgs.stamp(stamp + 100 * 10**9)
    bag = write_bag(tmp_path / "run", records, "sqlite3")
    capsys.readouterr()
    argv = ["bag", "localize", str(bag), "--map", str(tmp_path / "map.json"),
            "--detections", "/detections", "--odom", "/odom", "-o", str(tmp_path / "o.mcap")]  # fmt: skip
    assert main(argv) == 2
    _one_error_line(capsys, "no detection message has odometry within 0.5 s")
    assert not (tmp_path / "o.mcap").exists()


def test_outputs_never_overwrite_the_inputs(walk, tmp_path, capsys):
    copy = tmp_path / "walk.mcap"
    shutil.copy(walk / "walk.mcap", copy)
    before = copy.read_bytes()
    capsys.readouterr()
    assert _localize(copy, walk, copy, "--detections", "/detections") == 2
    _one_error_line(capsys, "would overwrite the bag")
    assert copy.read_bytes() == before
    out = tmp_path / "same"
    assert _localize(copy, walk, out, "--detections", "/detections", "--jsonl", str(out)) == 2
    _one_error_line(capsys, "would both write it")


def test_the_last_answer_agrees_with_semloc_localize_on_the_final_local_map(localized, capsys):
    """`semloc localize` replays the final local map by `seen` (objects in their final state),
    the bag one message at a time (objects as they were then): the same place, within mm."""
    capsys.readouterr()
    assert main(["localize", str(localized / "global_reconstruction.json"),
                 str(localized / "local.json"), "--format", "json"]) == 0  # fmt: skip
    replayed = json.loads(capsys.readouterr().out)
    last = _lines(localized / "out.jsonl")[-1]["result"]
    assert replayed["status"] == last["status"] == "localized"
    rotation, translation = pose_error(np.asarray(last["pose"]), np.asarray(replayed["pose"]))
    assert rotation < 0.5 and translation < 0.02


def test_detections_in_a_moving_frame_without_odom_get_one_warning(walk, tmp_path, capsys):
    """The simulated walk's detections are in the camera frame, which /odom moves: without
    --odom the command says so in one line on stderr (and answers as before); with it, no
    warning."""
    capsys.readouterr()
    out = tmp_path / "no_odom.mcap"
    assert _localize(walk / "walk.mcap", walk, out, "--detections", "/detections") == 0
    warnings = [line for line in capsys.readouterr().err.splitlines() if "warning" in line]
    assert len(warnings) == 1, warnings
    assert "which /odom moves" in warnings[0] and "give --odom /odom" in warnings[0]
    out = tmp_path / "odom.mcap"
    assert _localize(walk / "walk.mcap", walk, out, "--detections", "/detections",
                     "--odom", "/odom") == 0  # fmt: skip
    assert "warning" not in capsys.readouterr().err


def test_near_and_radius_are_a_prior_on_the_odometry_origin(localized, tmp_path, capsys):
    """Around the true odometry origin the run localizes as without a prior; 10 m away it
    never claims a place; bad values end in one line (the options of `semloc localize`)."""
    truth = np.asarray(json.loads((localized / "ground_truth.json").read_text())["T_global_local"])
    run = ["--detections", "/detections", "--odom", "/odom", "--points", "/detections/points"]
    x, y, z = truth[:3, 3] + [0.5, -0.5, 0.0]
    near = ["--near", str(x), str(y), str(z), "--radius", "2"]
    assert _localize(localized / "walk.mcap", localized, tmp_path / "a.mcap", *run, *near,
                     "--jsonl", str(tmp_path / "a.jsonl")) == 0  # fmt: skip
    within = [line["result"] for line in _lines(tmp_path / "a.jsonl")]
    assert within[-1]["status"] == "localized"
    assert all(h.get("outside_prior") is False for r in within for h in r["hypotheses"][:1])
    rotation, translation = pose_error(np.asarray(within[-1]["pose"]), truth)
    assert rotation < 2.0 and translation < 0.1
    far = ["--near", str(x + 10), str(y), str(z), "--radius", "2"]
    assert _localize(localized / "walk.mcap", localized, tmp_path / "b.mcap", *run, *far,
                     "--jsonl", str(tmp_path / "b.jsonl")) == 0  # fmt: skip
    assert all(line["result"]["status"] != "localized" for line in _lines(tmp_path / "b.jsonl"))
    capsys.readouterr()
    for bad, message in ((["--near", "1", "2", "3"], "--near X Y Z and --radius R go together"),
                         (["--near", "1", "2", "3", "--radius", "0"], "radius must be > 0")):  # fmt: skip
        assert _localize(localized / "walk.mcap", localized, tmp_path / "c.mcap", *run, *bad) == 2
        _one_error_line(capsys, message)


def _estimate(stamp: int, T_map_robot: np.ndarray, frame: str = "map"):
    """A geometry_msgs/PoseWithCovarianceStamped as RViz's 2D Pose Estimate sends it."""
    message = msgs.new(msgs.POSE, header=msgs.header(stamp, frame))
    message.pose.pose = msgs.pose(T_map_robot)
    message.pose.covariance = RVIZ.copy()
    return message


def _status_priors(path):
    from mcap.reader import make_reader

    with open(path, "rb") as handle:
        return [json.loads(msgs.deserialize(m.data, s.name).data)["prior"]
                for s, c, m in make_reader(handle).iter_messages(topics=["/semloc/status"])]  # fmt: skip


def test_initialpose_in_a_bag_sets_the_prior_from_the_next_detection_message(tmp_path, capsys):
    """An estimate recorded after keyframe 3 is the prior (odom_prior with the odometry at its
    stamp) of every answer from keyframe 4 on, in --jsonl and /semloc/status; an estimate
    before any odometry and one in another frame are left out, one warning each on stderr;
    --initialpose none reads none."""
    from helpers import room
    from rosbag_fixtures import robot_poses

    from semloc.ros.initialpose import odom_prior

    gmap = room(14)
    semloc.save_map(gmap, tmp_path / "map.json")
    drive = messages(gmap, n=16, radius=4.0)
    stamp = 10**9 + 3 * 10**8  # keyframe 3's odometry
    robot = robot_poses(16)[3]
    records = [
        ("/initialpose", msgs.POSE, 5 * 10**8, _estimate(5 * 10**8, T_MAP_ODOM)),  # before odom
        *[r for r in drive if r[2] <= stamp],
        ("/initialpose", msgs.POSE, stamp + 1, _estimate(stamp, T_MAP_ODOM @ robot)),
        ("/initialpose", msgs.POSE, stamp + 2, _estimate(stamp, T_MAP_ODOM @ robot, "odom")),
        *[r for r in drive if r[2] > stamp],
    ]
    bag = write_bag(tmp_path / "run", records)
    run = ["--detections", "/detections", "--odom", "/odom"]
    capsys.readouterr()
    assert _localize(bag, tmp_path, tmp_path / "a.mcap", *run,
                     "--jsonl", str(tmp_path / "a.jsonl"), "--map", str(tmp_path / "map.json")) == 0  # fmt: skip
    warnings = [line for line in capsys.readouterr().err.splitlines() if "warning" in line]
    assert warnings == ["warning: skipped 1 pose estimates before any odometry",
                        "warning: skipped 1 pose estimates not in the map frame 'map'"]  # fmt: skip
    lines = _lines(tmp_path / "a.jsonl")
    expected = odom_prior(T_MAP_ODOM @ robot, RVIZ, robot).to_dict()
    after = [line["stamp"] > stamp / 1e9 for line in lines]
    assert any(after) and not all(after)
    priors = [line["result"]["prior"] for line in lines]
    assert [p is not None for p in priors] == after
    for prior in filter(None, priors):  # the message's pose went through a quaternion
        assert set(prior) == set(expected)
        np.testing.assert_allclose(prior["position"], expected["position"], atol=1e-9)
        for key in ("radius", "heading", "heading_tolerance"):
            assert prior[key] == pytest.approx(expected[key], abs=1e-9)
    assert _status_priors(tmp_path / "a.mcap") == priors
    assert lines[-1]["result"]["status"] == "localized"
    assert Prior.from_dict(expected).contains(T_MAP_ODOM)  # the truth lies within it
    assert _localize(bag, tmp_path, tmp_path / "b.mcap", *run, "--initialpose", "none",
                     "--jsonl", str(tmp_path / "b.jsonl"), "--map", str(tmp_path / "map.json")) == 0  # fmt: skip
    assert "warning" not in capsys.readouterr().err
    assert all(line["result"]["prior"] is None for line in _lines(tmp_path / "b.jsonl"))


def test_an_initialpose_topic_that_is_not_one_ends_in_one_line(walk, tmp_path, capsys):
    """The default topic may be absent (the walk has none: answers as before, prior null);
    a topic given that is absent or of another type ends in one line, exit 2."""
    run = ["--detections", "/detections", "--odom", "/odom"]
    assert _localize(walk / "walk.mcap", walk, tmp_path / "a.mcap", *run,
                     "--jsonl", str(tmp_path / "a.jsonl")) == 0  # fmt: skip
    assert all(line["result"]["prior"] is None for line in _lines(tmp_path / "a.jsonl"))
    for topic, fragment in (("/pose", "no topic /pose (--initialpose)"),
                            ("/odom", "--initialpose needs geometry_msgs/msg/PoseWithCovarianceStamped")):  # fmt: skip
        capsys.readouterr()
        assert _localize(walk / "walk.mcap", walk, tmp_path / "b.mcap", *run,
                         "--initialpose", topic) == 2  # fmt: skip
        _one_error_line(capsys, fragment)
        assert not (tmp_path / "b.mcap").exists()


def test_camera_info_makes_each_update_say_what_the_camera_covered(walk, tmp_path, capsys):
    """With --camera-info every answer weighs what the camera should have seen: the support
    and the hypotheses say how many map objects the looks expected and how many were missing;
    without it they say nothing (null)."""
    capsys.readouterr()
    assert main(["bag", "info", str(walk / "walk.mcap")]) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if "/camera_info" in x)
    assert "--camera-info" in line
    run = ["--detections", "/detections", "--odom", "/odom", "--points", "/detections/points"]
    looks = tmp_path / "looks.jsonl"
    assert _localize(walk / "walk.mcap", walk, tmp_path / "a.mcap", *run, "--camera-info",
                     "/camera_info", "--range", "6", "--jsonl", str(looks)) == 0  # fmt: skip
    results = [line["result"] for line in _lines(looks)]
    supported = [r["support"] for r in results if r["support"] is not None]
    assert supported and all(s["n_expected"] is not None for s in supported)
    assert any(s["n_expected"] > 0 for s in supported)
    best = [r["hypotheses"][0] for r in results if r["hypotheses"] and r["hypotheses"][0]["pose"]]
    assert best and all("n_missing" in h and "n_expected" in h for h in best)
    assert results[-1]["status"] == "localized"
    last = results[-1]["support"]
    assert len(last["missing_ids"]) == min(last["n_missing"], 50)
    said = (
        f"support: {last['n_pairs']} pairs; {last['n_missing']} of {last['n_expected']} map objects"
    )
    assert said in " ".join(capsys.readouterr().out.split())
    plain = [line["result"] for line in _lines(walk / "out.jsonl")] if (
        walk / "out.jsonl").exists() else []  # fmt: skip
    assert all(r["support"] is None or r["support"]["n_missing"] is None for r in plain)


def test_a_camera_info_topic_of_another_type_ends_in_one_line(walk, tmp_path, capsys):
    capsys.readouterr()
    out = tmp_path / "o.mcap"
    assert _localize(walk / "walk.mcap", walk, out, "--detections", "/detections", "--odom",
                     "/odom", "--camera-info", "/odom") == 2  # fmt: skip
    _one_error_line(capsys, "walk.mcap", "--camera-info needs", "CameraInfo")
    assert not out.exists()
