"""Map-to-map alignment (`semloc.align`): success, correspondences, time and memory by size.

Second sessions are cut from a first map: the `n` objects nearest to a random object of it;
the first map keeps `overlap` (uniform 30-100 %) of them and loses the others, those beyond a
line across the second session's area (the first session did not get that far); the first map
covers the second session's area and as far again around it (a building of identical rooms
holds twins of everything beyond), all of them moved into a random frame of the second session
(4-DoF about gravity; its origin within 3 m of its area, as where a robot started).  Variants: `clean`; `noisy` (centres and points shifted 0.1-0.3 m
sideways, 5 % wrong labels); `moved` (a fifth of the shared objects moved 0.5-2 m with a new
heading before the second session).  First maps: the real samples (ScanNet scene0000_00, Replica
office4, 3RScan scene_1; with their points) and simulated buildings of 400 objects (64 box
points per object) for the larger sessions.

Success: the transform within 15° / 0.5 m, counted over the cases whose overlap holds at least
5 unmoved objects; the pose is the best place's whatever the status.  The status apart:
`localized` (the share answered as sure), `wrong` (the share answered `localized` at a wrong
pose: a false answer) and `ambiguous` (the share held back as not sure, right pose or not).
`where the truth fits best`: success over the cases where no wrong place of the answer fits B
as well as the truth does (`semloc.alignment.place_scores`: each pose grown by guided matching,
its agreeing pairs scored; where a wrong place fits as well the data cannot tell them apart),
and how many cases that leaves.  Correspondences: precision and recall of the best
hypothesis' pairs against the unmoved shared objects.  Times: CPU ms of `semloc.align` with the first map prepared once
(a robot or server that holds it), one core; peak MB: tracemalloc's peak during one alignment.
The CLIPPER-style baseline (`semloc.baselines.clipper`, B as one local map, unchanged) runs on
every case of the real samples and on the first `--clipper-cases` scored cases of each size and
variant on the buildings (its dense consistency graph of thousands of same-label candidates
takes minutes there), each run in a forked process bounded by `--clipper-budget` CPU seconds
(RLIMIT_CPU) and `--clipper-memory` MB of resident growth (watched every 10 ms): its time is process CPU time on the same
core as semloc's, its peak MB the resident peak above the process' start.  A run over the
budget counts as at least the time it took (the median reads `> t`, the ratio `< r`); a run
stopped by the memory bound reads `out of memory`, its peak `> bound`.  The ratio is semloc's
median over the cases the baseline ran on ÷ the baseline's median.

    PYTHONPATH=src python benchmarks/bench_align.py [--trials 5] [--sizes 15 30 60 150 300]
        [--no-real] [--no-clipper] [--clipper-cases 1] [--clipper-budget 120]
        [--clipper-memory 6144] [--markdown TABLE.md]
"""

from __future__ import annotations

import argparse
import math
import multiprocessing
import os
import resource
import signal
import sys
import time
import tracemalloc
from dataclasses import dataclass

import numpy as np

import semloc
from semloc.alignment import place_scores
from semloc.baselines.clipper import ClipperBaseline
from semloc.eval.datasets import real_data_dir
from semloc.eval.success import is_success
from semloc.eval.variants import variant_maps
from semloc.localizer import Localizer
from semloc.maps import ObjectMap
from semloc.sim.layouts import layout
from semloc.transforms import yaw_pose

VARIANTS = ("clean", "noisy", "moved")
MIN_SHARED = 5


@dataclass
class Case:
    first: ObjectMap
    second: ObjectMap
    truth: np.ndarray  # T_first_second
    pairs: set[tuple[str, str]]  # (first id, second id) of the unmoved shared objects


@dataclass
class Outcome:
    source: str
    size: int
    variant: str
    scored: bool  # the overlap holds >= MIN_SHARED unmoved objects
    success: bool
    status: str
    precision: float
    recall: float
    ms: float
    clipper: ClipperRun | None = None
    twin: bool = False  # a wrong place of the answer fits B at least as well as the truth


