"""Run the benchmark in parallel with Dask and write its outputs.

`run_benchmark(config, out)` simulates the sequences (one Dask task each), then runs every
(sequence, start, map kind, method) chain of attempts as a task on a `LocalCluster` (one
single-threaded worker process per core by default) or on an existing cluster
(`scheduler="tcp://host:8786"`, whose workers must be able to import semloc), with a rich
progress bar.  Chains start longest first (FPFH + RANSAC, then the other baselines, then
semloc), so that the workers finish together; the FPFH index of each global map is built once
(a task of its own) and shared by all workers.  Rows are sorted before writing, so the outputs
do not depend on completion order: for a fixed seed everything except the `ms` column is
reproducible.

Outputs (all or none: built beside `out` and moved in at the end, report.md last): results.csv,
hypotheses.csv, ablation.csv, the PNG figures, config.json and report.md; with `real_walks` also
those of `semloc.eval.realwalks`.
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from semloc.baselines import METHODS
from semloc.eval.datasets import real_data_dir
from semloc.eval.protocol import (
    NIGHT,
    REAL_PAIRS,
    Attempt,
    BenchConfig,
    bench_kinds,
    conditions,
    run_at_night,
    run_attempts,
    run_real_attempt,
    simulate,
    start_keyframes,
    with_night_rows,
)  # fmt: skip
from semloc.eval.report import write_outputs
from semloc.io.interrupts import children_spared, ignore_sigint, interrupts_deferred
from semloc.io.output import staged_folder

_ONE_THREAD = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


@dataclass
class BenchOutput:
    rows: list[dict]
    hypotheses: list[dict]
    ablation: list[dict]
    files: list[Path]
    seconds: float
    real_walks: list[dict] | None = None  # rows of real_walks.csv with --real-walks


# Rough relative cost of one chain per method (seconds per attempt on the quick run): chains
# are started longest first, so that the last ones to finish are short and the workers end
# together instead of one long FPFH chain running alone at the end.
_COST = {"fpfh-ransac": 10.0, "fcgf-dense": 6.0, "sift": 2.0, "svl": 2.0, "clipper": 1.2,
         "random-walk": 1.2, "segmatch": 1.0, "semloc": 0.6}  # fmt: skip


def _cost(method: str) -> float:
    return _COST.get(method, 1.0)


def _sequence_task(config: BenchConfig, index: int):
    for var in _ONE_THREAD:
        os.environ[var] = "1"
    return simulate(config, index)


def _fpfh_index_task(seq, kind: str):
    """The FPFH baseline's index of one global map, built once for all workers."""
    from semloc.baselines.fpfh import global_index

    return global_index(seq.global_maps[kind])


def _fpfh_chain_task(seq, job: Attempt, index):
    from semloc.baselines.fpfh import FpfhConfig, share_index

    kind = conditions(job.map_kind)[0]  # the night queries use the reconstruction map
    share_index(seq.global_maps[kind], index, FpfhConfig(**job.settings))
    return run_attempts(seq, job)


def _real_data() -> str | None:
    """The real samples' folder when the importers' data is present (all pairs' files)."""
    folder = real_data_dir()
    if folder is None:
        return None
    needed = [folder / "3rscan_subscans" / "scene_1", folder / "3rscan_subscans" / "scene_2",
              folder / "scan2cad" / "scene0470_00"]  # fmt: skip
    return str(folder) if all(p.exists() for p in needed) else None


def _order(row: dict, methods: list[str]) -> tuple:
    method = row["method"]
    position = methods.index(method) if method in methods else len(methods)
    return (position, method, row["map_kind"], row["sequence"], row["start"], row["offset"],
            row.get("rank", 0))  # fmt: skip


def plan(config: BenchConfig, n_keyframes: int) -> list[Attempt]:
    """All chains of attempts: the comparison (with the night queries of the image methods:
    `bench_kinds`, `run_at_night`), then the γ ablation (semloc only)."""
    jobs = []
    for index in range(config.sequences):
        starts = start_keyframes(config, index, n_keyframes, config.starts)
        for start in starts:
            for kind in bench_kinds(config):
                for method in config.methods:
                    if kind != NIGHT or run_at_night(method):
                        jobs.append(Attempt(index, start, kind, method))
        ablation = start_keyframes(config, index, n_keyframes, config.ablation_starts)
        kind = "reconstruction" if "reconstruction" in config.map_kinds else config.map_kinds[0]
        for start in ablation if config.ablation_starts else []:
            for gamma in config.gammas:
                settings = {"gamma": gamma, "top_k": config.ablation_top_k}
                label = f"semloc gamma={gamma:g}"
                jobs.append(Attempt(index, start, kind, "semloc", label, settings, ablation=True))
    return jobs


def dask_setup(worker: object) -> None:
    """Dask preload of each local worker process: it logs nothing below CRITICAL, like the
    scheduler, and ignores SIGINT.  The workers share the command's stderr: what they log
    lands among its output, also after its last line (an interrupt's heartbeat traceback,
    matplotlib building its font cache), while a task's error reaches the caller through its
    future anyway.  Ctrl-C in a terminal reaches the whole process group: a worker that took
    it printed a KeyboardInterrupt traceback; the command closes its workers itself."""
    for name in ("", "distributed"):  # the root logger, and distributed's own level
        logging.getLogger(name).setLevel(logging.CRITICAL)
    ignore_sigint()


