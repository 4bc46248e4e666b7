"""Speed and memory of full localizations with point sets, from rooms to buildings (issue 11).

    PYTHONPATH=src python benchmarks/bench_speed.py [--quick] [--sizes 300 1000 3000 10000 20000]
        [--views 3 5 8] [--trials 5] [--markdown TABLE.md] [--against TREE [--rounds 3]]
        [--clipper CLIPPER/build/bindings/python]

Maps: the real samples (ScanNet scene0000_00 via `load_scannet`, Replica office4 via
`load_replica`; found by `semloc.io.datasets.real_data_dir()`, rows skipped with a note when
absent) and simulated buildings of about 300 / 1k / 3k / 10k / 20k objects
(`semloc.sim.layouts.layout`: classrooms, meeting rooms, offices, ... full of repeated objects;
320 box-surface points per object).  Local views: the 3 / 5 / 8 objects nearest to a viewpoint
near a random object (`crop_with_truth`: visible-side points, ~160 per object, random
heading).  A localization is `semloc.localize` (one update per object in the crop's `seen`
order, the answer at the last one); streaming feeds new copies of the same objects one per
`Localizer.update` (each update prepares its object's cloud), with an answer at every update (on the largest view size only, to keep
the run short).

Each map runs in its own process, pinned to one core (`--cpu`), and reports its peak resident
memory (ru_maxrss: interpreter, map and points included).  The process first prepares every map
object's cloud (`Localizer.prepare`: downsampled points, normals, KD-tree; timed and printed
as a one-time cost per map) and runs one untimed localization (it loads the compiled code),
so the timed localizations are those of a robot that has loaded its map.  Printed per map and view size:
median / p90 / max ms of a full localization (`localize`, Localizer construction included),
the same for one streaming update, time by stage (`Result.timing_ms` of the localization,
summed over its updates), success (rotation < 15°, translation < 0.5 m), and
a label-constrained RANSAC on centres on the same cases (2 same-label pairs per hypothesis,
4-DoF closed form about gravity, inliers: local centres within 0.5 m of a same-label global
centre; its per-map label trees built inside its timing), as the ratio semloc / RANSAC.  Last,
how time and memory grow with the buildings' size: the slope of a log-log fit.

`--clipper PATH` (a CLIPPER build's `bindings/python` folder; how to build it: see
`bench_clipper.py`) adds the real CLIPPER on the same cases: its core (consistency graph
scored and solved, the solver built before the clock starts; one thread, OMP_NUM_THREADS=1)
over semloc's candidate associations (`CandidateIndex`), as `bench_clipper.py` runs it, where a
view has at most `--clipper-max-nodes` of them (its graph is dense: `-` beyond); the tables
gain its median ms (CPU ms, as semloc's), success and the ratio semloc ÷ CLIPPER (median over
the cases); the peak MB then includes CLIPPER's graph.

`--against TREE` instead times this checkout against another one (e.g. a `git worktree` of the
commit before a change) map by map, the two in turn for `--rounds` rounds, and prints the
median of the rounds' ratios: on a shared machine two runs at once slow each other down
unevenly, and a single run of each is within the noise.  With `--clipper`, each checkout's
ratio to CLIPPER too (each measured in its own processes).

`--profile MAP` instead prints where the time of 4 x `--trials` localizations of the largest
view size goes on one map (cProfile, own CPU ms per localization by function; each compiled
kernel is one entry).

Times are CPU seconds of the benchmark process (`time.process_time`; the stage times too, by
reading the Localizer's clock as process time), so that other work on a shared machine does
not inflate them; wall-clock medians of the localizations are printed beside.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # one core, as the targets are stated

import argparse  # noqa: E402
import cProfile  # noqa: E402
import json  # noqa: E402
import pstats  # noqa: E402
import resource  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from dataclasses import asdict, dataclass, field  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from scipy.spatial import cKDTree  # noqa: E402

import semloc.localizer as localizer_module  # noqa: E402
from semloc.association import AssociationConfig, CandidateIndex  # noqa: E402
from semloc.eval.datasets import real_data_dir  # noqa: E402
from semloc.eval.success import is_success  # noqa: E402
from semloc.io.importers.replica import load_replica  # noqa: E402
from semloc.io.importers.scannet import load_scannet  # noqa: E402
from semloc.localizer import Localizer, localize  # noqa: E402
from semloc.maps import ObjectMap  # noqa: E402
from semloc.sim.crop import crop_with_truth  # noqa: E402
from semloc.sim.layouts import layout  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_clipper import (  # noqa: E402
    candidate_pairs,
    clipper_core,
    clipper_solver,
    columns,
    load_clipper,
    omp_note,
    pose_of,
)

POINTS_PER_OBJECT = 320  # about half of them face a viewpoint
FULL = {"sizes": [300, 1000, 3000, 10000, 20000], "views": [3, 5, 8], "trials": 5}
QUICK = {"sizes": [300, 3000], "views": [8], "trials": 3}
INLIER_M = 0.5
RANSAC_HYPOTHESES = 500
CLIPPER_MAX_NODES = 3000  # views with more candidate associations are left out (dense graph)


@dataclass
class Case:
    """The measurements of one localization."""

    ms: float
    wall_ms: float
    update_ms: list[float]
    stages: dict[str, float]
    success: bool
    ransac_ms: float
    ransac_success: bool
    clipper_ms: float | None = None  # CLIPPER's score + solve (None: not run)
    clipper_success: bool | None = None


@dataclass
class Row:
    """One map and view size: its cases and the process's peak memory."""

    map: str
    n_objects: int
    view: int
    cases: list[Case] = field(default_factory=list)
    peak_mb: float = 0.0
    prepare_ms: float = 0.0  # preparing every map object's cloud, once per map


