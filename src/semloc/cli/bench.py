"""`semloc bench`: the paper's evaluation protocol, semloc against the registered baselines."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from semloc.baselines import DEFAULT_METHODS, VARIANTS
from semloc.cli.app import MAX_SEED, app, console, fail
from semloc.cli.extras import need
from semloc.eval.protocol import BenchConfig
from semloc.eval.report import claims_table, summary_table
from semloc.eval.runner import run_benchmark


@app.command()
def bench(
    quick: Annotated[
        bool,
        typer.Option(
            "--quick", help="Small but meaningful subset (2 sequences x 3 starts): minutes."
        ),
    ] = False,
    out: Annotated[
        Path,
        typer.Option(
            "--output",
            "-o",
            help="Folder for results.csv, hypotheses.csv, the PNGs and report.md.",
        ),
    ] = Path("bench_out"),
    scheduler: Annotated[
        str | None,
        typer.Option(
            help="Address of an existing Dask scheduler (tcp://host:8786); default: a "
            "local cluster."
        ),
    ] = None,
    workers: Annotated[
        int | None,
        typer.Option(
            min=1, max=512, help="Worker processes of the local cluster (default: all cores)."
        ),
    ] = None,
    seed: Annotated[
        int,
        typer.Option(min=0, max=MAX_SEED, help="Seed of the worlds, start keyframes and methods."),
    ] = 0,
    methods: Annotated[
        str | None,
        typer.Option(
            help=f"Methods to compare, separated by commas (default: all of {', '.join(DEFAULT_METHODS)}); "
            f"opt-in: {', '.join(VARIANTS)} (semloc with the shape-descriptor gate)."
        ),
    ] = None,
    sequences: Annotated[
        int | None,
        typer.Option(
            min=0, max=1000, help="Simulated sequences (default 6; quick 2; 0: only the real data)."
        ),
    ] = None,
    starts: Annotated[
        int | None,
        typer.Option(min=1, max=1000, help="Random starts per sequence (default 8; quick 3)."),
    ] = None,
    progress: Annotated[bool, typer.Option(help="Show a progress bar.")] = True,
    night: Annotated[
        bool,
        typer.Option(
            help="Add the day / night pair: the reconstruction map (made by day) with the "
            "query images relit at night (the 'night' column; image methods such as SIFT "
            "are affected, object methods see the same objects)."
        ),
    ] = True,
    real_walks: Annotated[
        bool,
        typer.Option(
            "--real-walks",
            help="Also the protocol on camera walks through the real scans (ScanNet "
            "scene0000_00, Scan2CAD scene0470_00): real_walks.csv, .png, .md.",
        ),
    ] = False,
) -> None:
    """Reproduce the paper's comparison: semloc vs CLIPPER, random-walk, SegMatch, FPFH+RANSAC,
    SIFT.

    Attempts from random keyframes of simulated sequences (when > 2 objects
    are seen, then +15 and +30 keyframes) against reconstruction, CAD and
    dynamic global maps and the night queries, plus ablations over gamma and
    the local objects.
    """
    need("bench", "bench", "sim")
    methods = ",".join(DEFAULT_METHODS) if methods is None else methods
    chosen = [m.strip() for m in methods.split(",") if m.strip()]
    known = DEFAULT_METHODS + VARIANTS
    unknown = [m for m in chosen if m not in known]
    if unknown or not chosen:
        fail(f"--methods: unknown {unknown or methods!r}; choose from {','.join(known)}")
    if scheduler is not None and workers is not None:
        fail("--workers applies to the local cluster; leave it out with --scheduler")
    overrides: dict = {"seed": seed, "methods": list(dict.fromkeys(chosen))}
    if sequences is not None:
        overrides["sequences"] = sequences
    if starts is not None:
        overrides["starts"] = starts
    if "semloc" not in chosen:
        overrides["ablation_starts"] = 0
    overrides["real_walks"] = real_walks
    overrides["night"] = night
    config = BenchConfig.quick(**overrides) if quick else BenchConfig(**overrides)
    try:
        output = run_benchmark(config, out, scheduler, workers, progress=progress)
    except ValueError as exc:
        fail(str(exc))
    console.print(summary_table(output.rows, config.methods), soft_wrap=True)
    console.print(claims_table(output.rows, config.methods), soft_wrap=True)
    if output.real_walks is not None:
        console.print("real walks (real_walks.md):")
        console.print(summary_table(output.real_walks, config.methods), soft_wrap=True)
    console.print(f"{len(output.rows)} attempts in {output.seconds:.0f} s; wrote {out}/report.md")
