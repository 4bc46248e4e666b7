"""semloc against the real CLIPPER (C++, Lusk et al., ICRA 2021) on the same views, in one process.

    OMP_NUM_THREADS=1 PYTHONPATH=src python benchmarks/bench_clipper.py \
        [--clipper CLIPPER/build/bindings/python] [--views 20] [--repeats 5] [--seed 0]

The views are those of `semloc.eval.variants` on the real maps (ScanNet scene0000_00, Replica
office4, 3RScan scene_1; simulated buildings when the real samples are absent): clean and
noisy, 3 / 5 / 8 objects with points, `--views` per map and size.  Per view:

- semloc: a full `semloc.localize` (Localizer construction, one update per keyframe, the
  answer at the last one), and the last update alone (a Localizer that has seen the other
  keyframes, answer on); each repeat on new copies of the view's objects, so that it prepares
  their point clouds as a localization of new detections does (the map's are prepared once);
- CLIPPER: its consistency graph over the same candidate associations as semloc's
  (`CandidateIndex`: labels through the taxonomy), scored with its Euclidean-distance
  invariant (epsilon 0.5 m, sigma 0.25 m, as semloc's CLIPPER-style baseline), its dense-cluster
  solve and the selected associations; then the closed-form pose of those associations (for
  the success column only; its time is printed apart).

Printed per size: median ms of each, the ratio semloc / CLIPPER (full localization against
CLIPPER's association), and success (rotation < 15°, translation < 0.5 m) of both.  Times are
the smallest of `--repeats` runs (CPU noise on a shared machine only ever adds).

CLIPPER is not a dependency of semloc: build it yourself (a C++ build with CMake and Eigen) and
point `--clipper` at the folder holding its `clipperpy` package:

    git clone https://github.com/mit-acl/clipper && cd clipper && mkdir build && cd build
    cmake .. -DCLIPPER_ENABLE_MAXCLIQUE=OFF -DCLIPPER_ENABLE_SCS_SDR=OFF && make py_clipper
    # --clipper clipper/build/bindings/python

Without it, the CLIPPER columns say so and only semloc is timed.  Set OMP_NUM_THREADS=1:
CLIPPER scores its graph with OpenMP, semloc runs on one core.
"""

from __future__ import annotations

import argparse
import importlib
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from semloc.association import AssociationConfig, CandidateIndex
from semloc.closed_form import fit
from semloc.compiling import warm_up
from semloc.eval.datasets import real_data_dir
from semloc.eval.success import is_success
from semloc.eval.variants import make_case, variant_maps
from semloc.localizer import Localizer, localize
from semloc.maps import ObjectMap
from semloc.sim.layouts import layout

SIZES = (3, 5, 8)
EPSILON, SIGMA = 0.5, 0.25


def load_clipper(folder: Path | None):
    """The `clipperpy` module of a CLIPPER build, or None (and why)."""
    if folder is None:
        return None, "no CLIPPER build given (--clipper BUILD/bindings/python)"
    sys.path.insert(0, str(folder))
    try:
        return importlib.import_module("clipperpy"), ""
    except ImportError as exc:
        return None, f"{folder}: no importable clipperpy ({exc})"


def best_of(
    repeats: int, run: Callable[..., object], setup: Callable[[], tuple] = tuple
) -> tuple[float, object]:
    """The smallest wall time (ms) of `repeats` runs of `run(*setup())` (setup untimed), and
    the last run's value."""
    times, value = [], None
    for _ in range(repeats):
        arguments = setup()
        began = time.perf_counter()
        value = run(*arguments)
        times.append((time.perf_counter() - began) * 1e3)
    return min(times), value


def fresh(local: ObjectMap) -> ObjectMap:
    """A copy of `local` made of new objects: a repeat must not find the clouds that an
    earlier repeat prepared for the same objects (a robot's detections are new each time)."""
    return ObjectMap([o.replace() for o in local], up=local.up, name=local.name)


def last_update_ms(global_map: ObjectMap, local: ObjectMap, repeats: int) -> float:
    """The smallest time (ms) of the last keyframe's update, on a Localizer that has seen the
    other keyframes (a fresh one per repeat, and fresh objects)."""
    keyframes = sorted(set(local.seen.tolist()))
    times = []
    for _ in range(repeats):
        copy = fresh(local)
        batches = [[o for o in copy if o.seen == k] for k in keyframes]
        localizer = Localizer(global_map, local_up=local.up)
        for batch in batches[:-1]:
            localizer.update(batch, answer=False)
        began = time.perf_counter()
        localizer.update(batches[-1])
        times.append((time.perf_counter() - began) * 1e3)
    return min(times)