# ---------------------------------------------------------------------------------------------
# Maps and views
def load_map(name: str, points: int = POINTS_PER_OBJECT) -> ObjectMap | None:
    """A map by name: 'scannet', 'replica' or 'building-N' (None: real data absent)."""
    if name.startswith("building-"):
        n = int(name.split("-")[1])
        return layout(n, seed=n, points_per_object=points)
    data = real_data_dir()
    if data is None:
        return None
    if name == "scannet":
        folder = data / "scannet" / "scene0000_00"
        return load_scannet(folder) if folder.is_dir() else None
    folder = data / "replica" / "office4"
    return load_replica(folder) if folder.is_dir() else None


def views(global_map: ObjectMap, size: int, trials: int, seed: int):
    """`trials` local views of the `size` objects nearest to a viewpoint near an object."""
    rng = np.random.default_rng(seed)
    up = np.asarray(global_map.up if global_map.up is not None else [0.0, 0.0, 1.0])
    for _ in range(trials):
        anchor = global_map.positions[rng.integers(len(global_map))]
        center = anchor + np.cross(up, rng.normal(size=3)) * 0.7  # beside the object
        distances = np.sort(np.linalg.norm(global_map.positions - center, axis=1))
        radius = float(distances[min(size, len(distances)) - 1]) + 1e-6
        yield crop_with_truth(global_map, center, radius, "random", int(rng.integers(2**31)))


