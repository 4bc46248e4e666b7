"""`semloc ros2 node | play | echo` as processes on the loopback DDS wire."""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import time

import pytest
from test_live_node import walk  # noqa: F401  (the fixture)

pytest.importorskip("cyclonedds", reason="the ros2 extra (cyclonedds) is not installed")
pytest.importorskip("rosbags", reason="the ros extra is not installed")


def semloc(*args: str, env: dict | None = None, **options) -> subprocess.Popen:
    env = {**(os.environ if env is None else env), "PYTHONPATH": os.pathsep.join(sys.path)}
    return subprocess.Popen([sys.executable, "-m", "semloc", *args], env=env, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, **options)  # fmt: skip


@pytest.mark.slow
def test_node_play_and_echo_as_commands(walk):  # noqa: F811
    domain = str(random.randrange(100, 200))
    node = semloc("ros2", "node", "--map", str(walk / "global_reconstruction.json"),
                  "--domain", domain, "--reliable")  # fmt: skip
    echo = semloc("ros2", "echo", "/semloc/status", "--domain", domain, "--count", "3")
    try:
        first = node.stdout.readline()
        assert "semloc node on domain" in first, first + node.stderr.read()
        time.sleep(1.0)  # discovery
        played = semloc("ros2", "play", str(walk / "walk.mcap"), "--domain", domain, "--rate", "4")
        out, err = played.communicate(timeout=120)
        assert played.returncode == 0, err
        assert "/detections 24" in out and "/odom 24" in out
        lines, _ = echo.communicate(timeout=60)
        statuses = [json.loads(json.loads(line)["data"])["status"] for line in lines.splitlines()]
        assert len(statuses) == 3 and set(statuses) <= {"localized", "ambiguous", "failed"}
    finally:
        echo.kill()
        node.send_signal(signal.SIGINT)
        out, err = node.communicate(timeout=120)
    assert node.returncode == 130, err
    assert err.strip().splitlines()[-1] == "semloc: interrupted" and "Traceback" not in err
    assert any(s in out for s in ("localized", "ambiguous"))


def test_echo_needs_a_type_for_an_unknown_topic():
    run = semloc("ros2", "echo", "/somewhere")
    _, err = run.communicate(timeout=60)
    assert run.returncode == 2 and "give --type" in err


def test_node_prior_options_are_checked_in_one_line(walk):  # noqa: F811
    base = ["ros2", "node", "--map", str(walk / "global_reconstruction.json")]
    for bad, message in ((["--radius", "2"], "--near X Y Z and --radius R go together"),
                         (["--near", "1", "2", "3", "--radius", "-1"], "radius must be > 0")):  # fmt: skip
        run = semloc(*base, *bad)
        _, err = run.communicate(timeout=60)
        assert run.returncode == 2 and message in err and "Traceback" not in err, err


@pytest.mark.slow
def test_without_cyclonedds_uri_the_commands_stay_on_loopback(walk):  # noqa: F811
    """Started without CYCLONEDDS_URI, `ros2 play` and `ros2 echo` fall back to loopback (and
    say so): they find each other, and nothing is sent to the machine's network."""
    bare = {k: v for k, v in os.environ.items() if k != "CYCLONEDDS_URI"}
    domain = str(random.randrange(100, 200))
    echo = semloc("ros2", "echo", "/odom", "--domain", domain, "--count", "2", env=bare)
    try:
        time.sleep(1.0)  # discovery
        played = semloc("ros2", "play", str(walk / "walk.mcap"), "--domain", domain,
                        "--rate", "4", env=bare)  # fmt: skip
        out, err = played.communicate(timeout=120)
        assert played.returncode == 0, err
        assert "DDS stays on this machine (loopback): CYCLONEDDS_URI is not set" in err
        lines, echo_err = echo.communicate(timeout=60)
    finally:
        echo.kill()
    assert len(lines.splitlines()) == 2, echo_err  # heard over loopback
    assert "DDS stays on this machine (loopback)" in echo_err


def test_a_set_cyclonedds_uri_is_honoured_and_a_bad_network_refused(walk):  # noqa: F811
    from semloc.ros2.wire import LOOPBACK, choose_network

    assert os.environ["CYCLONEDDS_URI"]  # (set by the tests' conftest)
    before = os.environ["CYCLONEDDS_URI"]
    assert choose_network("loopback") is None and choose_network("default") is None
    assert os.environ["CYCLONEDDS_URI"] == before  # never overridden
    assert '<NetworkInterface name="lo"/>' in LOOPBACK and "AllowMulticast>false" in LOOPBACK
    run = semloc("ros2", "echo", "/odom", "--network", "everywhere")
    _, err = run.communicate(timeout=60)
    assert run.returncode == 2 and "Invalid value for '--network'" in err
    assert "'everywhere' is not one of 'loopback', 'default'" in err


def test_the_node_banner_lists_every_topic_it_reads(walk):  # noqa: F811
    node = semloc("ros2", "node", "--map", str(walk / "global_reconstruction.json"),
                  "--domain", str(random.randrange(100, 200)), "--points", "/detections/points")  # fmt: skip
    try:
        first = node.stdout.readline()
    finally:
        node.send_signal(signal.SIGINT)
        node.communicate(timeout=30)
    assert ": /detections + /odom + /detections/points -> " in first, first


def test_the_node_banner_names_the_camera_info_and_a_bad_range_is_refused(walk):  # noqa: F811
    base = ["ros2", "node", "--map", str(walk / "global_reconstruction.json"), "--domain",
            str(random.randrange(100, 200)), "--camera-info", "/camera_info"]  # fmt: skip
    node = semloc(*base, "--range", "6")
    lines: list[str] = []
    try:  # the banner, however the console wraps it: up to its arrow's line
        while len(lines) < 5 and " -> " not in " ".join(" ".join(lines).split()) + " ":
            lines.append(node.stdout.readline())
    finally:
        node.send_signal(signal.SIGINT)
        node.communicate(timeout=30)
    banner = " ".join(" ".join(lines).split())
    assert ": /detections + /odom + /camera_info (coverage to 6 m) + /tf_static -> " in banner
    run = semloc(*base, "--range", "0")
    _, err = run.communicate(timeout=60)
    assert run.returncode == 2 and "Invalid value for '--range'" in err and "Traceback" not in err
