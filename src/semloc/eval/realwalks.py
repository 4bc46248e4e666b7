"""The paper's protocol on real geometry: camera walks through the real scans (`--real-walks`).

For each real scene (ScanNet scene0000_00: its reconstruction map; Scan2CAD scene0470_00: its
scan-derived reconstruction map and its CAD map) `real_walk_count` walks are rendered, detected
and fused (`semloc.sim.realscan.simulate_walk`); from `real_walk_starts` random start keyframes
of each walk every method relocalizes as in the simulated protocol (`run_attempts`: when more
than 2 objects are seen, then +15 and +30 keyframes).  Rows carry the map kind as "real
reconstruction", "real night" (the reconstruction map with the query images at night, with
`config.night`) or "real cad" and the walk as the sequence.  Image methods (SIFT) see the
scans' vertex colours and run against the reconstruction maps only (the CAD models have no
colours).  Besides the attempts, semloc runs incrementally over the first walk of each scene
for the top-2 score plot.

Outputs: real_walks.csv and real_walks_hypotheses.csv (the results/hypotheses columns),
real_walks.png (recall vs translation tolerance at top-10 and vs k), real_walks_scores.png and
real_walks.md (the recall table).
"""

from __future__ import annotations

import os
from pathlib import Path
from types import SimpleNamespace

from dask.distributed import as_completed
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeElapsedColumn

from semloc.baselines import METHODS
from semloc.eval.datasets import real_data_dir
from semloc.eval.images import has_images
from semloc.eval.protocol import (
    NIGHT,
    Attempt,
    BenchConfig,
    conditions,
    run_at_night,
    run_attempts,
    start_keyframes,
    with_night_rows,
)
from semloc.eval.recall import HYPOTHESIS_COLUMNS, RESULT_COLUMNS, format_rows
from semloc.eval.report import comparison_figure, summary_table
from semloc.io import write_atomic
from semloc.localizer import Localizer, LocalizerConfig
from semloc.pictures.viz import plot_scores, save_figure
from semloc.sim.realscan import load_real_scan, simulate_walk

SCENES = {
    "scene0000_00": ("scannet/scene0000_00", ("reconstruction",)),
    "scene0470_00": ("scan2cad/scene0470_00", ("reconstruction", "cad")),
}
"""Real scenes walked: folder under the data path, global map kinds localized against."""
PREFIX = "real "


def real_walk_data() -> Path:
    """The real-data folder holding every walked scene; ValueError saying what is missing."""
    folder = real_data_dir()
    if folder is None or not all((folder / path).is_dir() for path, _ in SCENES.values()):
        raise ValueError(
            f"--real-walks needs the real scans {', '.join(p for p, _ in SCENES.values())} under "
            "$SEMLOC_DATA or ../shared/data/real"
        )
    return folder


def walk_seed(config: BenchConfig, walk: int) -> int:
    return config.seed * 1000 + 500 + walk


def walk_sequence(data: str, scene: str, seed: int, n_keyframes: int):
    """One rendered, detected and fused walk through a real scene (a Dask task)."""
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[var] = "1"
    scan = load_real_scan(Path(data) / SCENES[scene][0])
    return simulate_walk(scan, n_keyframes=n_keyframes, seed=seed)


def run_walk_attempts(
    seq, scene: str, walk: int, start: int, kind: str, method: str
) -> tuple[list[dict], list[dict]]:
    """`run_attempts` on a walk; rows name the walk and the map kind as "real <kind>" (no
    rows for an image method on a scan without vertex colours)."""
    if METHODS[method].images and not has_images(seq.world, conditions(kind)[0]):
        return [], []
    rows, hyps = run_attempts(seq, Attempt(walk, start, kind, method))
    for row in rows + hyps:
        row["sequence"], row["map_kind"] = f"{scene}/walk{walk}", PREFIX + kind
    return rows, hyps


def score_trace(seq, kind: str, gamma: float) -> dict:
    """semloc incrementally over a whole walk: keyframes, top-2 scores and statuses."""
    localizer = Localizer(seq.global_maps[kind], LocalizerConfig(gamma=gamma), local_up=(0, 0, 1))
    trace: dict = {"keyframes": [], "top_scores": [], "statuses": []}
    for kf in seq.keyframes:
        if kf.objects:
            result = localizer.update(kf.objects)
            trace["keyframes"].append(kf.index)
            trace["top_scores"].append(result.steps[-1].top_scores)
            trace["statuses"].append(result.status)
    return trace


def plan(config: BenchConfig) -> list[tuple[str, int, int, str, str]]:
    """All chains: (scene, walk, start, map kind, method); with `config.night` also the night
    queries of the image methods against the reconstruction map (`night`; the object methods'
    night rows are copies of their day rows); image methods on the reconstruction maps only
    (the scans' vertex colours; CAD models have none)."""
    jobs = []
    for scene, (_, scene_kinds) in SCENES.items():
        kinds = [*scene_kinds, NIGHT] if config.night else list(scene_kinds)
        for walk in range(config.real_walk_count):
            index = 500 + 10 * list(SCENES).index(scene) + walk
            for start in start_keyframes(
                config, index, config.real_walk_keyframes, config.real_walk_starts
            ):
                jobs += [(scene, walk, start, kind, method) for kind in kinds
                         for method in config.methods
                         if (kind != "cad" or not METHODS[method].images)
                         and (kind != NIGHT or run_at_night(method))]  # fmt: skip
    return jobs