# ---------------------------------------------------------------------------------------------
# The RANSAC baseline
def ransac(global_map: ObjectMap, local_map: ObjectMap, seed: int) -> np.ndarray | None:
    """Label-constrained RANSAC on centres: 4-DoF pose from 2 same-label pairs, most inliers."""
    rng = np.random.default_rng(seed)
    labels = np.char.lower(np.asarray(global_map.labels, dtype=str))
    local_labels = np.char.lower(np.asarray(local_map.labels, dtype=str))
    groups = {label: np.flatnonzero(labels == label) for label in set(local_labels)}
    groups = {label: g for label, g in groups.items() if len(g)}
    trees = {label: cKDTree(global_map.positions[g]) for label, g in groups.items()}
    usable = np.flatnonzero([label in groups for label in local_labels])
    if len(usable) < 2:
        return None
    local_xyz = local_map.positions
    i, j = _two_distinct(rng, usable, RANSAC_HYPOTHESES)
    gi = np.array([rng.choice(groups[local_labels[k]]) for k in i])
    gj = np.array([rng.choice(groups[local_labels[k]]) for k in j])
    poses = _yaw_poses(
        local_xyz[i], local_xyz[j], global_map.positions[gi], global_map.positions[gj]
    )
    aligned = local_xyz[None] @ np.swapaxes(poses[:, :3, :3], 1, 2) + poses[:, None, :3, 3]
    inliers = np.zeros(len(poses), dtype=int)
    for k in usable:
        distance, _ = trees[local_labels[k]].query(aligned[:, k])
        inliers += distance < INLIER_M
    return poses[int(np.argmax(inliers))]


def _two_distinct(rng, usable: np.ndarray, count: int) -> tuple[np.ndarray, np.ndarray]:
    first = rng.integers(len(usable), size=count)
    second = (first + rng.integers(1, len(usable), size=count)) % len(usable)
    return usable[first], usable[second]


def _yaw_poses(l1, l2, g1, g2) -> np.ndarray:
    """Gravity-aligned (z up) poses mapping local pairs (l1, l2) onto global (g1, g2)."""
    dl, dg = (l2 - l1)[:, :2], (g2 - g1)[:, :2]
    yaw = np.arctan2(dg[:, 1], dg[:, 0]) - np.arctan2(dl[:, 1], dl[:, 0])
    c, s = np.cos(yaw), np.sin(yaw)
    poses = np.tile(np.eye(4), (len(yaw), 1, 1))
    poses[:, 0, 0], poses[:, 0, 1], poses[:, 1, 0], poses[:, 1, 1] = c, -s, s, c
    mid_l, mid_g = (l1 + l2) / 2, (g1 + g2) / 2
    poses[:, :3, 3] = mid_g - np.einsum("nij,nj->ni", poses[:, :3, :3], mid_l)
    return poses


# ---------------------------------------------------------------------------------------------
# The real CLIPPER (--clipper)
class Clipper:
    """CLIPPER's core on one map: score + solve over semloc's candidate associations (the
    index built once), as `bench_clipper.py` runs it; views with more than `max_nodes`
    candidates are left out."""

    def __init__(self, module, global_map: ObjectMap, max_nodes: int) -> None:
        self.module, self.global_map, self.max_nodes = module, global_map, max_nodes
        self.index = CandidateIndex(global_map, AssociationConfig())

    def run(self, local: ObjectMap, truth: np.ndarray) -> tuple[float | None, bool | None]:
        """CPU ms of score + solve (the solver built before), and whether the closed-form
        pose of its associations succeeds; (None, None) over `max_nodes` candidates."""
        pairs = candidate_pairs(local, self.index)
        if len(pairs) > self.max_nodes:
            return None, None
        solver = clipper_solver(self.module)
        local_xyz, global_xyz = columns(local), columns(self.global_map)
        tick = time.process_time()
        selected = clipper_core(solver, local_xyz, global_xyz, pairs)
        ms = (time.process_time() - tick) * 1e3
        pose = pose_of(self.global_map, local, selected)
        return ms, pose is not None and bool(is_success(pose, truth))


def clipper_for(path: str | None, global_map: ObjectMap, max_nodes: int) -> Clipper | None:
    """A `Clipper` on `global_map` from the build at `path` (None without a path)."""
    if path is None:
        return None
    module, why = load_clipper(Path(path))
    if module is None:
        raise SystemExit(why)
    return Clipper(module, global_map, max_nodes)


