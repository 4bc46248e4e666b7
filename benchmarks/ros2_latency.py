"""Latency of the live ROS 2 node: from a detection message on the wire to the node's answer.

    PYTHONPATH=src python benchmarks/ros2_latency.py [--keyframes 200] [--size small] [--seed 0]

A simulated walk (`semloc simulate --bag`: detections and odometry at 10 Hz) is played at its
recorded pace onto the DDS wire (loopback only: `CYCLONEDDS_URI` is set to the loopback
configuration unless the environment sets one) into a `semloc ros2 node` process; this
process plays the bag and listens to `/semloc/status`.  Latency: from the moment the player
wrote a detection message to the moment the listener took the status of that stamp.
Printed: answers, answers lost, latency median / p95 / max, and the answers compared with
`semloc bag localize --jsonl` on the same bag (status and confidence).
"""

from __future__ import annotations

import argparse
import json
import os
import random
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from semloc.cli import main as semloc_main
from semloc.ros import messages as msgs
from semloc.ros2.node import Wire, samples
from semloc.ros2.play import play
from semloc.ros2.wire import choose_network

choose_network("loopback")  # DDS on this machine (before any participant), unless
# CYCLONEDDS_URI says otherwise


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--keyframes", type=int, default=200)
    parser.add_argument("--size", default="small")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder)
        simulate = ["simulate", str(out), "--bag", "--no-snapshots", "--seed", str(args.seed),
                    "--size", args.size, "--keyframes", str(args.keyframes)]  # fmt: skip
        assert semloc_main(simulate) == 0
        localize = ["bag", "localize", str(out / "walk.mcap"), "--map",
                    str(out / "global_reconstruction.json"), "--detections", "/detections",
                    "--odom", "/odom", "-o", str(out / "out.mcap"), "--jsonl", str(out / "out.jsonl")]  # fmt: skip
        assert semloc_main(localize) == 0
        expected = [json.loads(line) for line in (out / "out.jsonl").read_text().splitlines()]
        measure(out / "global_reconstruction.json", out / "walk.mcap", expected)
    return 0


def measure(map_file: Path, bag: Path, expected: list[dict]) -> None:
    domain = random.randrange(100, 200)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    node = subprocess.Popen(
        [sys.executable, "-m", "semloc", "ros2", "node", "--map", str(map_file), "--domain",
         str(domain), "--reliable"], env=env, text=True, stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
    )  # fmt: skip
    listener = Wire(domain).reader("/semloc/status", msgs.STRING, reliable=True)
    sent: dict[int, float] = {}
    heard: dict[int, tuple[float, dict]] = {}
    done = threading.Event()

    def published(topic: str, log_time: int) -> None:
        if topic == "/detections":
            sent[log_time] = time.perf_counter()

    def listen() -> None:
        while not done.is_set():
            for message in samples(listener):
                status = json.loads(message.data)
                heard.setdefault(int(round(status["stamp"] * 1e9)), (time.perf_counter(), status))
            time.sleep(0.0002)

    thread = threading.Thread(target=listen)
    try:
        assert "semloc node on domain" in node.stdout.readline()
        threading.Thread(target=node.stdout.read, daemon=True).start()  # drain
        thread.start()
        time.sleep(1.0)  # discovery
        play(bag, Wire(domain), rate=1.0, published=published)
        deadline = time.monotonic() + 10
        while len(heard) < len(expected) and time.monotonic() < deadline:
            time.sleep(0.05)
    finally:
        done.set()
        thread.join(10)
        node.send_signal(signal.SIGINT)
        node.wait(30)
    latency = np.array([(heard[s][0] - sent[s]) * 1e3 for s in sent if s in heard])
    got = [heard[s][1] for s in sorted(heard)]
    same = sum(g["status"] == e["result"]["status"] and g["confidence"] == e["result"]["confidence"]
               for g, e in zip(got, expected))  # fmt: skip
    print("| detection messages | answers (bag localize) | lost | latency ms median / p95 / max "
          "| answers equal to bag localize |\n|---:|---:|---:|---|---:|\n"
          f"| {len(sent)} | {len(heard)} ({len(expected)}) | {len(expected) - len(heard)} | "
          f"{np.median(latency):.1f} / {np.percentile(latency, 95):.1f} / {latency.max():.1f} | "
          f"{same} of {len(expected)} |")  # fmt: skip


if __name__ == "__main__":
    raise SystemExit(main())
