"""The clustering stage alone: recorded localizations replayed against `HierarchicalClustering`.

    PYTHONPATH=src python benchmarks/bench_clustering.py [--maps scannet replica building-300]
        [--views 8] [--trials 5] [--seed 0] [--reference OLD_CLUSTERING.py] [--cache DIR]

Each localization of `bench_speed.py` (same maps, same views, same seeds) is run once through
`semloc.localize` with the clustering's inputs recorded (the global map, and per update the
local positions, ids and detections); the updates are then replayed against the clustering
alone, timed in CPU ms (`time.process_time`, one core: pin with `taskset -c 0`).  Printed per
map: median / p90 / max ms per localization (its updates summed) and per update, and the pool
size.  With `--reference`, the same updates are replayed against another clustering module
(e.g. `git show main:src/semloc/clustering.py > /tmp/old.py`): after every update the sets,
scores (to 1e-9), ages and the `top()` lists must agree, and its times are printed beside
(both the least of `--repeat` replays, at least 2, taking turns at going first; the
reference's first-call costs are paid before timing).
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import importlib.util  # noqa: E402
import pickle  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_speed import load_map, views  # noqa: E402

import semloc.localizer as localizer_module  # noqa: E402
from semloc.clustering import HierarchicalClustering  # noqa: E402


def record(name: str, view: int, trials: int, seed: int) -> list[dict]:
    """The clustering inputs of each localization of `trials` views of `view` objects."""
    global_map = load_map(name)
    if global_map is None:
        return []
    sessions: list[dict] = []

    class Recording(HierarchicalClustering):
        def __init__(self, positions, ids, config=None):
            super().__init__(positions, ids, config)
            sessions.append({"positions": positions, "ids": ids, "config": config, "updates": []})

        def update(self, positions, ids, detections):
            sessions[-1]["updates"].append(
                (np.array(positions), list(ids), {k: np.array(v) for k, v in detections.items()})
            )
            super().update(positions, ids, detections)

    original = localizer_module.HierarchicalClustering
    localizer_module.HierarchicalClustering = Recording
    try:
        for local, _ in views(global_map, view, trials, seed + view):
            localizer_module.localize(global_map, local)
    finally:
        localizer_module.HierarchicalClustering = original
    return sessions


def replay(cls, session: dict, check=None) -> tuple[list[float], list[int]]:
    """CPU ms of each update of one session, and the pool size after it; `check(step, hc)`
    is called after each update (outside the timing)."""
    hc = cls(session["positions"], session["ids"], session["config"])
    times, sizes = [], []
    for step, (positions, ids, detections) in enumerate(session["updates"]):
        tick = time.process_time()
        hc.update(positions, ids, detections)
        times.append((time.process_time() - tick) * 1e3)
        sizes.append(hc.n_sets)
        if check is not None:
            check(step, hc)
    return times, sizes


def snapshot(hc) -> dict:
    """What a user reads of the pool: every set with score and age, and the top lists."""
    return {
        "sets": [(s.pairs, s.score, s.last_merge) for s in hc.sets()],
        "top": [s.pairs for s in hc.top(50, min_size=2)],
        "top_size": [s.pairs for s in hc.top(50, min_size=2, largest_first=True)],
    }


def same(a: dict, b: dict) -> str:
    """'' when two snapshots agree (scores to 1e-9), else what differs."""
    sets_a = {p: (s, m) for p, s, m in a["sets"]}
    sets_b = {p: (s, m) for p, s, m in b["sets"]}
    if sets_a.keys() != sets_b.keys():
        return f"sets differ: {len(sets_a.keys() - sets_b.keys())} / {len(sets_b.keys() - sets_a.keys())}"
    for pairs, (score, age) in sets_a.items():
        if abs(score - sets_b[pairs][0]) > 1e-9 or age != sets_b[pairs][1]:
            return f"set {pairs}: {score, age} vs {sets_b[pairs]}"
    if a["top"] != b["top"] or a["top_size"] != b["top_size"]:
        return "top lists differ"
    return ""


def compare(reference_cls, session: dict) -> str:
    """Replay a session against the reference and this clustering; the first difference
    after any update ('' if none)."""
    expected: list[dict] = []
    replay(reference_cls, session, lambda step, hc: expected.append(snapshot(hc)))
    found: list[str] = []

    def check(step: int, hc) -> None:
        why = same(snapshot(hc), expected[step])
        if why and not found:
            found.append(f"update {step}: {why}")

    replay(HierarchicalClustering, session, check)
    return found[0] if found else ""


def timed(classes: list, session: dict, repeat: int) -> tuple[list[np.ndarray], list[int]]:
    """Per class, the least CPU ms of each update over `repeat` replays of the session (the
    classes take turns going first, so that neither always runs on the other's warm caches),
    and the pool sizes of the first class after each update."""
    best: list = [None] * len(classes)
    sizes: list[int] = []
    for r in range(repeat):
        order = range(len(classes)) if r % 2 == 0 else reversed(range(len(classes)))
        for i in order:
            times, sizes_i = replay(classes[i], session)
            best[i] = np.asarray(times) if best[i] is None else np.minimum(best[i], times)
            sizes = sizes_i if i == 0 else sizes
    return best, sizes


def load_module(path: str):
    spec = importlib.util.spec_from_file_location("reference_clustering", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def _fmt(values) -> str:
    return f"{np.median(values):.2f} / {np.percentile(values, 90):.2f} / {np.max(values):.2f}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--maps", nargs="+", default=["scannet", "replica", "building-300"])
    parser.add_argument("--views", type=int, nargs="+", default=[8])
    parser.add_argument("--trials", type=int, default=5)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--reference", help="another clustering.py to compare with")
    parser.add_argument("--cache", help="keep the recordings in this folder")
    parser.add_argument("--repeat", type=int, default=1, help="replays per session (min time)")
    args = parser.parse_args(argv)
    reference = load_module(args.reference) if args.reference else None
    print(
        "| map | view | localizations | ms per localization (median / p90 / max) | "
        "ms per update | pool | reference ms per localization | equal |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---|")
    failures = 0
    classes = [HierarchicalClustering]
    if reference is not None:
        classes.append(reference.HierarchicalClustering)
    warm_up = 0.0
    for session in _sessions(args.maps[0], args.views[0], args)[:1]:
        tick = time.process_time()  # compiles (or loads from numba's cache) the inner loops
        replay(HierarchicalClustering, session)
        warm_up = (time.process_time() - tick) * 1e3
        for cls in classes[1:]:
            replay(cls, session)  # the reference's first-call costs, outside its times
    for name in args.maps:
        for view in args.views:
            sessions = _sessions(name, view, args)
            if not sessions:
                print(f"| {name} | {view} | real data absent | | | | | |")
                continue
            per_loc, per_update, pool, ref_loc, equal = [], [], [], [], True
            for session in sessions:
                best, sizes = timed(classes, session, max(args.repeat, 2 if reference else 1))
                per_loc.append(float(np.sum(best[0])))
                per_update += list(best[0])
                pool.append(max(sizes))
                if reference is not None:
                    ref_loc.append(float(np.sum(best[1])))
                    mismatch = compare(reference.HierarchicalClustering, session)
                    if mismatch:
                        equal = False
                        failures += 1
                        print(f"MISMATCH {name} view {view}: {mismatch}", file=sys.stderr)
            print(
                f"| {name} | {view} | {len(sessions)} | {_fmt(per_loc)} | {_fmt(per_update)} | "
                f"{max(pool)} | {_fmt(ref_loc) if ref_loc else '-'} | "
                f"{('yes' if equal else 'NO') if reference else '-'} |"
            )
    print(
        f"\nfirst localization of the process (compiling or loading the kernels): {warm_up:.0f} ms"
    )
    return 1 if failures else 0


def _sessions(name: str, view: int, args) -> list[dict]:
    if args.cache:
        path = Path(args.cache) / f"{name}-v{view}-t{args.trials}-s{args.seed}.pkl"
        if path.exists():
            return pickle.loads(path.read_bytes())
    sessions = record(name, view, args.trials, args.seed)
    if args.cache and sessions:
        Path(args.cache).mkdir(parents=True, exist_ok=True)
        path.write_bytes(pickle.dumps(sessions))
    return sessions


if __name__ == "__main__":
    sys.exit(main())
