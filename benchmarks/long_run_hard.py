"""A robot's day outside the clean room: an old map, a detector that errs, look-alike rooms.

    PYTHONPATH=src python benchmarks/long_run_hard.py [--keyframes 1000] [--seeds 10]
        [--worlds rooms real] [--conditions all] [--jobs 2]

The walk of `benchmarks/long_run.py` (`semloc.sim.longwalk.LongWalk`), with today's world
differing from the map and the detector erring (`semloc.sim.longwalk.World`), and two
kidnaps per run: one anywhere at 35 % of the run, one into the look-alike of where the robot
stands at 65 % (the same spot in another copy of the room).  Each condition runs with and
without the sensor's coverage passed (`Localizer.update(..., coverage=...)`; with it, each
keyframe sends every object in view, as a look's update must).

Conditions (`--conditions`, default all):

    clean        today's long run (no change, 2 % mislabels, the default drift)
    moved10/20/30  10 / 20 / 30 % of the map's objects stand 1-3 m from where the map has them,
                 10 % are gone
    mislabels    10 % of detections carry another label of the map's vocabulary
    phantoms     an object the map does not hold at 30 % of keyframes
    segments     10 % of detections split in two, 10 % of near same-label pairs merged
    drift        strong yaw drift (0.3 deg/m bias, 0.4 deg/sqrt(m) walk)
    hard         all together: 20 % moved, 10 % gone, 10 % mislabels, phantoms at 30 % of
                 keyframes, 5 % split / merged, strong drift

Worlds: `copies`, a generated floor of 300 objects tiled 3 x 1, each copy keeping a random 70 %
of its objects (about 630 objects; look-alike rooms that differ); `real`, ScanNet
scene0000_00 tiled 3 x 1 the same way (skipped without `../shared/data/real`); `rooms`, the
generated building of 600 objects of `long_run.py` (its rooms of a kind are exact copies:
a kidnap into one cannot be told by any evidence).

Printed per world, condition and coverage (seeds pooled): keyframes; share right after the
first right answer; share `localized`; wrong `localized` claims (all seeds; per seed the
largest) and of them those the view could have told (`Told`: after a kidnap, only once an
object seen since stands where the claimed place has none of its kind); keyframes from the look-alike kidnap to the end of the claim (median, max: 0 = not
claimed at the kidnap's keyframe) and to a right `localized` answer (median); moved objects
found over the run (precision / recall, below); share of updates whose
answer used negative evidence (`support.n_missing` given); update ms, first / last 100
(median over seeds); memory growth (MB, largest).  Right: the pose at the robot within 0.5 m
and 15 deg.

Moved objects, as a user reads them: reported, every map object the run's change report
(`Result.changes` of the tracked answers, `semloc.changes.RunChanges`) named moved at any
update of the run, over all its claims (a report read once, then withdrawn, still counts);
precision, the share of them that stand elsewhere today.  Recall counts only what the robot
could report: the moved objects detected (under any label) at `REPORTABLE` or more keyframes
whose answer was `localized`, right, and from a tracked claim (the report learns only from
tracking, and a change needs that many detections: one could be a mislabel or a phantom);
recall, the share of them reported.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))

from long_run import errors, rss_mb  # noqa: E402

from semloc import Localizer, LocalizerConfig, ObjectMap  # noqa: E402
from semloc.eval.datasets import real_data_dir  # noqa: E402
from semloc.sim.layouts import layout  # noqa: E402
from semloc.sim.longwalk import Drift, LongWalk, WalkConfig, World, tiled  # noqa: E402
from semloc.tracking import TrackingConfig, allowances  # noqa: E402

REPORTABLE = 2
"""A moved object counts in the recall once detected under a right tracked claim at this many
keyframes (the change report's `min_evidence`)."""
STRONG = Drift(translation=0.01, yaw_walk=0.4, yaw_bias=0.3)
CONDITIONS: dict[str, dict] = {
    "clean": {},
    "moved10": {"world": World(moved=0.1, gone=0.1)},
    "moved20": {"world": World(moved=0.2, gone=0.1)},
    "moved30": {"world": World(moved=0.3, gone=0.1)},
    "mislabels": {"wrong_label_rate": 0.1},
    "phantoms": {"world": World(phantoms=0.3)},
    "segments": {"world": World(split=0.1, merged=0.1)},
    "drift": {"drift": STRONG},
    "hard": {
        "world": World(moved=0.2, gone=0.1, phantoms=0.3, split=0.05, merged=0.05),
        "wrong_label_rate": 0.1,
        "drift": STRONG,
    },
}


def world_map(name: str, seed: int) -> ObjectMap | None:
    if name == "rooms":
        return layout(600, seed=seed, points_per_object=320)
    if name == "copies":
        return tiled(layout(300, seed=seed, points_per_object=320), 3, 1, keep=0.7, seed=seed)
    data = real_data_dir()
    if data is None:
        return None
    from semloc.io.importers.scannet import load_scannet

    return tiled(load_scannet(data / "scannet" / "scene0000_00"), 3, 1, keep=0.7, seed=seed)


def one_run(task: tuple[str, str, bool, int, int]) -> dict:
    """One seed of one world, condition and coverage setting: its summary."""
    world, condition, coverage, seed, keyframes = task
    global_map = world_map(world, seed)
    assert global_map is not None
    config = WalkConfig(keyframes=keyframes, kidnap_at=int(0.35 * keyframes),
                        lookalike_at=int(0.65 * keyframes), **CONDITIONS[condition])  # fmt: skip
    if coverage:  # a look's update holds every detection in it (`semloc.coverage`)
        config = replace(config, redetections=config.max_visible)
    walk = LongWalk(global_map, config, seed=seed)
    localizer = Localizer(global_map, LocalizerConfig(), local_up=[0, 0, 1]).prepare()
    right, status, ms, rss, negative = [], [], [], [], 0
    moved = Moved(walk)
    told = Told(walk.map)
    import time

    for frame in walk:
        tracked = localizer.tracking
        start = time.perf_counter()
        kwargs = {"coverage": frame.coverage} if coverage else {}
        result = localizer.update(frame.objects, position=frame.T_odom_robot, **kwargs)
        ms.append((time.perf_counter() - start) * 1e3)
        m, deg = errors(result.pose, frame)
        right.append(m < 0.5 and deg < 15.0)
        status.append(result.status)
        told.add(frame, result.pose if result.status == "localized" and not right[-1] else None)
        rss.append(rss_mb())
        support = getattr(result, "support", None)
        negative += getattr(support, "n_missing", None) is not None
        moved.add(frame, result, tracked and right[-1])
    found = summary(config, np.array(right), np.array(status), ms, rss, negative, moved)
    return {**found, "wrong_told": told.wrong}


class Told:
    """Wrong claims the view could have told: at a keyframe when, since the latest kidnap,
    an object was detected where the claimed place holds no map object of its kind (its true
    label, within `tracking.allowances` of where the claimed pose puts it).  Before that,
    nothing seen since the robot was carried off differs from the place it left: the same spot
    of an identical room, or views of objects both places hold, cannot be told by any tracker
    (the one failure an honest evidence rule must make)."""

    def __init__(self, global_map: ObjectMap) -> None:
        self.map = global_map
        self.allowance = allowances(global_map, TrackingConfig().track_tolerance)
        self.since: list[tuple[np.ndarray, int]] = []  # since the kidnap: (local xyz, map index)
        self.wrong = 0

    def add(self, frame, wrong_pose: np.ndarray | None) -> None:
        if frame.kidnapped:
            self.since = []
        self.since += [(o.position, g) for o in frame.objects
                       if (g := frame.truth.get(o.id)) is not None]  # fmt: skip
        if wrong_pose is not None and any(self._tells(wrong_pose, *seen) for seen in self.since):
            self.wrong += 1

    def _tells(self, pose: np.ndarray, xyz: np.ndarray, g: int) -> bool:
        at = pose[:3, :3] @ xyz + pose[:3, 3]
        kind = np.flatnonzero(self.map.labels == self.map.labels[g])
        gaps = np.linalg.norm(self.map.positions[kind] - at, axis=1)
        return not bool((gaps <= self.allowance[kind]).any())


class Moved:
    """The moved objects a run reported and those it could have (see the module docstring)."""

    def __init__(self, walk: LongWalk) -> None:
        self.index = {str(g): i for i, g in enumerate(walk.map.ids)}
        self.truth = set(np.flatnonzero(np.any(walk.offsets != 0, axis=1)).tolist())
        self.detected: Counter[int] = Counter()  # moved map index -> keyframes seen rightly
        self.reported: set[int] = set()

    def add(self, frame, result, right_tracked: bool) -> None:
        if result.status != "localized":
            return
        if right_tracked:
            self.detected.update({g for g in frame.truth.values() if g in self.truth})
        changes = result.changes
        if changes is not None and changes.evidence is not None:  # the run's report
            self.reported |= {self.index[m.global_id] for m in changes.moved}

    def counts(self) -> dict[str, int]:
        reportable = {g for g, n in self.detected.items() if n >= REPORTABLE}
        return {"moved_found": len(self.reported),
                "moved_right": len(self.reported & self.truth),
                "moved_truth": len(reportable),
                "moved_recalled": len(self.reported & reportable)}  # fmt: skip


def summary(config, right, status, ms, rss, negative, moved: Moved) -> dict:
    n = len(status)
    localized = status == "localized"
    wrong = localized & ~right
    first = int(np.argmax(right)) if right.any() else n
    at = config.lookalike_at
    claimed = np.flatnonzero(~wrong[at:]) if at is not None and at < n else np.zeros(0, int)
    ended = int(claimed[0]) if len(claimed) else None
    back = np.flatnonzero(localized[at:] & right[at:]) if at is not None else np.zeros(0, int)
    return {
        "keyframes": n,
        "right": float(right[first:].mean()) if first < n else 0.0,
        "localized": float(localized.mean()),
        "wrong": int(wrong.sum()),
        "lookalike_end": ended,
        "lookalike_back": int(back[0]) if len(back) else None,
        **moved.counts(),
        "negative": negative / max(n, 1),
        "ms_first": float(np.median(ms[:100])),
        "ms_last": float(np.median(ms[-100:])),
        "rss": float(max(rss) - rss[min(10, n - 1)]),
    }


def table(rows: list[tuple[str, str, bool, list[dict]]]) -> str:
    head = (
        "| world | condition | coverage | seeds x keyframes | right after first right | "
        "localized | wrong claims (largest per seed) | of them after the view told | look-alike kidnap → claim ended "
        "(median / max) | → right localized (median) | moved precision / recall (of those "
        "detected twice under a right tracked claim) | "
        "updates with negative evidence | ms first / last 100 | memory MB |\n|" + "---|" * 14
    )
    lines = [head]
    for world, condition, coverage, runs in rows:
        ends = [r["lookalike_end"] for r in runs if r["lookalike_end"] is not None]
        backs = [r["lookalike_back"] for r in runs if r["lookalike_back"] is not None]
        found = sum(r["moved_found"] for r in runs)
        hit = sum(r["moved_right"] for r in runs)
        truth = sum(r["moved_truth"] for r in runs)
        recalled = sum(r["moved_recalled"] for r in runs)
        precision = f"{hit / found:.2f}" if found else "n/a"
        recall = f"{recalled / truth:.2f}" if truth else "n/a"
        lines.append(
            f"| {world} | {condition} | {'yes' if coverage else 'no'} | "
            f"{len(runs)} x {runs[0]['keyframes']} | "
            f"{np.mean([r['right'] for r in runs]):.3f} | "
            f"{np.mean([r['localized'] for r in runs]):.3f} | "
            f"{sum(r['wrong'] for r in runs)} ({max(r['wrong'] for r in runs)}) | "
            f"{sum(r['wrong_told'] for r in runs)} | "
            f"{_median(ends)} / {max(ends) if ends else 'n/a'} | {_median(backs)} | "
            f"{precision} / {recall} | {np.mean([r['negative'] for r in runs]):.2f} | "
            f"{np.median([r['ms_first'] for r in runs]):.1f} / "
            f"{np.median([r['ms_last'] for r in runs]):.1f} | "
            f"{max(r['rss'] for r in runs):.0f} |"
        )
    return "\n".join(lines)


def _median(values: list) -> str:
    return "n/a" if not values else f"{np.median(values):g}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--keyframes", type=int, default=1000)
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--first-seed", type=int, default=1)
    parser.add_argument("--worlds", nargs="+", default=["copies", "real"],
                        choices=["copies", "real", "rooms"])  # fmt: skip
    parser.add_argument("--conditions", nargs="+", default=list(CONDITIONS), choices=CONDITIONS)
    parser.add_argument("--coverage", choices=["both", "yes", "no"], default="both")
    parser.add_argument("--jobs", type=int, default=2)
    args = parser.parse_args(argv)
    worlds = [w for w in args.worlds if w != "real" or real_data_dir() is not None]
    if len(worlds) < len(args.worlds):
        print("real: skipped (no ../shared/data/real; set SEMLOC_DATA)", file=sys.stderr)
    settings = {"both": [False, True], "yes": [True], "no": [False]}[args.coverage]
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    groups = [(w, c, cov) for w in worlds for c in args.conditions for cov in settings]
    tasks = [(w, c, cov, s, args.keyframes) for w, c, cov in groups for s in seeds]
    with ProcessPoolExecutor(args.jobs) as pool:
        results = list(pool.map(one_run, tasks))
    rows = []
    for i, (w, c, cov) in enumerate(groups):
        runs = results[i * len(seeds) : (i + 1) * len(seeds)]
        rows.append((w, c, cov, runs))
        print(table(rows[-1:]).splitlines()[-1], file=sys.stderr)
    print(table(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