def second_session(full: ObjectMap, n: int, variant: str, rng: np.random.Generator) -> Case:
    """A second session of `n` objects of `full` in its own frame (see the module docstring)."""
    centre = full.positions[rng.integers(len(full))]
    near = np.argsort(np.linalg.norm(full.positions - centre, axis=1), kind="stable")[:n]
    overlap = rng.uniform(0.3, 1.0)
    side = full.positions[near, :2] @ _direction(rng)  # the first session did not get that far
    beyond = near[np.argsort(side, kind="stable")[::-1][: round((1 - overlap) * len(near))]]
    only_second = set(beyond.tolist())
    # the first session covers the second one's area and as far again around it, not the whole
    # building: the rest of a building of identical rooms would hold twins of every view
    reach = 2.0 * np.linalg.norm(full.positions[near] - centre, axis=1).max()
    covered = np.linalg.norm(full.positions - centre, axis=1) <= reach
    first = full.with_objects(o for i, o in enumerate(full) if covered[i] and i not in only_second)
    # the second session's frame starts within 3 m of its area, with any heading
    origin = centre + np.append(rng.uniform(-3, 3, 2), -centre[2])
    truth = yaw_pose(rng.uniform(-np.pi, np.pi), origin)
    to_second = np.linalg.inv(truth)
    labels = sorted(set(full.labels.tolist()))
    objects, pairs = [], set()
    for k, i in enumerate(near.tolist()):
        obj = full[i]
        moved = variant == "moved" and i not in only_second and rng.random() < 0.2
        if moved:
            step = np.append(_direction(rng) * rng.uniform(0.5, 2.0), 0.0)
            spin = yaw_pose(rng.uniform(-np.pi, np.pi))
            obj = obj.transformed(
                yaw_pose(0.0, obj.position + step) @ spin @ yaw_pose(0.0, -obj.position)
            )
        if variant == "noisy":
            obj = obj.transformed(
                yaw_pose(0.0, np.append(_direction(rng) * rng.uniform(0.1, 0.3), 0))
            )
            if rng.random() < 0.05:
                obj = obj.replace(label=str(rng.choice([x for x in labels if x != obj.label])))
        obj = obj.transformed(to_second).replace(id=f"s{k}")
        if i not in only_second and not moved:
            pairs.add((full[i].id, obj.id))
        objects.append(obj)
    second = ObjectMap(objects, up=full.up, name="second")
    return Case(first, second, truth, pairs)


def _direction(rng: np.random.Generator) -> np.ndarray:
    angle = rng.uniform(-np.pi, np.pi)
    return np.array([np.cos(angle), np.sin(angle)])


def run_case(source: str, case: Case, variant: str, clipper: Bound | None) -> Outcome:
    Localizer(case.first).prepare()
    start = time.process_time()
    result = semloc.align(case.first, case.second)
    ms = (time.process_time() - start) * 1e3
    found = set(result.hypotheses[0].pairs) if result.hypotheses else set()
    right = len(found & case.pairs)
    outcome = Outcome(
        source, len(case.second), variant, len(case.pairs) >= MIN_SHARED,
        result.pose is not None and is_success(result.pose, case.truth), result.status,
        right / len(found) if found else 1.0, right / len(case.pairs) if case.pairs else 1.0, ms,
    )  # fmt: skip
    wrong = [h.pose for h in result.hypotheses
             if h.pose is not None and not is_success(h.pose, case.truth)]  # fmt: skip
    if wrong:  # does a wrong place fit B as well as the truth? (then the data cannot tell)
        truth, *others = place_scores(case.first, case.second, [case.truth, *wrong])
        outcome.twin = max(others) >= truth
    if clipper is not None:
        outcome.clipper = run_clipper(case, clipper)
    return outcome


@dataclass(frozen=True)
class Bound:
    """What one run of the baseline may take: CPU seconds and MB of memory (None: no bound)."""

    seconds: float | None = None
    mb: float | None = None