# ---------------------------------------------------------------------------------------------
# One map (in its own process)
def measure_map(
    name: str,
    view_sizes: list[int],
    trials: int,
    seed: int,
    points: int,
    clipper_path: str | None = None,
    clipper_max_nodes: int = CLIPPER_MAX_NODES,
):
    global_map = load_map(name, points)
    if global_map is None:
        return []
    localizer_module.time = _ProcessClock  # Result.timing_ms in CPU ms, like the totals
    tick = time.process_time()
    Localizer(global_map).prepare()  # each object's cloud and KD-tree, once per map
    prepare_ms = (time.process_time() - tick) * 1e3
    clipper = clipper_for(clipper_path, global_map, clipper_max_nodes)
    for local, truth in views(global_map, max(view_sizes), 1, seed + 1000):
        localize(global_map, local)  # warm-up: loads the compiled code, first-call costs
        if clipper is not None:  # and CLIPPER's (its OpenMP threads started)
            clipper.run(local, truth.T_global_local)
    rows = []
    for view in view_sizes:
        row = Row(name, len(global_map), view, prepare_ms=prepare_ms)
        stream = view == max(view_sizes)
        for case, (local, truth) in enumerate(views(global_map, view, trials, seed + view)):
            row.cases.append(
                measure_case(global_map, local, truth.T_global_local, case, stream, clipper)
            )
        rows.append(row)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # kB on Linux
    for row in rows:
        row.peak_mb = peak
    return rows


class _ProcessClock:
    """Stands in for the `time` module of semloc.localizer: its stage times in CPU seconds."""

    perf_counter = staticmethod(time.process_time)


def measure_case(
    global_map: ObjectMap,
    local: ObjectMap,
    truth: np.ndarray,
    seed: int,
    stream: bool,
    clipper: Clipper | None = None,
) -> Case:
    wall, cpu = time.perf_counter(), time.process_time()
    result = localize(global_map, local)
    cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
    update_ms = []
    if stream:  # the same objects one per update, an answer at every update
        localizer = Localizer(global_map, local_up=local.up)
        # new copies: each update prepares its object's cloud, as a new detection's is
        for obj in sorted((o.replace() for o in local), key=lambda o: o.seen):
            tick = time.process_time()
            localizer.update([obj])
            update_ms.append((time.process_time() - tick) * 1e3)
    ransac_cpu = time.process_time()
    pose = ransac(global_map, local, seed)
    ransac_cpu = time.process_time() - ransac_cpu
    clipper_ms, clipper_success = clipper.run(local, truth) if clipper else (None, None)
    return Case(
        ms=cpu * 1e3,
        wall_ms=wall * 1e3,
        update_ms=update_ms,
        stages={k: float(v) for k, v in result.timing_ms.items()},
        success=result.pose is not None and bool(is_success(result.pose, truth)),
        ransac_ms=ransac_cpu * 1e3,
        ransac_success=pose is not None and bool(is_success(pose, truth)),
        clipper_ms=clipper_ms,
        clipper_success=clipper_success,
    )


def profile_map(name: str, view: int, trials: int, seed: int, points: int, top: int = 30) -> str:
    """Where the time of `trials` localizations of `view` objects goes on one map: cProfile's
    functions by own time, in CPU ms per localization (compiled kernels are single entries)."""
    global_map = load_map(name, points)
    if global_map is None:
        return f"{name}: real data not found (set SEMLOC_DATA)"
    Localizer(global_map).prepare()
    cases = [local for local, _ in views(global_map, view, trials, seed + view)]
    for local, _ in views(global_map, view, 1, seed + 1000):
        localize(global_map, local)  # warm-up, as in the timed runs
    profiler = cProfile.Profile(time.process_time)
    profiler.enable()
    for local in cases:
        localize(global_map, local)
    profiler.disable()
    stats = pstats.Stats(profiler).stats  # (file, line, name) -> (_, calls, own, with callees, _)
    rows = sorted(stats.items(), key=lambda item: -item[1][2])[:top]
    total = sum(own for _, _, own, _, _ in stats.values())
    lines = [
        f"cProfile of {trials} localizations of {view} objects on {name}: "
        f"{total * 1e3 / trials:.1f} CPU ms each",
        "",
        "| function | calls per localization | own ms | with callees ms |",
        "|---|---:|---:|---:|",
    ]
    for (file, line, function), (_, calls, own, cumulative, _) in rows:
        where = f"{Path(file).name}:{line}({function})" if line else function
        lines.append(
            f"| {where} | {calls / trials:.1f} | {own * 1e3 / trials:.2f} | "
            f"{cumulative * 1e3 / trials:.2f} |"
        )
    return "\n".join(lines)


