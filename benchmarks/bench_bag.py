"""A simulated run as a ROS 2 bag, localized by `semloc bag localize` (issue 47's target).

    PYTHONPATH=src python benchmarks/bench_bag.py [--minutes 2] [--seed 0] [--size small]
        [--resolution 160x120] [--out FOLDER]

Simulates a walk of `--minutes` at 10 keyframes per second (`semloc simulate OUT --bag
--keyframes N`), then runs `semloc bag localize` on walk.mcap against the reconstruction map
twice, pinned to one core: with the detections' points (`--points`) and from boxes alone.
Prints, for each, the CPU time against the run's duration (faster than real time when the
ratio is below 1), the statuses of the answers, the error of the last pose against the ground
truth, and whether every answer equals the in-process Localizer on the same detections
(the simulated sequence's own keyframe objects, one `Localizer.update` per keyframe that
changed them).  Needs the `sim`, `viz` and `ros` extras.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

import semloc
from semloc.sim.noise import DetectionNoise
from semloc.sim.scenario import simulate_sequence
from semloc.transforms import pose_error

HZ = 10


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--minutes", type=float, default=2.0)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--size", default="small")
    parser.add_argument("--resolution", default="160x120")
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    keyframes = int(round(args.minutes * 60 * HZ))
    out = args.out or Path(tempfile.mkdtemp(prefix="bench_bag."))
    semloc_cmd = [sys.executable, "-m", "semloc"]
    if not (out / "walk.mcap").exists():
        subprocess.run([*semloc_cmd, "simulate", str(out), "--bag", "--no-snapshots", "--seed",
                        str(args.seed), "--size", args.size, "--keyframes", str(keyframes),
                        "--resolution", args.resolution], check=True)  # fmt: skip
    truth = np.asarray(json.loads((out / "ground_truth.json").read_text())["T_global_local"])
    expected = _in_process(args, keyframes, out)
    print(f"run: {keyframes} keyframes = {keyframes / HZ:.0f} s at {HZ} Hz ({out})")
    for name, extra in (("points", ["--points", "/detections/points"]), ("boxes", [])):
        cpu = _localize(semloc_cmd, out, name, extra)
        lines = [json.loads(line) for line in (out / f"{name}.jsonl").read_text().splitlines()]
        statuses = [line["result"]["status"] for line in lines]
        last = lines[-1]["result"]
        error = "no pose"
        if last["pose"] is not None:
            rotation, translation = pose_error(np.asarray(last["pose"]), truth)
            error = f"{rotation:.2f}° {translation:.3f} m"
        same = (
            "n/a (the in-process run fuses points)" if name == "boxes" else _same(lines, expected)
        )
        print(f"{name:>6}: {cpu:.1f} s CPU for {keyframes / HZ:.0f} s of data "
              f"(x{cpu / (keyframes / HZ):.2f} real time), {len(lines)} answers, "
              f"localized {statuses.count('localized')} / ambiguous "
              f"{statuses.count('ambiguous')} / failed {statuses.count('failed')}; last "
              f"{last['status']}, error {error}; equal to in-process: {same}")  # fmt: skip


def _localize(semloc_cmd: list[str], out: Path, name: str, extra: list[str]) -> float:
    """CPU seconds of one `semloc bag localize` run, pinned to one core (a warm-up run first,
    so the compiled code is loaded from the cache, as on a robot that ran it once)."""
    argv = [*semloc_cmd, "bag", "localize", str(out / "walk.mcap"), "--map",
            str(out / "global_reconstruction.json"), "--detections", "/detections", "--odom",
            "/odom", "-o", str(out / f"{name}.mcap"), "--jsonl", str(out / f"{name}.jsonl"),
            *extra]  # fmt: skip
    pin = ["taskset", "-c", "0"] if _has_taskset() else []
    subprocess.run(pin + argv, check=True, capture_output=True)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run(pin + argv, check=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def _has_taskset() -> bool:
    return any(os.access(Path(p) / "taskset", os.X_OK) for p in os.environ["PATH"].split(":"))


def _in_process(args: argparse.Namespace, keyframes: int, out: Path) -> list:
    width, height = (int(v) for v in args.resolution.split("x"))
    seq = simulate_sequence(args.seed, args.size, "all", "walk", n_keyframes=keyframes,
                            resolution=(width, height), noise=DetectionNoise())  # fmt: skip
    loc = semloc.Localizer(semloc.load_map(out / "global_reconstruction.json"), local_up=[0, 0, 1])
    return [loc.update(kf.objects) for kf in seq.keyframes if kf.objects]


def _same(lines: list[dict], expected: list) -> bool:
    if len(lines) != len(expected):
        return False
    for line, result in zip(lines, expected, strict=True):
        got = line["result"]
        if got["status"] != result.status or (got["pose"] is None) != (result.pose is None):
            return False
        if result.pose is not None and not np.allclose(got["pose"], result.pose, atol=1e-6):
            return False
    return True


if __name__ == "__main__":
    main()