@dataclass
class ClipperRun:
    """One run of the baseline: `ms` its CPU time, or at least that when `over` says why not
    finished (`time`: over the CPU budget; `memory`: an allocation over the memory bound)."""

    ms: float
    success: bool = False
    peak_mb: float = float("nan")  # the process's resident peak above its start
    over: str | None = None
    bound_mb: float = float("nan")  # the memory bound, when `over` is `memory`


def warm_clipper(full: ObjectMap) -> None:
    """Loads what the baseline uses (lazy imports, compiled code) in this process, so that the
    forked runs time the baseline, not its loading."""
    case = second_session(full, 8, "clean", np.random.default_rng(2))
    ClipperBaseline(case.first, local_up=case.second.up).update(list(case.second))


def run_clipper(case: Case, bound: Bound) -> ClipperRun:
    """The baseline on `case` (B as one local map) in a forked process bounded by `bound`: CPU
    time as semloc's (process CPU time on the same core), peak memory as the resident peak.
    The memory bound is watched from here, on the child's resident size: a limit on its address
    space would miss the arrays it places in the free heap inherited from this process."""
    context = multiprocessing.get_context("fork")
    receive, send = context.Pipe(duplex=False)
    child = context.Process(target=_clipper_child, args=(case, bound, send), daemon=True)
    child.start()
    send.close()
    deadline = None if bound.seconds is None else 5 * bound.seconds + 60  # wall time: contention
    began = time.monotonic()
    started: tuple[float, float] | None = None  # the child's CPU seconds and resident bytes
    answer: ClipperRun | None = None
    while answer is None:  # messages: the start, then the answer
        if deadline is not None and time.monotonic() - began > deadline:
            break
        if not receive.poll(_WATCH_SECONDS):
            if started is not None and bound.mb is not None:
                answer = _over_memory(child.pid, started, bound.mb)
            continue
        try:
            message = receive.recv()
        except EOFError:
            break
        if isinstance(message, ClipperRun):
            answer = message
        else:
            started = message
    if answer is None:  # killed by the CPU limit (SIGXCPU), or out of wall time
        cpu = _cpu_seconds(child.pid) if child.is_alive() else None
        spent = cpu if cpu is not None else (bound.seconds or 0.0)
        answer = ClipperRun((spent - (started[0] if started else 0.0)) * 1e3, over="time")
        if child.is_alive():
            child.kill()
        child.join()
        if child.exitcode not in (-signal.SIGXCPU, -signal.SIGKILL):
            answer.over = f"exit {child.exitcode}"
    if child.is_alive():  # stopped over the memory bound
        child.kill()
    child.join()
    receive.close()
    return answer


_WATCH_SECONDS = 0.01  # how often the child's resident size is read


def _over_memory(pid: int, started: tuple[float, float], mb: float) -> ClipperRun | None:
    """A run stopped over the memory bound when the child's resident size has grown by more
    than `mb` since its start, else None."""
    resident = _status("VmRSS", pid)
    if not resident - started[1] > mb * 2**20:
        return None
    cpu = _cpu_seconds(pid)
    ms = ((cpu if cpu is not None else started[0]) - started[0]) * 1e3
    peak = (max(_status("VmHWM", pid), resident) - started[1]) / 2**20
    return ClipperRun(ms, peak_mb=peak, over="memory", bound_mb=mb)


def _clipper_child(case: Case, bound: Bound, send) -> None:
    if bound.seconds is not None:
        limit = math.ceil(time.process_time() + bound.seconds)
        resource.setrlimit(resource.RLIMIT_CPU, (limit, limit + 5))
    rss = _reset_peak()
    start = time.process_time()
    send.send((start, rss))
    answer = ClipperBaseline(case.first, local_up=case.second.up).update(list(case.second))
    ms = (time.process_time() - start) * 1e3
    success = answer.pose is not None and is_success(answer.pose, case.truth)
    send.send(ClipperRun(ms, success, (_status("VmHWM") - rss) / 2**20))


def _status(key: str, pid: int | str = "self") -> float:
    """A size (bytes) from /proc/<pid>/status (nan if unknown)."""
    try:
        with open(f"/proc/{pid}/status") as status:
            for line in status:
                if line.startswith(key + ":"):
                    return float(line.split()[1]) * 1024
    except OSError:
        pass
    return float("nan")