def run_benchmark(
    config: BenchConfig,
    out: str | Path,
    scheduler: str | None = None,
    workers: int | None = None,
    progress: bool = True,
    log: Callable[[str], None] | None = None,
) -> BenchOutput:
    """Run the whole benchmark (see the module docstring) and write the outputs into `out`."""
    from dask.distributed import Client, LocalCluster, as_completed
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeElapsedColumn

    begin = time.perf_counter()
    if config.real_walks:
        from semloc.eval import realwalks  # open3d: only for the real walks

        realwalks.real_walk_data()  # missing scans: say so before the long run
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ValueError(f"{out}: exists and is not a folder")
    for var in _ONE_THREAD:
        os.environ.setdefault(var, "1")
    cluster = client = None
    try:
        if scheduler:
            try:
                client = Client(scheduler, timeout=15)
            except (OSError, TimeoutError, ValueError) as exc:
                message = f"cannot connect to the Dask scheduler {scheduler!r}: {exc}"
                raise ValueError(message) from None
        else:
            # an interrupt waits until the cluster is up: cut half-way, its worker processes
            # and their watcher threads could not be closed (a crash at interpreter exit).
            # A terminal's Ctrl-C also reaches the workers: they start with SIGINT blocked (one
            # cut in its start printed a traceback, or failed the cluster: "Nanny failed to
            # start", which the deferral would report as the interrupt it is)
            with children_spared():
                cluster = LocalCluster(
                    n_workers=workers or os.cpu_count() or 1, threads_per_worker=1,
                    processes=True, dashboard_address=":0", silence_logs=logging.CRITICAL,
                    preload=[__name__],
                )  # fmt: skip
                client = Client(cluster)
        first = 1000.0  # the simulations run before any chain
        sequences = [client.submit(_sequence_task, config, i, pure=False, priority=first)
                     for i in range(config.sequences)]  # fmt: skip
        indices = {}  # (sequence, map kind) -> FPFH index: one per map, not one per worker
        if "fpfh-ransac" in config.methods:
            indices = {(i, kind): client.submit(_fpfh_index_task, seq, kind, pure=False,
                                                priority=first / 2)
                       for i, seq in enumerate(sequences) for kind in config.map_kinds}  # fmt: skip
        futures = {}
        for job in sorted(plan(config, config.keyframes), key=lambda j: -_cost(j.method)):
            seq, cost = sequences[job.sequence], _cost(job.method)
            if job.method == "fpfh-ransac" and not job.settings:
                index = indices[job.sequence, conditions(job.map_kind)[0]]
                future = client.submit(_fpfh_chain_task, seq, job, index, pure=False,
                                       priority=cost)  # fmt: skip
            else:
                future = client.submit(run_attempts, seq, job, pure=False, priority=cost)
            futures[future] = job.ablation
        data = _real_data() if config.real else None
        for pair in REAL_PAIRS if data else []:
            for method in (m for m in config.methods if not METHODS[m].images):  # no images
                future = client.submit(run_real_attempt, data, pair, method, pure=False,
                                       priority=_cost(method))  # fmt: skip
                futures[future] = False
        rows, hyps, ablation_rows = [], [], []
        columns = [
            "[progress.description]{task.description}", BarColumn(), MofNCompleteColumn(),
            TimeElapsedColumn(),
        ]  # fmt: skip
        with Progress(*columns, disable=not progress, transient=False) as bar:
            task = bar.add_task("relocalization attempts", total=len(futures))
            for future in as_completed(list(futures)):
                chain_rows, chain_hyps = future.result()
                if futures[future]:
                    ablation_rows += chain_rows
                else:
                    rows += chain_rows
                    hyps += chain_hyps
                bar.advance(task)
        if config.real_walks:
            real = realwalks.run_real_walks(client, config, progress)
    finally:
        # the close is not cut either: a cluster left half-closed has worker watcher threads
        # waiting without the GIL, and the interpreter's exit then aborted (a fatal error)
        with interrupts_deferred():
            if client is not None:
                client.close()
            if cluster is not None:
                cluster.close()
    if NIGHT in bench_kinds(config):
        rows, hyps = (with_night_rows(r, "reconstruction", NIGHT) for r in (rows, hyps))
    rows.sort(key=lambda r: _order(r, config.methods))
    hyps.sort(key=lambda r: _order(r, config.methods))
    ablation_rows.sort(key=lambda r: _order(r, config.methods))
    seconds = time.perf_counter() - begin
    with staged_folder(out, index="report.md") as stage:  # all files or none
        staged = write_outputs(stage, config, rows, hyps, ablation_rows, seconds)
        if config.real_walks:
            staged += realwalks.write_outputs(stage, config, real["rows"], real["hypotheses"],
                                              real["traces"])  # fmt: skip
    files = [out / f.relative_to(stage) for f in staged]
    if config.real_walks:
        return BenchOutput(rows, hyps, ablation_rows, files, seconds, real["rows"])
    return BenchOutput(rows, hyps, ablation_rows, files, seconds)