def run_real_walks(client, config: BenchConfig, progress: bool = True) -> dict:
    """Submit the walks and attempts to a Dask `client`: rows, hypotheses and score traces
    (the arguments of `write_outputs`, which the caller writes with the rest of its files)."""
    data = real_walk_data()
    walks = {
        (scene, walk): client.submit(walk_sequence, str(data), scene, walk_seed(config, walk),
                                     config.real_walk_keyframes, pure=False)
        for scene in SCENES for walk in range(config.real_walk_count)
    }  # fmt: skip
    futures = [
        client.submit(run_walk_attempts, walks[scene, walk], scene, walk, start, kind, method,
                      pure=False)
        for scene, walk, start, kind, method in plan(config)
    ]  # fmt: skip
    traces = {
        scene: client.submit(score_trace, walks[scene, 0], kinds[-1], 0.8, pure=False)
        for scene, (_, kinds) in SCENES.items()
    }
    rows, hyps = [], []
    columns = ["[progress.description]{task.description}", BarColumn(), MofNCompleteColumn(),
               TimeElapsedColumn()]  # fmt: skip
    with Progress(*columns, disable=not progress, transient=False) as bar:
        task = bar.add_task("real-walk attempts", total=len(futures))
        for future in as_completed(futures):
            chain_rows, chain_hyps = future.result()
            rows += chain_rows
            hyps += chain_hyps
            bar.advance(task)
    if config.night:
        day, night = PREFIX + "reconstruction", PREFIX + NIGHT
        rows, hyps = (with_night_rows(r, day, night) for r in (rows, hyps))
    rows.sort(key=lambda r: _order(r, config.methods))
    hyps.sort(key=lambda r: _order(r, config.methods))
    return {"rows": rows, "hypotheses": hyps, "traces": {s: f.result() for s, f in traces.items()}}


def _order(row: dict, methods: list[str]) -> tuple:
    position = methods.index(row["method"]) if row["method"] in methods else len(methods)
    return (position, row["map_kind"], row["sequence"], row["start"], row["offset"],
            row.get("rank", 0))  # fmt: skip


def kinds_of(rows: list[dict]) -> list[str]:
    return [PREFIX + k for k in ("reconstruction", NIGHT, "cad") if any(
        r["map_kind"] == PREFIX + k for r in rows)]  # fmt: skip


def scores_figure(traces: dict[str, dict]):
    """The incremental top-2 score plot of each scene's first walk, side by side."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(traces), figsize=(6.4 * len(traces), 3.8), dpi=90,
                             squeeze=False)  # fmt: skip
    for ax, (scene, trace) in zip(axes[0], traces.items(), strict=True):
        steps = [SimpleNamespace(step=k, top_scores=s)
                 for k, s in zip(trace["keyframes"], trace["top_scores"], strict=True)]  # fmt: skip
        kind = SCENES[scene][1][-1]
        plot_scores(ax, steps, statuses=trace["statuses"], x_label="keyframe",
                    title=f"{scene}, {kind} map: top-2 association-set scores")  # fmt: skip
    fig.tight_layout()
    return fig


def table_text(rows: list[dict], methods: list[str]) -> str:
    return summary_table(rows, methods)


def write_outputs(
    out: Path, config: BenchConfig, rows: list[dict], hyps: list[dict], traces: dict
) -> list[Path]:
    out.mkdir(parents=True, exist_ok=True)
    write_atomic(out / "real_walks.csv", format_rows(rows, RESULT_COLUMNS))
    write_atomic(out / "real_walks_hypotheses.csv", format_rows(hyps, HYPOTHESIS_COLUMNS))
    files = [out / "real_walks.csv", out / "real_walks_hypotheses.csv"]
    methods = [m for m in config.methods if any(r["method"] == m for r in rows)]
    if rows:
        figure = comparison_figure(rows, hyps, methods, kinds_of(rows))
        files.append(save_figure(figure, out / "real_walks.png"))
    files.append(save_figure(scores_figure(traces), out / "real_walks_scores.png"))
    attempts = {(r["map_kind"], r["sequence"], r["start"], r["offset"]) for r in rows}
    text = (
        "# Real walks\n\n"
        f"{config.real_walk_count} camera walks of {config.real_walk_keyframes} keyframes "
        f"through each real scan ({', '.join(SCENES)}), {config.real_walk_starts} random starts "
        "per walk, attempts when more than 2 objects are seen, then +15 and +30 keyframes; "
        f"{len(attempts)} attempts in all. Success: 15° / 0.5 m. 'real night': the "
        "reconstruction map with the query images at night (object methods see the same "
        "objects as by day); SIFT runs on the scans' vertex colours, not against CAD maps.\n\n"
        "## Recall (top-1 / top-10) and time per update\n\n"
        + table_text(rows, methods)
        + "\n![real_walks.png](real_walks.png)\n\n![real_walks_scores.png](real_walks_scores.png)\n"
    )
    write_atomic(out / "real_walks.md", text)
    return [*files, out / "real_walks.md"]