def _reset_peak() -> float:
    """Resets the resident peak (VmHWM) to the resident size, which it returns."""
    try:
        with open("/proc/self/clear_refs", "w") as clear:
            clear.write("5")
    except OSError:
        pass
    return _status("VmRSS")


def _cpu_seconds(pid: int) -> float | None:
    try:
        with open(f"/proc/{pid}/stat") as stat:
            fields = stat.read().rpartition(")")[2].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return None


def peak_mb(case: Case) -> float:
    tracemalloc.start()
    semloc.align(case.first, case.second)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return peak / 2**20


def first_maps(real: bool, seed: int) -> dict[str, ObjectMap]:
    maps = {}
    data = real_data_dir() if real else None
    if data is not None:
        maps.update(variant_maps(data))
    for k in range(2):
        maps[f"building-{k}"] = layout(400, seed=seed + k, points_per_object=64)
    return maps


def table(outcomes: list[Outcome], memory: dict[int, float]) -> str:
    lines = [
        "| objects | variant | cases | success | where the truth fits best "
        "| localized / wrong / ambiguous "
        "| pairs precision / recall | median / p90 ms | peak MB "
        "| CLIPPER-style success (cases) | CLIPPER-style median ms | CLIPPER-style peak MB "
        "| time ÷ CLIPPER |",
        "|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for size in sorted({o.size for o in outcomes}):
        for variant in VARIANTS:
            group = [o for o in outcomes if (o.size, o.variant) == (size, variant) and o.scored]
            if not group:
                continue
            ms = [o.ms for o in group]
            lines.append(
                f"| {size} | {variant} | {len(group)} | {np.mean([o.success for o in group]):.0%} | "
                f"{_determined(group)} | {_statuses(group)} | "
                f"{np.mean([o.precision for o in group]):.0%} / {np.mean([o.recall for o in group]):.0%} | "
                f"{np.median(ms):.0f} / {np.percentile(ms, 90):.0f} | "
                f"{memory.get(size, float('nan')):.1f} | {_versus(group)} |"
            )
    return "\n".join(lines)


def _versus(group: list[Outcome]) -> str:
    """The baseline's cells over the cases it ran on: success (over those it finished; how many
    it ran on), median ms, peak MB, and semloc's median ms over the same cases ÷ its median.
    An unfinished run counts as at least the time it took: a median that is only bounded
    reads `> t`, the ratio `< r`; a run stopped by the memory bound makes the peak `> bound`
    and, when the median is not reached, the time `out of memory` (no ratio)."""
    versus = [o for o in group if o.clipper is not None]
    if not versus:
        return "- | - | - | -"
    runs = [o.clipper for o in versus]
    done = [r for r in runs if r.over is None]
    success = f"{np.mean([r.success for r in done]):.0%}" if done else "-"
    count = f"{len(versus)}" if len(done) == len(runs) else f"{len(done)} of {len(runs)} finished"
    exact = float(np.median([r.ms if r.over is None else np.inf for r in runs]))
    theirs = exact if np.isfinite(exact) else float(np.median([r.ms for r in runs]))
    mine = float(np.median([o.ms for o in versus]))
    bounded = "" if np.isfinite(exact) else "> "
    over_memory = [r for r in runs if r.over == "memory"]
    peaks = [r.peak_mb for r in done if np.isfinite(r.peak_mb)]
    peak = (
        f"> {min(r.bound_mb for r in over_memory):.0f}"
        if over_memory
        else (f"{np.median(peaks):.0f}" if peaks else "-")
    )
    if bounded and over_memory:  # stopped by the memory bound: its time says nothing
        return f"{success} ({count}) | out of memory | {peak} | -"
    ratio = f"{'< ' if bounded else ''}{mine / theirs:.2g}"
    return f"{success} ({count}) | {bounded}{theirs:.0f} | {peak} | {ratio}"


def _determined(group: list[Outcome]) -> str:
    """Success over the cases where no wrong place of the answer fits B as well as the truth
    (`place_scores`), and how many cases that leaves."""
    kept = [o for o in group if not o.twin]
    return f"{np.mean([o.success for o in kept]):.0%} ({len(kept)})" if kept else "-"


def _statuses(group: list[Outcome]) -> str:
    """The shares answered `localized`, `localized` at a wrong pose, and `ambiguous`."""
    localized = [o.status == "localized" for o in group]
    wrong = [o.status == "localized" and not o.success for o in group]
    ambiguous = [o.status == "ambiguous" for o in group]
    return f"{np.mean(localized):.0%} / {np.mean(wrong):.0%} / {np.mean(ambiguous):.0%}"


def slope(outcomes: list[Outcome], key: str = "ms", above: int = 30) -> float:
    """Log-log slope of the median `key` against the second map's size (sizes >= `above`)."""
    sizes = sorted({o.size for o in outcomes if o.size >= above})
    if len(sizes) < 2:
        return float("nan")
    medians = [np.median([getattr(o, key) for o in outcomes if o.size == s]) for s in sizes]
    return float(np.polyfit(np.log(sizes), np.log(medians), 1)[0])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=5, help="cases per map, size and variant")
    parser.add_argument("--sizes", type=int, nargs="+", default=[15, 30, 60, 150, 300])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--no-real", action="store_true", help="simulated buildings only")
    parser.add_argument("--no-clipper", action="store_true", help="semloc only")
    parser.add_argument(
        "--clipper-cases",
        type=int,
        default=1,
        help="the baseline's cases per size and variant on the buildings (the first scored ones; "
        "it runs on every real-sample case)",
    )
    parser.add_argument(
        "--clipper-budget",
        type=float,
        default=120.0,
        help="CPU seconds the baseline may take per case (0: no bound)",
    )
    parser.add_argument(
        "--clipper-memory",
        type=float,
        default=6144.0,
        help="MB the baseline may allocate per case (0: no bound)",
    )
    parser.add_argument("--markdown", help="also write the table to this file")
    args = parser.parse_args(argv)
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    start = time.perf_counter()
    rng = np.random.default_rng(args.seed)
    maps = first_maps(not args.no_real, args.seed)
    warm = second_session(maps["building-0"], 20, "clean", np.random.default_rng(1))
    semloc.align(warm.first, warm.second)  # loads the compiled code
    if not args.no_clipper:  # the baseline's too, before its runs are forked from this process
        warm_clipper(maps["building-0"])
    bound = Bound(args.clipper_budget or None, args.clipper_memory or None)
    outcomes, memory, on_buildings = [], {}, {}
    for size in args.sizes:
        for source, full in maps.items():
            if size > len(full):
                continue
            for variant in VARIANTS:
                for _ in range(args.trials):
                    case = second_session(full, size, variant, rng)
                    clipper = not args.no_clipper
                    if clipper and source.startswith("building"):
                        ran = on_buildings.get((size, variant), 0)
                        clipper = ran < args.clipper_cases and len(case.pairs) >= MIN_SHARED
                        on_buildings[(size, variant)] = ran + clipper
                    outcomes.append(run_case(source, case, variant, bound if clipper else None))
                    if size not in memory and source.startswith("building"):
                        memory[size] = peak_mb(case)
        print(f"done {size} objects", file=sys.stderr)
    report = "\n\n".join(
        [
            "`PYTHONPATH=src python benchmarks/bench_align.py "
            + " ".join(argv if argv is not None else sys.argv[1:])
            + "` (success at 15° / 0.5 m over the cases whose overlap holds >= 5 unmoved objects)",
            table(outcomes, memory),
            f"log-log slope of the median time against the second map's size (>= 30 objects): "
            f"{slope(outcomes):.2f}; cases not scored (overlap < 5 objects): "
            f"{sum(not o.scored for o in outcomes)}; run time {time.perf_counter() - start:.0f} s",
        ]
    )
    print(report)
    if args.markdown:
        from semloc.io import write_atomic

        write_atomic(args.markdown, report + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