def run_child(name: str, args: argparse.Namespace, src: str | None = None) -> list[Row]:
    """Measure one map in a fresh process pinned to one core; its rows.  `src`: the folder
    that process imports semloc from (default: as this one does)."""
    command = [sys.executable, __file__, "--worker", name, "--trials", str(args.trials)]
    command += ["--views", *map(str, args.views), "--seed", str(args.seed)]
    command += ["--points", str(args.points)]
    if getattr(args, "clipper", None):
        command += ["--clipper", str(args.clipper), "--clipper-max-nodes"]
        command += [str(args.clipper_max_nodes)]
    if args.cpu >= 0 and hasattr(os, "sched_setaffinity"):
        command = ["taskset", "-c", str(args.cpu), *command]
    env = None
    if src is not None:
        env = {**os.environ, "PYTHONPATH": os.pathsep.join([src, os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run(command, capture_output=True, text=True, check=False, env=env)
    if done.returncode != 0:
        print(f"{name}: failed\n{done.stderr[-2000:]}", file=sys.stderr)
        return []
    rows = []
    for raw in json.loads(done.stdout.strip().splitlines()[-1]):
        cases = [Case(**case) for case in raw.pop("cases")]
        rows.append(Row(**raw, cases=cases))
    return rows


def compare(names: list[str], args: argparse.Namespace) -> str:
    """This checkout against the one at `args.against`, map by map: the two measured in turn,
    `args.rounds` times, so that the slow and fast spells of a shared machine fall on both
    (two runs at once, one per core, slow each other down unevenly); per round the median ms
    of a localization and of a streaming update, and the median of the rounds' ratios."""
    other = str(Path(args.against).resolve() / "src")
    with_clipper = bool(getattr(args, "clipper", None))
    lines = [
        f"`bench_speed.py --against {args.against}` ({args.rounds} rounds, {args.trials} "
        "localizations per map and view in each; CPU ms, one core)",
        "",
        "| map | view | localization ms, this (per round) | other | this ÷ other | "
        "streaming update ms, this | other | this ÷ other |"
        + (" ÷ CLIPPER, this | ÷ CLIPPER, other |" if with_clipper else ""),
        "|---|---:|---|---|---:|---|---|---:|" + ("---:|---:|" if with_clipper else ""),
    ]
    for name in names:
        rounds = [(run_child(name, args), run_child(name, args, other)) for _ in range(args.rounds)]
        if not all(mine and theirs for mine, theirs in rounds):
            continue
        for v, view in enumerate(args.views):
            cells = [str(view)]
            for of in (lambda c: [c.ms], lambda c: c.update_ms):
                mine, theirs = (
                    [float(np.median([x for c in r[side][v].cases for x in of(c)] or [np.nan]))
                     for r in rounds]
                    for side in (0, 1)
                )  # fmt: skip
                ratio = float(np.median(np.array(mine) / np.array(theirs)))
                cells += [" / ".join(f"{x:.1f}" for x in mine),
                          " / ".join(f"{x:.1f}" for x in theirs), f"{ratio:.2f}"]  # fmt: skip
            if with_clipper:  # each checkout's ratio to CLIPPER: the median of its rounds'
                for side in (0, 1):
                    ratios = [_clipper_ratio(r[side][v].cases) for r in rounds]
                    kept = [x for x in ratios if x is not None]
                    cells.append(f"{np.median(kept):.1f}" if kept else "-")
            lines.append(f"| {name} | " + " | ".join(cells) + " |")
        print(f"done {name}", file=sys.stderr)
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------------
# Tables
def _stats(values: list[float]) -> tuple[float, float, float]:
    return float(np.median(values)), float(np.percentile(values, 90)), float(np.max(values))


def _fmt(values: list[float]) -> str:
    median, p90, most = _stats(values)
    return f"{median:.1f} / {p90:.1f} / {most:.1f}"


def _clipper_ratio(cases: list[Case]) -> float | None:
    """Median over the cases CLIPPER ran on of semloc's time ÷ CLIPPER's score + solve."""
    ratios = [c.ms / c.clipper_ms for c in cases if c.clipper_ms]
    return float(np.median(ratios)) if ratios else None


def _clipper_cells(cases: list[Case]) -> str:
    """CLIPPER's median ms, semloc's time ÷ it, and its success (over the cases it ran on)."""
    ran = [c for c in cases if c.clipper_ms is not None]
    if not ran:
        return " - | - | - |"
    ratio = _clipper_ratio(ran)
    count = "" if len(ran) == len(cases) else f" ({len(ran)} of {len(cases)})"
    return (
        f" {np.median([c.clipper_ms for c in ran]):.3f} | {ratio:.1f} | "
        f"{_rate([bool(c.clipper_success) for c in ran])}{count} |"
    )


def speed_table(rows: list[Row], with_clipper: bool = False) -> str:
    lines = [
        "| map | objects | map prepared once, ms | view | localization ms (median / p90 / max) | "
        "wall median | "
        "update ms (median / p90 / max) | peak MB | success | RANSAC ms | time ÷ RANSAC | "
        "RANSAC success |"
        + (
            " CLIPPER score + solve ms | time ÷ CLIPPER | CLIPPER success |" if with_clipper else ""
        ),
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
        + ("---:|---:|---:|" if with_clipper else ""),
    ]
    for row in rows:
        ms = [c.ms for c in row.cases]
        updates = [u for c in row.cases for u in c.update_ms]
        ransac_ms = [c.ransac_ms for c in row.cases]
        ratio = np.median(ms) / max(np.median(ransac_ms), 1e-9)
        lines.append(
            f"| {row.map} | {row.n_objects} | {row.prepare_ms:.0f} | {row.view} | {_fmt(ms)} | "
            f"{np.median([c.wall_ms for c in row.cases]):.1f} | "
            f"{_fmt(updates) if updates else '-'} | "
            f"{row.peak_mb:.0f} | {_rate([c.success for c in row.cases])} | "
            f"{np.median(ransac_ms):.1f} | {ratio:.1f} | "
            f"{_rate([c.ransac_success for c in row.cases])} |"
            + (_clipper_cells(row.cases) if with_clipper else "")
        )
    return "\n".join(lines)


def stage_table(rows: list[Row]) -> str:
    stages = sorted({k for row in rows for c in row.cases for k in c.stages})
    ordered = [k for k in stages if k != "total"] + (["total"] if "total" in stages else [])
    lines = [
        "| map | objects | view | " + " | ".join(f"{k} ms" for k in ordered) + " |",
        "|---|---:|---:|" + "---:|" * len(ordered),
    ]
    for row in rows:
        cells = [f"{np.median([c.stages.get(k, 0.0) for c in row.cases]):.1f}" for k in ordered]
        lines.append(f"| {row.map} | {row.n_objects} | {row.view} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def growth_table(rows: list[Row]) -> str:
    """Log-log slopes of median time and of peak memory against the buildings' size."""
    buildings = [row for row in rows if row.map.startswith("building-")]
    lines = [
        "| view | time slope | memory slope | sizes |",
        "|---:|---:|---:|---|",
    ]
    for view in sorted({row.view for row in buildings}):
        group = sorted((r for r in buildings if r.view == view), key=lambda r: r.n_objects)
        if len(group) < 2:
            continue
        n = np.log([r.n_objects for r in group])
        time_slope = np.polyfit(n, np.log([np.median([c.ms for c in r.cases]) for r in group]), 1)
        memory_slope = np.polyfit(n, np.log([r.peak_mb for r in group]), 1)
        sizes = ", ".join(str(r.n_objects) for r in group)
        lines.append(f"| {view} | {time_slope[0]:.2f} | {memory_slope[0]:.2f} | {sizes} |")
    return "\n".join(lines)


def _rate(flags: list[bool]) -> str:
    return f"{100 * np.mean(flags):.0f}%" if flags else "-"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="sizes 300 and 3000, views of 8")
    parser.add_argument("--sizes", type=int, nargs="+", help="building sizes (objects)")
    parser.add_argument("--views", type=int, nargs="+", help="local view sizes (objects)")
    parser.add_argument("--trials", type=int, help="localizations per map and view size")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--cpu", type=int, default=0, help="core to pin to (-1: no pinning)")
    parser.add_argument("--markdown", help="also write the tables to this file")
    parser.add_argument(
        "--points", type=int, default=POINTS_PER_OBJECT, help="points per building object"
    )
    parser.add_argument("--no-real", action="store_true", help="buildings only")
    parser.add_argument(
        "--profile", metavar="MAP", help="instead: where the time goes on MAP (e.g. building-300)"
    )
    parser.add_argument(
        "--against",
        metavar="TREE",
        help="instead: time this checkout against another one (its root; its src/ is imported), "
        "the two in turn map by map",
    )
    parser.add_argument("--rounds", type=int, default=3, help="rounds of --against")
    parser.add_argument(
        "--clipper", metavar="PATH", help="also the real CLIPPER: its build's bindings/python"
    )
    parser.add_argument(
        "--clipper-max-nodes",
        type=int,
        default=CLIPPER_MAX_NODES,
        help="CLIPPER runs on views with at most this many candidate associations",
    )
    parser.add_argument("--worker", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    preset = QUICK if args.quick else FULL
    args.sizes = args.sizes or preset["sizes"]
    args.views = args.views or preset["views"]
    args.trials = args.trials or preset["trials"]
    if args.profile:
        print(profile_map(args.profile, max(args.views), 4 * args.trials, args.seed, args.points))
        return 0
    if args.worker:
        rows = measure_map(
            args.worker, args.views, args.trials, args.seed, args.points,
            args.clipper, args.clipper_max_nodes,
        )  # fmt: skip
        print(json.dumps([asdict(row) for row in rows]))
        return 0
    start = time.perf_counter()
    print(omp_note())
    if args.clipper:  # checked here, before the children try it
        module, why = load_clipper(Path(args.clipper))
        print(f"CLIPPER: {why}" if module is None else f"CLIPPER: {module.__file__}")
        if module is None:
            return 2
    rows, notes = [], []
    real = [] if args.no_real else ["scannet", "replica"]
    if args.against:
        print(compare([*real, *(f"building-{n}" for n in args.sizes)], args))
        print(f"run time {time.perf_counter() - start:.0f} s")
        return 0
    for name in [*real, *(f"building-{n}" for n in args.sizes)]:
        found = run_child(name, args)
        if not found and not name.startswith("building-"):
            notes.append(f"{name}: real data not found (set SEMLOC_DATA), rows skipped")
        rows += found
        print(f"done {name}", file=sys.stderr)
    command = "PYTHONPATH=src python benchmarks/bench_speed.py " + " ".join(
        argv if argv is not None else sys.argv[1:]
    )
    report = "\n\n".join(
        [
            f"`{command.strip()}` (CPU ms, one core; peak MB: resident memory of the process)",
            speed_table(rows, bool(args.clipper)),
            "Time by stage (median over the cases, summed over the updates of a localization)",
            stage_table(rows),
            "Growth with the building's size (log-log slope; 1 = linear)",
            growth_table(rows),
            *notes,
            f"run time {time.perf_counter() - start:.0f} s",
        ]
    )
    print(report)
    if args.markdown:
        with open(args.markdown, "w", encoding="utf-8") as out:
            out.write(report + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
