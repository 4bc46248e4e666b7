"""A robot's day: one Localizer fed for a long walk with drifting odometry and a kidnap.

    PYTHONPATH=src python benchmarks/long_run.py [--keyframes 1000] [--worlds rooms real large]
        [--kidnap-at 600] [--seed 0] [--unbounded-budget 120] [--plot long_run.png]

Worlds: `rooms`, a generated building of 600 objects (`semloc.sim.layouts.layout`:
classrooms, meeting rooms, offices, kitchens, living rooms; points on the box faces), and
`real`, the ScanNet scene0000_00 objects (their mesh points) tiled 4 x 4 into a building, each
copy keeping a random 70 % of its objects (`semloc.sim.longwalk.tiled`; skipped with a note
when `../shared/data/real` is absent); `large`, a generated building of 5,000 objects (past
the place-retrieval threshold, `semloc.places`).  The walk (`semloc.sim.longwalk.LongWalk`): 0.5 m per
keyframe towards random objects in turn, up to 10 objects in a 120° view of 4 m, new ones plus
two re-detections per keyframe, points on the faces the robot sees; odometry drift 1 %/m
(random walk), 0.2°/√m of yaw random walk and a 0.05°/m yaw bias; a kidnap at `--kidnap-at`
carries the robot at least 12 m away without the odometry noticing.

Robots compared on the same keyframes:
* `semloc`: `Localizer(map)` with its defaults (bounded window, tracking), one update per
  keyframe with the robot's odometry position;
* `odometry only`: trusts semloc's first right `localized` answer, then only its odometry
  (the pose it holds is never corrected);
* `unbounded`: the Localizer of the paper's method, one local map for the whole run
  (`window=WindowConfig.unbounded()`, no tracking), run until `--unbounded-budget` seconds of
  updates are spent (its update time grows with the run).

Per keyframe the pose error is taken *at the robot*: the robot's odometry position mapped by
the answer's pose against its true position, and the rotation error.  Right: < 0.5 m and
< 15°.  Printed per world and robot: share of keyframes with a right pose after the first
right answer; share `localized`; wrong `localized` claims before / after the kidnap;
keyframes from the kidnap to a right `localized` answer; median update ms of the first and
last 100 keyframes; resident memory growth (MB) from keyframe 10 to the run's peak.
`--plot` writes the error and status along the run.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from semloc import Localizer, LocalizerConfig, ObjectMap
from semloc.eval.datasets import real_data_dir
from semloc.sim.layouts import layout
from semloc.sim.longwalk import LongWalk, WalkConfig, WalkKeyframe, tiled
from semloc.window import WindowConfig

RIGHT_M, RIGHT_DEG = 0.5, 15.0


@dataclass
class Trace:
    """What a robot answered along the run."""

    name: str
    status: list[str] = field(default_factory=list)
    error_m: list[float] = field(default_factory=list)
    error_deg: list[float] = field(default_factory=list)
    ms: list[float] = field(default_factory=list)
    rss_mb: list[float] = field(default_factory=list)
    poses: list = field(default_factory=list, repr=False)

    def right(self) -> np.ndarray:
        return (np.array(self.error_m) < RIGHT_M) & (np.array(self.error_deg) < RIGHT_DEG)


def rss_mb() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * 4096 / 2**20


def errors(pose: np.ndarray | None, frame: WalkKeyframe) -> tuple[float, float]:
    """Pose error at the robot: position (m) and rotation (degrees)."""
    if pose is None:
        return np.inf, np.inf
    at = pose[:3, :3] @ frame.T_odom_robot[:3, 3] + pose[:3, 3]
    R = pose[:3, :3] @ frame.T_global_local[:3, :3].T
    angle = np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1)))
    return float(np.linalg.norm(at - frame.robot_global)), float(angle)


def run(name: str, global_map: ObjectMap, frames: list[WalkKeyframe], config, budget=None):
    """Feed a Localizer keyframe by keyframe; its trace (stops when `budget` s are spent)."""
    localizer = Localizer(global_map, config, local_up=[0, 0, 1]).prepare()
    trace, spent = Trace(name), 0.0
    for frame in frames:
        start = time.perf_counter()
        result = localizer.update(frame.objects, position=frame.T_odom_robot)
        seconds = time.perf_counter() - start
        spent += seconds
        trace.ms.append(seconds * 1e3)
        trace.status.append(result.status)
        trace.poses.append(result.pose)
        m, deg = errors(result.pose, frame)
        trace.error_m.append(m)
        trace.error_deg.append(deg)
        trace.rss_mb.append(rss_mb())
        if budget is not None and spent > budget:
            break
    return trace


def odometry_only(semloc: Trace, frames: list[WalkKeyframe]) -> Trace:
    """The first right localized pose of semloc, then odometry alone."""
    trace = Trace("odometry only")
    held = None
    for k, frame in enumerate(frames):
        if held is None and semloc.status[k] == "localized" and semloc.right()[k]:
            held = semloc.poses[k]
        trace.status.append("localized" if held is not None else "failed")
        m, deg = errors(held, frame)
        trace.error_m.append(m)
        trace.error_deg.append(deg)
    return trace


def summary(trace: Trace, kidnap: int | None) -> dict:
    right, n = trace.right(), len(trace.status)
    localized = np.array(trace.status) == "localized"
    first = int(np.argmax(right)) if right.any() else n
    wrong = localized & ~right
    before = wrong[: kidnap if kidnap is not None else n]
    after = wrong[kidnap:] if kidnap is not None else np.zeros(0, bool)
    back = None
    if kidnap is not None and kidnap < n:
        hits = np.flatnonzero(localized[kidnap:] & right[kidnap:])
        back = int(hits[0]) if len(hits) else None
    ms = np.array(trace.ms)
    return {
        "keyframes": n,
        "right_after_first": float(right[first:].mean()) if first < n else 0.0,
        "localized": float(localized.mean()),
        "wrong_before": int(before.sum()),
        "wrong_after": int(after.sum()),
        "back_after": back,
        "ms_first": float(np.median(ms[:100])) if len(ms) else None,
        "ms_last": float(np.median(ms[-100:])) if len(ms) else None,
        "rss_growth": float(max(trace.rss_mb) - trace.rss_mb[min(10, n - 1)])
        if trace.rss_mb
        else None,
    }


def worlds(names: list[str], seed: int) -> dict[str, ObjectMap]:
    found: dict[str, ObjectMap] = {}
    if "rooms" in names:
        found["rooms (600 objects)"] = layout(600, seed=seed, points_per_object=320)
    if "large" in names:  # past the place-retrieval threshold (3,000 objects)
        found["rooms (5,000 objects)"] = layout(5000, seed=seed, points_per_object=320)
    if "real" in names:
        data = real_data_dir()
        if data is None:
            print("real: skipped (no ../shared/data/real; set SEMLOC_DATA)", file=sys.stderr)
        else:
            from semloc.io.importers.scannet import load_scannet

            room = load_scannet(data / "scannet" / "scene0000_00")
            building = tiled(room, 4, 4, keep=0.7, seed=seed)
            found[f"real: ScanNet 4x4 ({len(building)} objects)"] = building
    return found


def table(rows: list[tuple[str, str, dict]], kidnap: int | None) -> str:
    def f(x, fmt="{:.3f}"):
        return "n/a" if x is None else fmt.format(x)

    head = (
        "| world | robot | keyframes | right pose after first right | localized | "
        "wrong claims before / after kidnap | keyframes kidnap → right localized | "
        "ms first 100 / last 100 | memory growth MB |\n|" + "---|" * 9
    )
    lines = [head]
    for world, robot, s in rows:
        lines.append(
            f"| {world} | {robot} | {s['keyframes']} | {s['right_after_first']:.3f} | "
            f"{s['localized']:.3f} | {s['wrong_before']} / {s['wrong_after']} | "
            f"{f(s['back_after'], '{}')} | {f(s['ms_first'], '{:.1f}')} / "
            f"{f(s['ms_last'], '{:.1f}')} | {f(s['rss_growth'], '{:.0f}')} |"
        )
    return "\n".join(lines)


def plot(path: Path, traces: dict[str, list[Trace]], kidnap: int | None) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(traces), 1, figsize=(11, 3.2 * len(traces)), squeeze=False)
    colours = {"localized": "tab:green", "ambiguous": "tab:orange", "failed": "tab:red"}
    for ax, (world, runs) in zip(axes[:, 0], traces.items()):
        for trace, colour in zip(runs, ("tab:blue", "tab:orange", "tab:grey")):
            ax.plot(np.minimum(trace.error_m, 20), label=trace.name, lw=1, color=colour)
        semloc = runs[0]
        for k, status in enumerate(semloc.status):
            ax.axvspan(k - 0.5, k + 0.5, ymin=0.96, ymax=1.0, color=colours[status], lw=0)
        if kidnap is not None:
            ax.axvline(kidnap, color="k", ls="--", lw=0.8)
        ax.set_yscale("symlog", linthresh=0.5)
        ax.set_ylim(0, 25)
        ax.axhline(RIGHT_M, color="grey", lw=0.5)
        ax.set_title(f"{world}: error at the robot (m); semloc's status along the top")
        ax.set_xlabel("keyframe")
        ax.legend(loc="upper left")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--keyframes", type=int, default=1000)
    parser.add_argument("--worlds", nargs="+", default=["rooms", "real"],
                        choices=["rooms", "real", "large"])  # fmt: skip
    parser.add_argument("--kidnap-at", type=int, default=None, help="default: 60 %% of the run")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--unbounded-budget", type=float, default=120.0)
    parser.add_argument("--plot", type=Path, default=None)
    args = parser.parse_args(argv)
    kidnap = args.kidnap_at if args.kidnap_at is not None else int(0.6 * args.keyframes)
    rows, traces = [], {}
    for world, global_map in worlds(args.worlds, args.seed).items():
        walk = LongWalk(global_map, WalkConfig(keyframes=args.keyframes, kidnap_at=kidnap),
                        seed=args.seed)  # fmt: skip
        frames = list(walk)
        metres = args.keyframes * walk.config.step
        print(f"{world}: {len(frames)} keyframes, {metres:.0f} m", file=sys.stderr)
        localizer_trace = run("semloc", global_map, frames, LocalizerConfig())
        odometry = odometry_only(localizer_trace, frames)
        unbounded = run(
            "unbounded",
            global_map,
            frames,
            LocalizerConfig(window=WindowConfig.unbounded(), track=False),
            budget=args.unbounded_budget,
        )
        for trace in (localizer_trace, odometry, unbounded):
            rows.append((world, trace.name, summary(trace, kidnap)))
        traces[world] = [localizer_trace, odometry, unbounded]
        print(table(rows[-3:], kidnap), file=sys.stderr)
    print(table(rows, kidnap))
    if args.plot is not None:
        plot(args.plot, traces, kidnap)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
