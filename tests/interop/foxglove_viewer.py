"""Foxglove's own client library (`@foxglove/ws-protocol`, `node/client.js`) as a viewer of
semloc's live view, and the walk whose answers the interop tests and the picture use."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np

import semloc
from semloc.maps import ObjectMap
from semloc.sim.layouts import layout
from semloc.sim.longwalk import LongWalk, WalkConfig

NODE_DIR = Path(__file__).parent / "node"
LIBRARY = NODE_DIR / "node_modules" / "@foxglove" / "ws-protocol"
WAIT = 60.0
"""Bound (s) of a client's run (the client gives up after 20 s without its messages)."""

Answer = tuple[int, semloc.Result, ObjectMap, np.ndarray]


def walk_answers() -> tuple[ObjectMap, list[Answer]]:
    """A simulated walk's answers (stamp, result, local map, sensor pose in odom): failed,
    ambiguous ones with next-look suggestions, then localized ones."""
    building = layout(60, seed=2)
    localizer = semloc.Localizer(building, local_up=[0, 0, 1])
    answers = []
    walk = LongWalk(building, WalkConfig(keyframes=25, points_per_object=0), seed=2)
    for k, frame in enumerate(walk):
        result = localizer.update(frame.objects, position=frame.T_odom_robot)
        answers.append((k, result, localizer.local_map, frame.T_odom_robot))
    return building, answers


def viewer(port: int, subprotocol: str, topics: list[str]) -> tuple[str, dict, dict]:
    """Foxglove's client joins: the subprotocol it got, the channels by topic, and the decoded
    messages by topic (the first of each; it leaves once every one of `topics` had one)."""
    out = subprocess.run(
        ["node", str(NODE_DIR / "client.js"), f"ws://127.0.0.1:{port}", subprotocol, *topics],
        capture_output=True, text=True, timeout=WAIT, check=False,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr
    lines = [json.loads(line) for line in out.stdout.splitlines()]
    opened = next(line["open"] for line in lines if "open" in line)
    channels = {c["topic"]: c for line in lines if "channels" in line for c in line["channels"]}
    decoded: dict[str, dict] = {}
    for line in lines:
        if "topic" in line:
            decoded.setdefault(line["topic"], line)
    return opened, channels, decoded
