"""semloc against the real CLIPPER (C++, Lusk et al., ICRA 2021) on the same cases, one thread each.

    OMP_NUM_THREADS=1 PYTHONPATH=src python benchmarks/bench_clipper.py \
        [--clipper CLIPPER/build/bindings/python] [--views 20] [--repeats 5] [--seed 0] \
        [--merges 2] [--merge-sizes 15 30 60 150] [--against TREE] [--rounds 1]

Two kinds of case, written once to a temporary folder as native map files (`semloc.io`), so
that every process measured reads the very same cases:

- **Few-object views**: those of `semloc.eval.variants` on the real maps (ScanNet
  scene0000_00, Replica office4, 3RScan scene_1; simulated buildings when the real samples are
  absent): clean and noisy, 3 / 5 / 8 objects with points, `--views` per map and size.
- **Map merges**: a second session of 15 / 30 / 60 / 150 objects cut from a first map
  (`bench_align.second_session`: the first map covers part of it, in its own frame; clean and
  noisy alternately), `--merges` per map and size, on the real maps that are large enough and
  on a simulated building of 400 objects (64 points each: the 60- and 150-object sessions).

The cases are measured in a child process (`--worker`): it loads the first maps, prepares
their clouds once (`Localizer.prepare`, as a robot or server that holds its map) and runs one
untimed case of each kind first (semloc's compiled code loaded, CLIPPER's OpenMP threads
started), then per case:

- semloc: `semloc.localize` (views) or `semloc.align` (merges) on new copies of the case's
  objects, so that it prepares their point clouds as for new detections; for views also the
  last keyframe's update alone (a Localizer that has seen the other keyframes);
- CLIPPER: its consistency graph over the same candidate associations as semloc's
  (`CandidateIndex` of the first map, built once: labels through the taxonomy), with its
  Euclidean-distance invariant (epsilon 0.5 m, sigma 0.25 m, as semloc's CLIPPER-style
  baseline).  Its **core** is timed on `score_pairwise_consistency` + `solve` (+ reading the
  selected associations) only: the solver is built before the clock starts.  Cases with more
  than `--max-nodes` candidate associations are left to semloc (CLIPPER's graph is dense);
- **file to answer**, both: the view's (second session's) file read with `semloc.io.load_map`,
  then semloc's answer; or the candidates looked up, CLIPPER built, scored and solved, and the
  closed-form pose of its associations (4-DoF about gravity), all in Python around its C++ core.

Printed per size (and over all sizes): median ms of each, success (rotation < 15°, translation
< 0.5 m) of both, the **core ratio** (median over the cases of semloc's answer time ÷ CLIPPER's
score + solve) and the **file-to-answer ratio** (the same from the files).  Times are the
smallest of `--repeats` runs (fewer once they took 2 s: CLIPPER's 150-object merges take
seconds) in each of `--rounds` processes (CPU noise on a shared machine only ever adds).

`--against TREE` measures this checkout and another one (its root, e.g. a `git worktree` of an
older commit; its `src/` is imported) on the same case files, in turn, `--rounds` times each
(the same child process setup): both checkouts' tables, and one pairing them, this ÷ other.

OMP_NUM_THREADS must be 1 (the script says whether it is, and warns if not): CLIPPER scores its
graph with OpenMP, semloc runs on one core; the ratios are single-thread ones.

CLIPPER is not a dependency of semloc: build it yourself (a C++ build with CMake, Eigen and
pybind11) and point `--clipper` at the folder holding its `clipperpy` package:

    git clone https://github.com/mit-acl/clipper && cd clipper && mkdir build && cd build
    cmake .. -DCLIPPER_ENABLE_MAXCLIQUE=OFF -DCLIPPER_ENABLE_SCS_SDR=OFF \
        -DCLIPPER_BUILD_TESTS=OFF -DPython_EXECUTABLE=$(which python)
    make py_clipper            # then: --clipper clipper/build/bindings/python

CLIPPER's CMakeLists.txt downloads pybind11 2.9 at configure time; offline, or where that
version is too old for your Python, replace its `FetchContent_Declare(pybind11 ...)` /
`FetchContent_MakeAvailable(pybind11)` lines with `find_package(pybind11 REQUIRED)`,
`pip install 'pybind11>=2.12'` and add `-DPYBIND11_FINDPYTHON=ON
-Dpybind11_DIR=$(python -m pybind11 --cmakedir)` to the cmake line.  Without a build the
CLIPPER columns say so and only semloc is timed.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, fields
from pathlib import Path

import numpy as np

import semloc
from semloc.association import AssociationConfig, CandidateIndex
from semloc.closed_form import fit
from semloc.compiling import warm_up
from semloc.eval.datasets import real_data_dir
from semloc.eval.success import is_success
from semloc.eval.variants import make_case, variant_maps
from semloc.io.native import load_map, save_map
from semloc.localizer import Localizer, localize
from semloc.maps import ObjectMap
from semloc.sim.layouts import layout

SIZES = (3, 5, 8)
MERGE_SIZES = (15, 30, 60, 150)
EPSILON, SIGMA = 0.5, 0.25
MAX_NODES = 20_000  # CLIPPER's graph of n candidate associations: 12k nodes take 1.4 GB
BUDGET_MS = 2000.0  # a case's repeats stop once they have taken this long


# ---------------------------------------------------------------------------------------------
# CLIPPER through its Python binding
def load_clipper(folder: Path | None):
    """The `clipperpy` module of a CLIPPER build, or None (and why)."""
    if folder is None:
        return None, "no CLIPPER build given (--clipper BUILD/bindings/python)"
    sys.path.insert(0, str(folder))
    try:
        return importlib.import_module("clipperpy"), ""
    except ImportError as exc:
        return None, f"{folder}: no importable clipperpy ({exc})"


def omp_note() -> str:
    """Whether OpenMP is held to one thread (CLIPPER's scoring; the ratios are single-thread)."""
    value = os.environ.get("OMP_NUM_THREADS")
    if value == "1":
        return "OMP_NUM_THREADS=1: CLIPPER runs on one thread, as semloc"
    return (
        f"WARNING: OMP_NUM_THREADS is {'unset' if value is None else repr(value)}, not 1: "
        "CLIPPER may score on several threads and the ratios are not single-thread ones"
    )


def candidate_pairs(local: ObjectMap, index: CandidateIndex) -> np.ndarray:
    """semloc's candidate associations, (local index, global index) rows, as CLIPPER takes them."""
    pairs = [(i, j) for i, obj in enumerate(local) for j in index.candidates(obj)]
    return np.array(pairs, dtype=np.int32).reshape(-1, 2)


def clipper_solver(clipperpy):
    """A CLIPPER instance with the Euclidean-distance invariant (built outside the timing)."""
    params = clipperpy.invariants.EuclideanDistanceParams()
    params.epsilon, params.sigma = EPSILON, SIGMA
    return clipperpy.CLIPPER(clipperpy.invariants.EuclideanDistance(params), clipperpy.Params())


def clipper_core(solver, local_xyz: np.ndarray, global_xyz: np.ndarray, pairs: np.ndarray):
    """CLIPPER's core: score the consistency graph, solve for its densest cluster; the selected
    (local index, global index) associations.  The positions are 3 x n, Fortran order."""
    if len(pairs) < 2:
        return np.zeros((0, 2), dtype=np.int32)
    solver.score_pairwise_consistency(local_xyz, global_xyz, pairs)
    solver.solve()
    return np.asarray(solver.get_selected_associations())


def columns(objmap: ObjectMap) -> np.ndarray:
    """The map's centres as CLIPPER's binding takes them (3 x n, Fortran order)."""
    return np.asfortranarray(objmap.positions.T)


def clipper_associate(clipperpy, global_map: ObjectMap, local: ObjectMap, index: CandidateIndex):
    """CLIPPER's selected (local index, global index) associations of `local` in `global_map`,
    all of it: candidates, solver, score and solve."""
    pairs = candidate_pairs(local, index)
    return clipper_core(clipper_solver(clipperpy), columns(local), columns(global_map), pairs)


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


# ---------------------------------------------------------------------------------------------
# Timing helpers
def best_of(
    repeats: int,
    run: Callable[..., object],
    setup: Callable[[], tuple] = tuple,
    budget_ms: float = BUDGET_MS,
) -> tuple[float, object]:
    """The smallest wall time (ms) of `repeats` runs of `run(*setup())` (setup untimed), and
    the last run's value; fewer runs once they have taken `budget_ms` in all (at least one:
    a run of seconds is long enough not to need the smallest of several)."""
    times, value = [], None
    for _ in range(repeats):
        arguments = setup()
        began = time.perf_counter()
        value = run(*arguments)
        times.append((time.perf_counter() - began) * 1e3)
        if sum(times) > budget_ms:
            break
    return min(times), value


def fresh(local: ObjectMap) -> ObjectMap:
    """A copy of `local` made of new objects: a repeat must not find the clouds that an
    earlier repeat prepared for the same objects (a robot's detections are new each time)."""
    return ObjectMap([o.replace() for o in local], up=local.up, name=local.name)


def feed(localizer: Localizer, objects: list) -> None:
    """Objects fed without an answer: `Localizer.add`, or `update(..., answer=False)` in the
    checkouts from before it (`--against` an older commit)."""
    if hasattr(localizer, "add"):
        localizer.add(objects)
    else:
        localizer.update(objects, answer=False)


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
            feed(localizer, batch)
        began = time.perf_counter()
        localizer.update(batches[-1])
        times.append((time.perf_counter() - began) * 1e3)
    return min(times)


# ---------------------------------------------------------------------------------------------
# The cases, written once (this checkout), read by every measured process
def maps() -> dict[str, ObjectMap]:
    """The real maps (or two simulated buildings when the real samples are absent)."""
    data = real_data_dir()
    if data is None:
        print("real samples not found (set SEMLOC_DATA): simulated buildings instead")
        return {"building-a": layout(120, seed=1), "building-b": layout(120, seed=2)}
    return variant_maps(data)


def write_cases(
    folder: Path,
    full_maps: dict[str, ObjectMap],
    views: int,
    merges: int,
    merge_sizes: tuple[int, ...],
    seed: int,
    building: ObjectMap | None = None,
) -> int:
    """Write the view and merge cases (map files and `cases.json`) to `folder`; their number.
    Merges also run on `building` (larger sessions than the real maps hold)."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_align import second_session  # only this process builds cases

    rng = np.random.default_rng(seed)
    entries: list[dict] = []
    for name, full in full_maps.items():
        global_path = save_map(full, folder / f"{name}.json")
        for k in SIZES:
            for v in range(views):
                case = make_case(full, ("clean", "noisy")[v % 2], k, rng)
                local_path = save_map(case.local, folder / f"{name}-view{k}-{v}.json")
                entries.append(_entry("view", k, global_path, local_path, case.truth))
    sources = {**full_maps, **({"building-400": building} if building is not None else {})}
    for size in merge_sizes:
        for name, full in sources.items():
            if size > len(full):
                continue
            for m in range(merges):
                case = second_session(full, size, ("clean", "noisy")[m % 2], rng)
                stem = folder / f"{name}-merge{size}-{m}"
                first = save_map(case.first, f"{stem}-first.json")
                second = save_map(case.second, f"{stem}-second.json")
                entries.append(_entry("merge", size, first, second, case.truth))
    (folder / "cases.json").write_text(json.dumps(entries))
    return len(entries)


def _entry(kind: str, size: int, global_path: Path, local_path: Path, truth) -> dict:
    return {"kind": kind, "size": size, "global": str(global_path), "local": str(local_path),
            "truth": np.asarray(truth).tolist()}  # fmt: skip


# ---------------------------------------------------------------------------------------------
# One process's measurements
@dataclass
class Measured:
    """One case in one process: times in ms (the smallest of the repeats; None: not run)."""

    kind: str  # "view" (semloc.localize) or "merge" (semloc.align)
    size: int  # objects in the view or second session
    semloc_ms: float
    file_ms: float  # semloc from the view's file to the answer
    semloc_ok: bool
    update_ms: float | None = None  # views: the last keyframe's update alone
    nodes: int = 0  # candidate associations: CLIPPER's graph nodes
    clipper_ms: float | None = None  # score + solve
    clipper_file_ms: float | None = None  # file read, candidates, score + solve, pose
    clipper_ok: bool | None = None


class Worker:
    """Measures the cases of one folder in this process: the first maps held (loaded and
    prepared once, each with its candidate index), semloc and CLIPPER warmed up."""

    def __init__(self, folder: Path, clipperpy, repeats: int, max_nodes: int = MAX_NODES) -> None:
        self.entries = json.loads((Path(folder) / "cases.json").read_text())
        self.clipperpy, self.repeats, self.max_nodes = clipperpy, repeats, max_nodes
        self.maps: dict[str, ObjectMap] = {}
        self.indexes: dict[str, CandidateIndex] = {}

    def held(self, path: str) -> tuple[ObjectMap, CandidateIndex]:
        """The first map at `path`, loaded and prepared once, and its candidate index."""
        if path not in self.maps:
            self.maps[path] = load_map(path)
            Localizer(self.maps[path]).prepare()
            self.indexes[path] = CandidateIndex(self.maps[path], AssociationConfig())
        return self.maps[path], self.indexes[path]

    def run(self) -> list[Measured]:
        """Every case, after one untimed case of each kind (loading, thread start-up)."""
        warm_up()
        for kind in ("view", "merge"):
            first = next((e for e in self.entries if e["kind"] == kind), None)
            if first is not None:
                self.measure(first, repeats=1)
        measured = []
        for n, entry in enumerate(self.entries):
            measured.append(self.measure(entry))
            if (n + 1) % 20 == 0:
                print(f"{n + 1} of {len(self.entries)} cases", file=sys.stderr, flush=True)
        return measured

    def measure(self, entry: dict, repeats: int | None = None) -> Measured:
        """semloc and CLIPPER on one case."""
        repeats = repeats or self.repeats
        global_map, index = self.held(entry["global"])
        local, truth = load_map(entry["local"]), np.array(entry["truth"])
        answer = localize if entry["kind"] == "view" else semloc.align
        ms, result = best_of(repeats, lambda c: answer(global_map, c), lambda: (fresh(local),))
        file_ms, _ = best_of(repeats, lambda: answer(global_map, load_map(entry["local"])))
        out = Measured(entry["kind"], entry["size"], ms, file_ms, _ok(result.pose, truth))
        if entry["kind"] == "view":
            out.update_ms = last_update_ms(global_map, local, repeats)
        pairs = candidate_pairs(local, index)
        out.nodes = len(pairs)
        if self.clipperpy is not None and len(pairs) <= self.max_nodes:
            selected = self.clipper(out, entry, repeats)
            out.clipper_ok = _ok(pose_of(global_map, local, selected), truth)
        return out

    def clipper(self, out: Measured, entry: dict, repeats: int) -> np.ndarray:
        """CLIPPER's core (score + solve) and its file-to-answer time, into `out`; the
        associations it selected."""
        global_map, index = self.held(entry["global"])
        local = load_map(entry["local"])
        arguments = (columns(local), columns(global_map), candidate_pairs(local, index))
        out.clipper_ms, selected = best_of(
            repeats, clipper_core, lambda: (clipper_solver(self.clipperpy), *arguments)
        )
        out.clipper_file_ms, _ = best_of(repeats, self.clipper_from_file, lambda: (entry,))
        return selected

    def clipper_from_file(self, entry: dict) -> np.ndarray | None:
        """CLIPPER from the view's file to a pose: read, candidates, score + solve, pose."""
        global_map, index = self.held(entry["global"])
        local = load_map(entry["local"])
        selected = clipper_associate(self.clipperpy, global_map, local, index)
        return pose_of(global_map, local, selected)


def _ok(pose: np.ndarray | None, truth: np.ndarray) -> bool:
    return pose is not None and bool(is_success(pose, truth))


# ---------------------------------------------------------------------------------------------
# Processes: this checkout, and another one in turn
def run_worker(folder: Path, args: argparse.Namespace, tree: str | None = None) -> list[Measured]:
    """The cases of `folder` measured in a new process; `tree`: the checkout whose src/ it
    imports semloc from (default: as this process does)."""
    command = [sys.executable, str(Path(__file__).resolve()), "--worker", str(folder)]
    command += ["--repeats", str(args.repeats), "--max-nodes", str(args.max_nodes)]
    if args.clipper is not None:
        command += ["--clipper", str(args.clipper)]
    env = dict(os.environ)
    if tree is not None:
        env["PYTHONPATH"] = os.pathsep.join([str(Path(tree).resolve() / "src"),
                                             env.get("PYTHONPATH", "")])  # fmt: skip
    done = subprocess.run(command, stdout=subprocess.PIPE, text=True, check=False, env=env)
    if done.returncode != 0:
        raise SystemExit(f"worker for {tree or 'this checkout'} failed ({done.returncode})")
    return [Measured(**raw) for raw in json.loads(done.stdout.strip().splitlines()[-1])]


def best_of_rounds(rounds: list[list[Measured]]) -> list[Measured]:
    """Per case, the smallest of each time over the rounds (the same cases in each)."""
    best = []
    for runs in zip(*rounds, strict=True):
        merged = asdict(runs[0])
        for f in fields(Measured):
            if f.name.endswith("_ms"):
                values = [getattr(r, f.name) for r in runs if getattr(r, f.name) is not None]
                merged[f.name] = min(values) if values else None
        best.append(Measured(**merged))
    return best


# ---------------------------------------------------------------------------------------------
# Tables
def _median(values: list[float | None], digits: int = 2) -> str:
    kept = [v for v in values if v is not None]
    return f"{np.median(kept):.{digits}f}" if kept else "-"


def _ratio(cases: list[Measured], mine: str, theirs: str) -> float | None:
    """Median over the cases (where both ran) of `mine` ÷ `theirs`."""
    pairs = [(getattr(c, mine), getattr(c, theirs)) for c in cases]
    kept = [a / b for a, b in pairs if a is not None and b]
    return float(np.median(kept)) if kept else None


def _groups(measured: list[Measured], kind: str) -> list[tuple[str, list[Measured]]]:
    """The cases of `kind` by size, then all of them."""
    cases = [m for m in measured if m.kind == kind]
    sizes = sorted({m.size for m in cases})
    return [(str(s), [m for m in cases if m.size == s]) for s in sizes] + [("all", cases)]


def table(measured: list[Measured], kind: str, with_clipper: bool) -> str:
    """One checkout's table of views or merges, per size and over all of them."""
    what = "semloc.localize" if kind == "view" else "semloc.align"
    header = ["objects", "cases", f"{what} ms", "file → answer ms", "semloc success"]
    header += ["one update ms"] if kind == "view" else []
    if with_clipper:
        header += ["candidates", "CLIPPER score + solve ms", "CLIPPER file → answer ms",
                   "CLIPPER success", "core ratio", "file-to-answer ratio"]  # fmt: skip
    lines = ["| " + " | ".join(header) + " |", "|---" * len(header) + "|"]
    for size, cases in _groups(measured, kind):
        cells = [size, str(len(cases)), _median([c.semloc_ms for c in cases]),
                 _median([c.file_ms for c in cases]),
                 f"{np.mean([c.semloc_ok for c in cases]):.2f}"]  # fmt: skip
        if kind == "view":
            cells.append(_median([c.update_ms for c in cases]))
        if with_clipper:
            ran = [c for c in cases if c.clipper_ms is not None]
            ok = f"{np.mean([c.clipper_ok for c in ran]):.2f}" if ran else "-"
            ran_note = "" if len(ran) == len(cases) else f" ({len(ran)} ran)"
            cells += [_median([c.nodes for c in cases], 0), _median([c.clipper_ms for c in ran], 3),
                      _median([c.clipper_file_ms for c in ran], 3), ok + ran_note,
                      _times(_ratio(ran, "semloc_ms", "clipper_ms")),
                      _times(_ratio(ran, "file_ms", "clipper_file_ms"))]  # fmt: skip
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _times(ratio: float | None) -> str:
    return "-" if ratio is None else f"{ratio:.1f}×"


def paired_table(this: list[Measured], other: list[Measured], with_clipper: bool) -> str:
    """This checkout against the other one on the same cases: time ratios this ÷ other, and
    each one's core and file-to-answer ratios against CLIPPER."""
    header = ["kind", "objects", "answer this ÷ other", "file → answer this ÷ other"]
    if with_clipper:
        header += ["core ratio this", "core ratio other", "file ratio this", "file ratio other"]
    lines = ["| " + " | ".join(header) + " |", "|---" * len(header) + "|"]
    for kind in ("view", "merge"):
        mine, theirs = dict(_groups(this, kind)), dict(_groups(other, kind))
        for size, cases in mine.items():
            if not cases:
                continue
            pairs = list(zip(cases, theirs[size], strict=True))
            cells = [kind, size, _quotient(pairs, "semloc_ms"), _quotient(pairs, "file_ms")]
            if with_clipper:
                for ours, clippers in (("semloc_ms", "clipper_ms"), ("file_ms", "clipper_file_ms")):
                    cells += [
                        _times(_ratio(side, ours, clippers)) for side in (cases, theirs[size])
                    ]
            lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _quotient(pairs: list[tuple[Measured, Measured]], name: str) -> str:
    """Median over the cases of this checkout's time ÷ the other's."""
    return f"{np.median([getattr(a, name) / getattr(b, name) for a, b in pairs]):.2f}"


def report(measured: list[Measured], with_clipper: bool) -> str:
    """One checkout's two tables."""
    return "\n\n".join([
        "Few-object views (semloc.localize)", table(measured, "view", with_clipper),
        "Map merges (semloc.align)", table(measured, "merge", with_clipper),
    ])  # fmt: skip


FOOTNOTE = (
    "core ratio: median over the cases of semloc's answer time (objects in memory) ÷ CLIPPER's "
    "score + solve; file-to-answer ratio: the same from the view's file (read, candidates, "
    "CLIPPER, closed-form pose); candidates: median number of CLIPPER's graph nodes"
)


# ---------------------------------------------------------------------------------------------
def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--clipper", type=Path, default=None)
    parser.add_argument("--views", type=int, default=20, help="views per map and size")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--merges", type=int, default=2, help="merges per map and size")
    parser.add_argument("--merge-sizes", type=int, nargs="*", default=list(MERGE_SIZES))
    parser.add_argument("--max-nodes", type=int, default=MAX_NODES,
                        help="CLIPPER runs on cases with at most this many candidates")  # fmt: skip
    parser.add_argument("--against", metavar="TREE", help="also measure this other checkout")
    parser.add_argument("--rounds", type=int, default=1, help="processes per checkout, in turn")
    parser.add_argument("--worker", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    clipperpy, why = load_clipper(args.clipper)
    if args.worker is not None:
        measured = Worker(args.worker, clipperpy, args.repeats, args.max_nodes).run()
        print(json.dumps([asdict(m) for m in measured]))
        return
    start = time.perf_counter()
    print(omp_note())
    print(f"CLIPPER: {why}; its columns are left out" if clipperpy is None else
          f"CLIPPER: {Path(clipperpy.__file__).parent}")  # fmt: skip
    with tempfile.TemporaryDirectory(prefix="bench-clipper-") as folder:
        building = layout(400, seed=1, points_per_object=64) if args.merge_sizes else None
        count = write_cases(Path(folder), maps(), args.views, args.merges,
                            tuple(args.merge_sizes), args.seed, building)  # fmt: skip
        print(f"{count} cases written", flush=True)
        trees = [None] + ([args.against] if args.against else [])
        rounds: dict[str | None, list[list[Measured]]] = {tree: [] for tree in trees}
        for r in range(args.rounds):
            for tree in trees:  # in turn: the machine's slow spells fall on both
                rounds[tree].append(run_worker(Path(folder), args, tree))
                print(f"round {r + 1}: {tree or 'this checkout'} done", flush=True)
    best = {tree: best_of_rounds(runs) for tree, runs in rounds.items()}
    with_clipper = clipperpy is not None
    for tree, measured in best.items():
        print(f"\n## {'this checkout' if tree is None else tree}\n")
        print(report(measured, with_clipper))
    if args.against:
        print(f"\n## this checkout ÷ {args.against} (same cases, {args.rounds} rounds each)\n")
        print(paired_table(best[None], best[args.against], with_clipper))
    print(f"\n({FOOTNOTE}; run time {time.perf_counter() - start:.0f} s)")


if __name__ == "__main__":
    main()