def clipper_associate(clipperpy, global_map: ObjectMap, local: ObjectMap, index: CandidateIndex):
    """CLIPPER's selected (local index, global index) associations of `local` in `global_map`."""
    pairs = [(i, j) for i, obj in enumerate(local) for j in index.candidates(obj)]
    if len(pairs) < 2:
        return np.zeros((0, 2), dtype=np.int32)
    params = clipperpy.invariants.EuclideanDistanceParams()
    params.epsilon, params.sigma = EPSILON, SIGMA
    solver = clipperpy.CLIPPER(clipperpy.invariants.EuclideanDistance(params), clipperpy.Params())
    solver.score_pairwise_consistency(
        np.asfortranarray(local.positions.T), np.asfortranarray(global_map.positions.T),
        np.array(pairs, dtype=np.int32),
    )  # fmt: skip
    solver.solve()
    return np.asarray(solver.get_selected_associations())


def pose_of(global_map: ObjectMap, local: ObjectMap, selected: np.ndarray) -> np.ndarray | None:
    """The closed-form pose of the associations (4-DoF about gravity when both maps have it)."""
    if len(selected) < 2:
        return None
    src = np.ascontiguousarray(local.positions[selected[:, 0]])
    dst = np.ascontiguousarray(global_map.positions[selected[:, 1]])
    yaw_only = global_map.up is not None and local.up is not None
    if len(selected) < 3 and not yaw_only:
        return None
    R, t, _ = fit(src, dst, np.ones(len(selected)), yaw_only)
    pose = np.eye(4)
    pose[:3, :3], pose[:3, 3] = R, t
    return pose


@dataclass
class Row:
    semloc_ms: list[float] = field(default_factory=list)
    update_ms: list[float] = field(default_factory=list)
    clipper_ms: list[float] = field(default_factory=list)
    clipper_pose_ms: list[float] = field(default_factory=list)
    semloc_ok: list[bool] = field(default_factory=list)
    clipper_ok: list[bool] = field(default_factory=list)


def maps() -> dict[str, ObjectMap]:
    data = real_data_dir()
    if data is None:
        print("real samples not found (set SEMLOC_DATA): simulated buildings instead")
        return {"building-a": layout(120, seed=1), "building-b": layout(120, seed=2)}
    return variant_maps(data)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--clipper", type=Path, default=None)
    parser.add_argument("--views", type=int, default=20, help="views per map and size")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    clipperpy, why = load_clipper(args.clipper)
    if clipperpy is None:
        print(f"CLIPPER: {why}; its columns are left out")
    warm_up()
    rng = np.random.default_rng(args.seed)
    rows = {k: Row() for k in SIZES}
    for name, full in maps().items():
        for k in SIZES:
            for v in range(args.views):
                case = make_case(full, ("clean", "noisy")[v % 2], k, rng)
                row = rows[k]
                ms, result = best_of(
                    args.repeats, localize, lambda c=case: (c.prior, fresh(c.local))
                )
                row.semloc_ms.append(ms)
                row.semloc_ok.append(is_success(result.pose, case.truth))
                row.update_ms.append(last_update_ms(case.prior, case.local, args.repeats))
                if clipperpy is None:
                    continue
                index = CandidateIndex(case.prior, AssociationConfig())  # built untimed
                ms, selected = best_of(args.repeats, lambda c=case, i=index: clipper_associate(
                    clipperpy, c.prior, c.local, i))  # fmt: skip
                row.clipper_ms.append(ms)
                ms, pose = best_of(
                    args.repeats, lambda c=case, s=selected: pose_of(c.prior, c.local, s)
                )
                row.clipper_pose_ms.append(ms)
                row.clipper_ok.append(is_success(pose, case.truth))
        print(f"{name}: done", flush=True)
    print_table(rows, clipperpy is not None)


def print_table(rows: dict[int, Row], with_clipper: bool) -> None:
    header = ["objects", "views", "semloc.localize ms", "one update ms", "semloc success"]
    if with_clipper:
        header += ["CLIPPER assoc. ms", "+ pose ms", "CLIPPER success", "ratio semloc / CLIPPER"]
    print("\n| " + " | ".join(header) + " |\n|" + "---|" * len(header))
    for k, row in rows.items():
        cells = [str(k), str(len(row.semloc_ms)), f"{np.median(row.semloc_ms):.2f}",
                 f"{np.median(row.update_ms):.2f}", f"{np.mean(row.semloc_ok):.2f}"]  # fmt: skip
        if with_clipper:
            ratio = np.median(np.array(row.semloc_ms) / np.array(row.clipper_ms))
            cells += [f"{np.median(row.clipper_ms):.2f}", f"{np.median(row.clipper_pose_ms):.3f}",
                      f"{np.mean(row.clipper_ok):.2f}", f"{ratio:.1f}×"]  # fmt: skip
        print("| " + " | ".join(cells) + " |")
    print("\n(ratio: median over the views of semloc.localize's time over CLIPPER's association)")


if __name__ == "__main__":
    main()
