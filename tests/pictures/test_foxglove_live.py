"""The live Foxglove view: a WebSocket server that advertises semloc's channels in Foxglove's
schemas and takes every kind of answer."""

from __future__ import annotations

import base64
import json
import os
import signal
import socket
import subprocess
import sys

import pytest

pytest.importorskip("foxglove", reason="foxglove-sdk (the viz extra) is not installed")

import semloc  # noqa: E402
from semloc.pictures.live import FoxgloveView  # noqa: E402
from semloc.sim.layouts import layout  # noqa: E402
from semloc.sim.longwalk import LongWalk, WalkConfig  # noqa: E402


def frames(sock: socket.socket, count: int) -> list[dict]:
    """The first `count` text frames of a WebSocket (server frames are not masked)."""
    found, buffer = [], b""
    while len(found) < count:
        while True:
            if len(buffer) >= 2:
                length, start = buffer[1] & 0x7F, 2
                if length == 126 and len(buffer) >= 4:
                    length, start = int.from_bytes(buffer[2:4], "big"), 4
                elif length == 127 and len(buffer) >= 10:
                    length, start = int.from_bytes(buffer[2:10], "big"), 10
                if (length < 126 or start > 2) and len(buffer) >= start + length:
                    break
            buffer += sock.recv(65536)
        opcode, payload = buffer[0] & 0x0F, buffer[start : start + length]
        buffer = buffer[start + length :]
        if opcode == 1:
            found.append(json.loads(payload))
    return found


def connected(port: int) -> tuple[socket.socket, bytes]:
    """A WebSocket opened with Foxglove's subprotocol, and the server's handshake answer."""
    sock = socket.create_connection(("127.0.0.1", port), timeout=10)
    key = base64.b64encode(os.urandom(16)).decode()
    sock.sendall(
        f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade"
        f"\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n"
        "Sec-WebSocket-Protocol: foxglove.sdk.v1\r\n\r\n".encode()
    )
    head = b""
    while b"\r\n\r\n" not in head:
        head += sock.recv(1)
    return sock, head


def test_the_view_advertises_its_channels_and_takes_answers():
    building = layout(60, seed=2)
    view = FoxgloveView(building, port=0)
    try:
        sock, head = connected(view.port)
        assert head.startswith(b"HTTP/1.1 101")
        info, advertise = frames(sock, 2)
        assert info["op"] == "serverInfo" and advertise["op"] == "advertise"
        schemas = {c["topic"]: c["schemaName"] for c in advertise["channels"]}
        assert schemas == {
            "/semloc/map": "foxglove.SceneUpdate", "/semloc/local": "foxglove.SceneUpdate",
            "/semloc/hypotheses": "foxglove.SceneUpdate", "/semloc/pose": "foxglove.PoseInFrame",
            "/tf": "foxglove.FrameTransform", "/semloc/status": "foxglove.Log",
        }  # fmt: skip
        localizer = semloc.Localizer(building, local_up=[0, 0, 1])
        statuses = set()
        walk = LongWalk(building, WalkConfig(keyframes=25, points_per_object=0), seed=2)
        for k, frame in enumerate(walk):
            result = localizer.update(frame.objects, position=frame.T_odom_robot)
            view.update(k, result, localizer.local_map, frame.T_odom_robot)
            statuses.add(result.status)
        assert "localized" in statuses
        view.publish_map()
        sock.close()
    finally:
        view.close()


def test_the_demo_streams_to_foxglove_and_stays_up_until_ctrl_c(tmp_path):
    pytest.importorskip("open3d", reason="the sim extra is not installed")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path), "COLUMNS": "200"}
    demo = subprocess.Popen(
        [sys.executable, "-m", "semloc", "demo", "--size", "tiny", "--keyframes", "8",
         "--resolution", "120x90", "--out", str(tmp_path / "out"), "--foxglove", "0"],
        env=env, text=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
    )  # fmt: skip
    try:
        port = None
        for line in demo.stdout:
            if "stays up at ws://localhost:" in line:
                port = int(line.split("ws://localhost:")[1].split(":")[0].split()[0])
                break
        assert port is not None, demo.stderr.read()
        sock, head = connected(port)
        sock.close()
        assert head.startswith(b"HTTP/1.1 101")
        assert (tmp_path / "out" / "result.json").is_file()
    finally:
        demo.send_signal(signal.SIGINT)
        _, err = demo.communicate(timeout=30)
    assert demo.returncode == 130, err
    assert "semloc: interrupted" in err.splitlines() and "Traceback" not in err
