"""Building scale (issue 55): place retrieval, position priors and "look there next" on maps of
1k to 100k objects.

    PYTHONPATH=src SEMLOC_DATA=../shared/data/real python benchmarks/building.py
        [--sizes 1000 10000 100000] [--bases rooms scannet replica] [--views 40]
        [--starts 20] [--no-retrieval] [--set KEY=JSON ...] [--quick] [--lookalike]

Buildings: a base tiled side by side into about N objects, each copy keeping a random 70 % of
the base's objects (`semloc.sim.longwalk.tiled`: copies are alike, not identical), 64 surface
points per object.  Bases: `rooms`, a simulated floor of repeated rooms
(`semloc.sim.layouts.layout(300)`: classrooms, offices, ... full of the same furniture), and
the real scans `scannet` (ScanNet scene0000_00) and `replica` (Replica office4) from
`SEMLOC_DATA` (rows skipped when absent).  Each building runs in its own process (its peak
resident memory is the process's).

Views: the 8 objects nearest to a point beside a random object, their visible-side points
(`bench_speed.views`).  Per building:

* index: time and memory of the place index (`semloc.places`, built once per map);
* localization: CPU ms per `semloc.localize` (median / p90; objects' clouds prepared first);
* top-1 / top-10: the best / any of the 10 best hypotheses within 15 deg and 0.5 m;
* ceiling: the share of views with no identical copy elsewhere, the most any method can
  place: a view has a copy when a gravity-aligned pose 0.5 m / 15 deg or more off the truth
  puts each of its map objects within `COPY_M` of a map object of its label (searched
  exhaustively from the view's two farthest objects);
* prior: top-1 with a 10 m position prior around a point within 5 m of the true origin, and
  its ceiling: the share of views with no identical copy whose origin lies in the prior;
* one room: top-1 of the same views against the base alone (the single-room success);
* wrong: `localized` answers with a wrong pose (without / with the prior).

A second table (issue 59, look-alike rooms) gives, per building without and with the prior,
the right hypothesis's rank (1, 2-5, 6+, not listed: the right place dropped out of the
search, and of those how many answers do not say the search was cut), the `ambiguous` answers with two or more hypotheses and how many of them carry a
`next_look`, the searches that were cut (the reason says so: places as well supported as the
best left out, `semloc.decision.SEARCH_CUT`, or every object waiting in place retrieval), and
the wrong claims.
`--lookalike` runs the sizes of the issue's look-alike buildings (2,300 and 6,800 objects; the
issue tiled a 226-object apartment: `rooms` is the nearest in size), without active runs.

Active runs (`--starts`, on the `rooms` building of the smallest size): starts where the
first view (objects within 2.5 m of the robot, centres only) is `ambiguous`; then each
keyframe the robot either walks on (2 m in its heading, turning back at the building's edge)
or, when the answer is ambiguous and has a suggestion, looks at the spot of the suggestion's
best separated rank (`Result.next_look`; the first suggestion whose spot it has not looked at
yet: an empty spot tells semloc nothing, so the same suggestion may come again); it sees the map objects within 2.5 m of where it
looks.  Printed: keyframes to the first right `localized` answer (median over the starts that
reach one), the share right and localized after 10 keyframes, wrong claims.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import resource  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from scipy.spatial import cKDTree  # noqa: E402

sys.path.insert(0, str(Path(__file__).parent))
from bench_speed import _yaw_poses, views  # noqa: E402

from semloc import Localizer, LocalizerConfig, ObjectMap, Prior, localize  # noqa: E402
from semloc.decision import SEARCH_CUT  # noqa: E402
from semloc.eval.datasets import real_data_dir  # noqa: E402
from semloc.eval.success import is_success  # noqa: E402
from semloc.io.importers.replica import load_replica  # noqa: E402
from semloc.io.importers.scannet import load_scannet  # noqa: E402
from semloc.maps import SemanticObject  # noqa: E402
from semloc.places import place_index  # noqa: E402
from semloc.sim.layouts import layout  # noqa: E402
from semloc.sim.longwalk import tiled  # noqa: E402
from semloc.transforms import yaw_pose  # noqa: E402

POINTS = 64
VIEW = 8
COPY_M = 0.3  # a copy's objects lie this close to the view's (less than a right pose's error)
PRIOR_RADIUS, PRIOR_OFFSET = 10.0, 5.0
WAITING = "fits too many places"  # a `failed` answer's reason while place retrieval waits
SIGHT_M, STEP_M, KEYFRAMES = 2.5, 2.0, 10


# --------------------------------------------------------------------------------- buildings
def base(name: str) -> ObjectMap | None:
    """The room or floor a building repeats (None: real data absent)."""
    if name == "rooms":
        return layout(300, seed=0, points_per_object=POINTS)
    data = real_data_dir()
    if data is None:
        return None
    folder = data / ("scannet/scene0000_00" if name == "scannet" else "replica/office4")
    if not folder.is_dir():
        return None
    scan = load_scannet(folder) if name == "scannet" else load_replica(folder)
    return _thinned(scan, POINTS)


def _thinned(scan: ObjectMap, points: int) -> ObjectMap:
    rng = np.random.default_rng(0)
    objects = []
    for obj in scan:
        if obj.points is not None and len(obj.points) > points:
            obj = obj.replace(points=obj.points[rng.choice(len(obj.points), points, False)])
        objects.append(obj)
    return scan.with_objects(objects)


def building(room: ObjectMap, size: int) -> ObjectMap:
    """`room` tiled into about `size` objects (each copy keeps 70 % of them)."""
    copies = max(1, math.floor(0.98 * size / (0.7 * len(room))))  # (maps hold <= 100k)
    columns = math.ceil(math.sqrt(copies))
    return tiled(room, columns, max(1, copies // columns), keep=0.7, seed=size)


def tile_offset(world: ObjectMap, room: ObjectMap, global_id: str) -> np.ndarray:
    """The translation of the copy holding `global_id` ('c.r/<room id>')."""
    inner = global_id.split("/", 1)[1]
    return world[world.index_of(global_id)].position - room[room.index_of(inner)].position


# ------------------------------------------------------------------------- the information ceiling
def copies(world: ObjectMap, ids: list[str], truth: np.ndarray, trees: dict) -> np.ndarray:
    """Where the local origin would be under each identical copy of the map objects `ids`
    elsewhere (module docstring): (n, 3), empty when the view is unique."""
    index = [world.index_of(i) for i in ids]
    xyz, labels = world.positions[index], world.labels[index]
    gaps = np.linalg.norm(xyz[:, None, :2] - xyz[None, :, :2], axis=2)
    a, b = np.unravel_index(np.argmax(gaps), gaps.shape)
    d = np.linalg.norm(xyz[a] - xyz[b])
    first, second = trees[labels[a]], trees[labels[b]]
    near = second.query_ball_point(first.data, d + 2 * COPY_M)
    i = np.repeat(np.arange(len(near)), [len(n) for n in near])
    j = np.concatenate([np.asarray(n, dtype=int) for n in near]) if len(i) else np.zeros(0, int)
    keep = np.linalg.norm(first.data[i] - second.data[j], axis=1) >= d - 2 * COPY_M
    i, j = i[keep], j[keep]
    origins = []
    for chunk in range(0, len(i), 50_000):
        s = slice(chunk, chunk + 50_000)
        n = len(i[s])
        poses = _yaw_poses(np.tile(xyz[a], (n, 1)), np.tile(xyz[b], (n, 1)),
                           first.data[i[s]], second.data[j[s]])  # fmt: skip
        moved = xyz[None] @ np.swapaxes(poses[:, :3, :3], 1, 2) + poses[:, None, :3, 3]
        fits = np.ones(n, dtype=bool)
        for k, label in enumerate(labels):
            fits &= trees[label].query(moved[:, k], distance_upper_bound=COPY_M)[0] <= COPY_M
        origins += [
            (pose @ truth)[:3, 3] for pose in poses[fits] if not is_success(pose @ truth, truth)
        ]  # fmt: skip (the view itself)
    return np.array(origins).reshape(-1, 3)


# ------------------------------------------------------------------------------- one building
def measure(base_name: str, size: int, n_views: int, settings: dict, seed: int) -> dict:
    room = base(base_name)
    if room is None:
        return {}
    world = building(room, size)
    config = LocalizerConfig(**settings)
    retrieval = config.retrieval.above is not None
    tick = time.process_time()
    index = place_index(world, config.retrieval) if retrieval else None
    index_s = time.process_time() - tick
    Localizer(world, config).prepare()
    Localizer(room, config).prepare()
    trees = {str(label): cKDTree(world.positions[world.labels == label])
             for label in np.unique(world.labels)}  # fmt: skip
    rng = np.random.default_rng(seed)
    cases = list(views(world, VIEW, n_views + 1, seed))
    localize(world, cases[0][0], config=config)  # warm-up
    rows = []
    for local, truth in cases[1:]:
        T = truth.T_global_local
        tick = time.process_time()
        result = localize(world, local, config=config)
        ms = (time.process_time() - tick) * 1e3
        offset = rng.normal(size=3) * [1, 1, 0]
        offset *= rng.uniform(0, PRIOR_OFFSET) / max(np.linalg.norm(offset), 1e-9)
        prior = Prior(position=T[:3, 3] + offset, radius=PRIOR_RADIUS)
        with_prior = localize(world, local, config=config, prior=prior)
        shift = np.eye(4)
        shift[:3, 3] = -tile_offset(world, room, truth.pairs[0][0])
        alone = localize(room, local, config=config)
        elsewhere = copies(world, [g for g, _ in truth.pairs], T, trees)
        rows.append({
            "ms": ms,
            "top1": _right(result, T, 1), "top10": _right(result, T, 10),
            "wrong": result.status == "localized" and not _right(result, T, 1),
            "prior": _right(with_prior, T, 1),
            "prior_wrong": with_prior.status == "localized" and not _right(with_prior, T, 1),
            **_answer(result, T, ""), **_answer(with_prior, T, "prior_"),
            "room": _right(alone, shift @ T, 1),
            "copy": len(elsewhere) > 0,
            "copy_in_prior": bool(np.any(np.linalg.norm(elsewhere - prior.position, axis=1)
                                         <= PRIOR_RADIUS + 0.5)),
        })  # fmt: skip
    return {
        "base": base_name, "size": size, "objects": len(world), "index_s": index_s,
        "index_mb": 0.0 if index is None else index.nbytes / 1e6, "rows": rows,
        "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    }  # fmt: skip


def _right(result, truth: np.ndarray, k: int) -> bool:
    return any(h.pose is not None and is_success(h.pose, truth) for h in result.hypotheses[:k])


def _answer(result, truth: np.ndarray, prefix: str) -> dict:
    """The right hypothesis's rank (0: not listed), whether the answer is `ambiguous` with two
    or more hypotheses, whether it then carries a `next_look`, and whether the search was cut."""
    ranks = [h.rank for h in result.hypotheses if h.pose is not None and is_success(h.pose, truth)]
    rivals = result.status == "ambiguous" and len(result.hypotheses) >= 2
    return {
        f"{prefix}rank": min(ranks, default=0),
        f"{prefix}ambiguous": rivals,
        f"{prefix}look": rivals and len(result.next_look) > 0,
        f"{prefix}cut": result.reason.startswith(SEARCH_CUT) or WAITING in result.reason,
    }


# -------------------------------------------------------------------------------- active runs
def observe(world: ObjectMap, truth: np.ndarray, spot: np.ndarray, rng) -> list[SemanticObject]:
    """The map objects within sight of `spot` (local frame), as local objects (centres)."""
    at = truth[:3, :3] @ spot + truth[:3, 3]
    near = np.flatnonzero(np.linalg.norm(world.positions - at, axis=1) <= SIGHT_M)
    inverse = np.linalg.inv(truth)
    return [
        SemanticObject(f"l-{world.ids[i]}", world.labels[i],
                       inverse[:3, :3] @ world.positions[i] + inverse[:3, 3] + rng.normal(0, 0.03, 3))
        for i in near
    ]  # fmt: skip


def active(world: ObjectMap, config, starts: int, follow: bool, seed: int) -> list[dict]:
    """Runs from ambiguous starts, following `next_look` or walking on (module docstring)."""
    rng = np.random.default_rng(seed)
    low, high = world.positions.min(axis=0), world.positions.max(axis=0)
    runs = []
    while len(runs) < starts:
        anchor = world.positions[rng.integers(len(world))]
        truth = yaw_pose(rng.uniform(-np.pi, np.pi), [anchor[0] + 0.5, anchor[1], 0.0])
        localizer = Localizer(world, config, local_up=[0, 0, 1])
        spot, heading = np.zeros(3), np.array([1.0, 0.0, 0.0])
        seen = observe(world, truth, spot, rng)
        if len(seen) < 2:
            continue
        result = localizer.update(seen)
        if result.status != "ambiguous":
            continue  # not an ambiguous start
        first, wrong, looked = None, 0, [spot]
        for k in range(1, KEYFRAMES + 1):
            looks = [  # a spot looked at already showed what it shows
                look.where[min(look.separates)] for look in (result.next_look if follow else [])
            ]
            looks = [p for p in looks if min(np.linalg.norm(p - q) for q in looked) > SIGHT_M / 2]
            if looks:
                spot = looks[0]
                looked.append(spot)
            else:
                step = spot + STEP_M * heading
                at = truth[:3, :3] @ step + truth[:3, 3]
                if np.any(at[:2] < low[:2]) or np.any(at[:2] > high[:2]):
                    heading = -heading
                    step = spot + STEP_M * heading
                spot = step
            seen = observe(world, truth, spot, rng)
            result = localizer.update(seen) if seen else result
            right = result.status == "localized" and is_success(result.pose, truth)
            wrong += result.status == "localized" and not right
            if right and first is None:
                first = k
        runs.append({"first": first, "final": result.status == "localized"
                     and is_success(result.pose, truth), "wrong": wrong})  # fmt: skip
    return runs


# ------------------------------------------------------------------------------------ tables
def building_table(results: list[dict]) -> str:
    lines = [
        "| building | objects | index s | index MB | localize ms (median / p90) | peak MB "
        "| ceiling | top-1 | top-10 | ceiling in prior | top-1, 10 m prior | one room top-1 "
        "| wrong (no prior / prior) |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in results:
        rows = r["rows"]

        def share(key: str, rows: list[dict] = rows) -> float:
            return float(np.mean([row[key] for row in rows]))

        ms = [row["ms"] for row in rows]
        lines.append(
            f"| {r['base']} | {r['objects']:,} | {r['index_s']:.1f} | {r['index_mb']:.0f} "
            f"| {np.median(ms):.1f} / {np.percentile(ms, 90):.1f} | {r['peak_mb']:.0f} "
            f"| {1 - share('copy'):.2f} | {share('top1'):.2f} | {share('top10'):.2f} "
            f"| {1 - share('copy_in_prior'):.2f} | {share('prior'):.2f} | {share('room'):.2f} "
            f"| {sum(row['wrong'] for row in rows)} / {sum(row['prior_wrong'] for row in rows)} |"
        )
    return "\n".join(lines)


RANKS = (("1", 1, 1), ("2-5", 2, 5), ("6+", 6, 10**9))


def rank_table(results: list[dict]) -> str:
    """Per building, without and with the prior: where the right hypothesis ranks, the
    `ambiguous` answers with two or more hypotheses and how many carry a `next_look`, how many
    searches were cut, and the wrong claims."""
    lines = [
        "| building | objects | prior | right at rank 1 | 2-5 | 6+ | not listed "
        "| of which the search was not cut | ambiguous (>= 2 hypotheses) | with next_look "
        "| search cut | wrong claims |",
        "|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in results:
        for prefix, prior in (("", "none"), ("prior_", "10 m")):
            rows = r["rows"]
            ranks = [row.get(f"{prefix}rank", 0) for row in rows]
            counts = [sum(low <= k <= high for k in ranks) for _, low, high in RANKS]
            ambiguous = sum(row.get(f"{prefix}ambiguous", False) for row in rows)
            looks = sum(row.get(f"{prefix}look", False) for row in rows)
            cut = sum(row.get(f"{prefix}cut", False) for row in rows)
            lost = sum(k == 0 and not row.get(f"{prefix}cut", False) for k, row in zip(ranks, rows))
            wrong = sum(row["prior_wrong" if prefix else "wrong"] for row in rows)
            lines.append(
                f"| {r['base']} | {r['objects']:,} | {prior} | "
                + " | ".join(str(c) for c in counts)
                + f" | {ranks.count(0)} | {lost} | {ambiguous} | {looks} | {cut} | {wrong} |"
            )
    return "\n".join(lines)


def active_table(objects: int, runs: dict[str, list[dict]]) -> str:
    lines = [
        f"Active runs on the rooms building ({objects:,} objects), from ambiguous starts",
        "",
        "| robot | starts | keyframes to a right localized answer (median) | right and "
        f"localized after {KEYFRAMES} | wrong claims |",
        "|---|---:|---:|---:|---:|",
    ]
    for name, found in runs.items():
        firsts = [r["first"] for r in found if r["first"] is not None]
        median = f"{np.median(firsts):.1f} ({len(firsts)} reach one)" if firsts else "never"
        final = np.mean([r["final"] for r in found])
        lines.append(
            f"| {name} | {len(found)} | {median} | {final:.2f} | {sum(r['wrong'] for r in found)} |"
        )
    return "\n".join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[1000, 10000, 100000])
    parser.add_argument("--bases", nargs="+", default=["rooms", "scannet", "replica"])
    parser.add_argument("--views", type=int, default=40)
    parser.add_argument("--starts", type=int, default=20, help="active runs (0: none)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--no-retrieval", action="store_true", help="cluster every candidate")
    parser.add_argument(
        "--set", nargs="+", default=[], metavar="KEY=JSON",
        help="Localizer settings, e.g. wait_above=2000 (flat LocalizerConfig fields)",
    )  # fmt: skip
    parser.add_argument("--quick", action="store_true", help="1k and 10k, 10 views, 8 starts")
    parser.add_argument(
        "--lookalike", action="store_true",
        help="the issue's look-alike buildings: 2,300 and 6,800 objects, no active runs",
    )  # fmt: skip
    parser.add_argument("--worker", nargs=2, metavar=("BASE", "SIZE"), help=argparse.SUPPRESS)
    parser.add_argument("--active-worker", type=int, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.quick:
        args.sizes, args.views, args.starts = [1000, 10000], 10, 8
    if args.lookalike:
        args.sizes, args.starts = [2300, 6800], 0
    settings = {key: json.loads(value) for key, value in (a.split("=", 1) for a in args.set)}
    if args.no_retrieval:
        settings["above"] = None
    if args.worker:
        found = measure(args.worker[0], int(args.worker[1]), args.views, settings, args.seed)
        print(json.dumps(found))
        return 0
    if args.active_worker:
        world = building(base("rooms"), args.active_worker)
        config = LocalizerConfig(**settings)
        runs = {name: active(world, config, args.starts, follow, args.seed)
                for name, follow in (("follows next_look", True), ("walks on", False))}  # fmt: skip
        print(json.dumps({"objects": len(world), "runs": runs}))
        return 0
    started = time.perf_counter()
    results, skipped = [], []
    for name in args.bases:
        for size in args.sizes:
            command = [sys.executable, __file__, "--worker", name, str(size), "--views",
                       str(args.views), "--seed", str(args.seed)]  # fmt: skip
            command += ["--no-retrieval"] if args.no_retrieval else []
            command += ["--set", *args.set] if args.set else []
            out = subprocess.run(command, capture_output=True, text=True)
            if out.returncode != 0:
                print(f"{name}-{size}: failed\n{out.stderr[-2000:]}", file=sys.stderr)
                continue
            found = json.loads(out.stdout.strip().splitlines()[-1])
            if found:
                results.append(found)
            else:
                skipped.append(f"{name} {size}: skipped, real data absent (SEMLOC_DATA)")
            print(f"done {name} {size}", file=sys.stderr)
    print(f"`{' '.join(['python', 'benchmarks/building.py', *sys.argv[1:]])}` (CPU ms, one core)")
    print()
    print(building_table(results))
    print("".join(f"\n{line}" for line in skipped))
    print(f"Right hypothesis's rank ({args.views} views per building)")
    print()
    print(rank_table(results))
    if args.starts == 0:
        print(f"\nrun time {time.perf_counter() - started:.0f} s")
        return 0
    command = [sys.executable, __file__, "--active-worker", str(min(args.sizes)), "--starts",
               str(args.starts), "--seed", str(args.seed)]  # fmt: skip
    command += ["--set", *args.set] if args.set else []
    command += ["--no-retrieval"] if args.no_retrieval else []
    out = subprocess.run(command, capture_output=True, text=True)
    if out.returncode == 0:
        found = json.loads(out.stdout.strip().splitlines()[-1])
        print()
        print(active_table(found["objects"], found["runs"]))
    else:
        print(f"active runs failed\n{out.stderr[-2000:]}", file=sys.stderr)
    print(f"\nrun time {time.perf_counter() - started:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
