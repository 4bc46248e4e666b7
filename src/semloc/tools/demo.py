"""The demo: simulate a walk through a generated world and relocalize incrementally, live.

`run_demo(DemoConfig(...), console)` simulates the sequence (world, global map, keyframes,
fused local objects), feeds the objects that are new or updated at each keyframe to a
`Localizer`, prints a live table (keyframe, local objects, association sets, top-2 scores,
status, time) and finally the pose error against ground truth.  It writes `scores.png`,
`map.png`, `world.png`, `result.json`, `ground_truth.json` and the global/local maps to `out`,
and with `rrd` a 3D Rerun recording of the updates (`semloc.pictures.viz3d`, the `viz` extra);
the files in `out` all or none (`semloc.io.output.staged_folder`).

The pictures come from the run's whole history, one `KeyframeStep` per update kept here
(`Result.steps` keeps only the last few).  Loading (or, once after an install, compiling) the
inner loops happens before the first update and is reported apart from the localization time.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field
from rich.console import Console
from rich.live import Live
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from semloc.compiling import WarmUp, warmup
from semloc.eval.success import is_success
from semloc.io.native import save_map
from semloc.io.output import staged_folder, write_atomic
from semloc.localizer import Localizer, LocalizerConfig
from semloc.pictures.display import for_rich
from semloc.pictures.live import FoxgloveView
from semloc.results import Result
from semloc.sim.mapkinds import MAP_KINDS
from semloc.sim.noise import DetectionNoise
from semloc.sim.scenario import SimulatedSequence, simulate_sequence
from semloc.sim.sensor import check_resolution
from semloc.sim.trajectory import PATHS
from semloc.transforms import pose_error

STATUS_STYLE = {"localized": "green", "ambiguous": "yellow", "failed": "red"}
"""The colour of each status wherever one is printed (demo, CLI); here, not in cli/, so that
the demo imports nothing of the command line (which imports the demo)."""


class DemoConfig(BaseModel):
    """What the demo simulates and how it localizes."""

    model_config = ConfigDict(extra="forbid")

    seed: int = Field(0, description="World and noise seed.")
    size: str = Field("small", description="World size: tiny, small, medium, large, building.")
    map_kind: str = Field("reconstruction", description="Global map: reconstruction, cad, dynamic.")
    path: str = Field("walk", description="Camera path: walk (through rooms) or orbit (one room).")
    keyframes: int = Field(40, ge=2, le=2000, description="Number of keyframes.")
    rooms: int = Field(2, ge=1, description="Rooms visited by the walk.")
    resolution: tuple[int, int] = Field((240, 180), description="Depth image width, height.")
    gamma: float = Field(0.8, gt=0, lt=1, description="Merge threshold of the clustering.")
    drift: float = Field(
        0.0, ge=0, le=1, description="Odometry drift, metres of position error per metre travelled."
    )
    drift_yaw: float = Field(
        0.0, ge=0, le=90, description="Odometry heading drift, degrees per metre travelled."
    )
    out: Path = Field(Path("demo_out"), description="Output folder.")
    rrd: Path | None = Field(None, description="Rerun recording of the updates to write.")
    foxglove: int | None = Field(
        None, ge=0, le=65535, description="Port of a live Foxglove view (foxglove-sdk)."
    )


@dataclass(frozen=True)
class KeyframeStep:
    """One update of the run as the pictures need it: the keyframe, the top association-set
    scores after it, the status and the update's time."""

    step: int
    top_scores: list[float]
    status: str
    ms: float


@dataclass
class DemoResult:
    """The outcome: last Result, ground truth, errors, timings and written files."""

    result: Result
    sequence: SimulatedSequence
    rotation_error_deg: float | None
    translation_error_m: float | None
    correct_pairs: int
    seconds: dict[str, float]
    files: list[Path] = field(default_factory=list)
    history: list[KeyframeStep] = field(default_factory=list)
    warm_up: WarmUp | None = None

    @property
    def success(self) -> bool:
        """The paper's criterion: < 15 degrees and < 0.5 m."""
        return is_success(self.result.pose, self.sequence.T_global_local)


def validate(config: DemoConfig) -> None:
    """Raise ValueError naming the bad option (the CLI turns it into one line + exit 2)."""
    if config.map_kind not in MAP_KINDS:
        raise ValueError(f"--map-kind must be one of {list(MAP_KINDS)}, got {config.map_kind!r}")
    if config.path not in PATHS:
        raise ValueError(f"--path must be one of {list(PATHS)}, got {config.path!r}")
    check_resolution(*config.resolution)


def simulate(config: DemoConfig, console: Console) -> SimulatedSequence:
    """The simulated sequence, with a progress bar."""
    columns = (
        TextColumn("{task.description}"),
        BarColumn(),
        TextColumn("{task.completed}/{task.total}"),
        TimeElapsedColumn(),
    )
    noise = DetectionNoise(drift_translation=config.drift, drift_yaw_deg=config.drift_yaw)
    with Progress(*columns, console=console, transient=True) as progress:
        task = progress.add_task("simulating keyframes", total=config.keyframes)
        return simulate_sequence(
            config.seed, config.size, config.map_kind, config.path,
            n_keyframes=config.keyframes, n_rooms=config.rooms, resolution=config.resolution,
            noise=noise,
            progress=lambda done, total: progress.update(task, completed=done, total=total),
        )  # fmt: skip


def _table() -> Table:
    table = Table(title="incremental relocalization", title_justify="left", expand=False)
    for name in ("kf", "objects", "new/upd", "sets", "top-1", "top-2", "status", "ms"):
        table.add_column(name, justify="right" if name != "status" else "left", no_wrap=True)
    return table


def _score(value: float | None) -> str:
    if value is None:
        return "-"
    return f"{value:.2f}" if abs(value) < 1e4 else f"{value:.3g}"


def localize_sequence(
    seq: SimulatedSequence,
    kind: str,
    gamma: float,
    console: Console,
    recording: Any = None,
    view: Any = None,
) -> tuple[Result, list[KeyframeStep], WarmUp]:
    """Run the Localizer over the keyframes (live table); the last Result, the whole history
    (one `KeyframeStep` per update) and the warm-up before the first update.

    `recording` (a `semloc.pictures.viz3d.DemoRecording`) gets the state after every update,
    `view` (a `semloc.pictures.live.FoxgloveView`) every answer."""
    localizer = Localizer(seq.global_maps[kind], LocalizerConfig(gamma=gamma), local_up=(0, 0, 1))
    result = Result(status="failed", pose=None, hypotheses=[])
    history: list[KeyframeStep] = []
    # every compiled loop, not only localization's (the first command of a new install: then
    # `align`, `serve` and `bag` find nothing left to compile); not inside the timed updates
    warm = warmup(lambda text: console.print(f"[dim]{text}…[/]"))
    table = _table()
    with Live(table, console=console, refresh_per_second=8, vertical_overflow="visible"):
        for kf in seq.keyframes:
            if not kf.objects:
                continue
            result = localizer.update(kf.objects, position=kf.T_odom_camera)
            step = result.steps[-1]
            history.append(
                KeyframeStep(kf.index, list(step.top_scores), result.status, float(step.ms))
            )
            if recording is not None:
                recording.update(kf.index, localizer.local_map, result)
            if view is not None:
                view.update(kf.index, result, localizer.local_map, kf.T_odom_camera)
            top = [*step.top_scores[:2], None, None][:2]
            table.add_row(
                str(kf.index), str(step.n_local), f"{len(kf.new)}/{len(kf.updated)}",
                str(step.n_sets),
                *(_score(s) for s in top),
                f"[{STATUS_STYLE[result.status]}]{result.status}[/]", f"{step.ms:.0f}",
            )  # fmt: skip
    console.print()
    return result, history, warm


def run_demo(config: DemoConfig, console: Console | None = None) -> DemoResult:
    """Simulate, localize incrementally, report and write the pictures (see module docstring)."""
    console = console or Console()
    validate(config)
    t0 = time.perf_counter()
    seq = simulate(config, console)
    t1 = time.perf_counter()
    gmap = seq.global_maps[config.map_kind]
    console.print(
        f"world seed {config.seed} ({seq.world.size}): {len(seq.world.rooms)} rooms, "
        f"{len(seq.world.objects)} objects; global map '{config.map_kind}' "
        f"with {len(gmap)} objects; "
        f"{len(seq.keyframes)} keyframes ({config.path}), {len(seq.local_map)} local objects fused"
    )
    recording = None
    if config.rrd is not None:
        from semloc.pictures.viz3d import DemoRecording  # rerun

        recording = DemoRecording(config.rrd, gmap, seq.T_global_local, seq.local_map.labels)
    view = None
    if config.foxglove is not None:
        view = FoxgloveView(gmap, port=config.foxglove)
        console.print(f"Foxglove: open a connection to ws://localhost:{view.port}")
    try:
        result, history, warm = localize_sequence(
            seq, config.map_kind, config.gamma, console, recording, view
        )
    except BaseException:
        if recording is not None:
            recording.discard()
        if view is not None:
            view.close()
        raise
    t2 = time.perf_counter()
    rot = trans = None
    if result.pose is not None:
        rot, trans = pose_error(result.pose, seq.T_global_local)
    truth = set(seq.correspondences(config.map_kind))
    correct = sum(1 for p in (result.best.pairs if result.best else []) if p in truth)
    seconds = {"simulate": t1 - t0, "warm_up": warm.seconds, "localize": t2 - t1 - warm.seconds}
    demo = DemoResult(result, seq, rot, trans, correct, seconds, history=history, warm_up=warm)
    with staged_folder(config.out, index="result.json") as stage:  # all files or none
        files = write_outputs(config.model_copy(update={"out": stage}), demo)
    demo.files = [config.out / f.relative_to(stage) for f in files]
    if recording is not None:
        demo.files.append(recording.close())
    demo.seconds["total"] = time.perf_counter() - t0
    _report(demo, config, console)
    if view is not None:
        _keep_serving(view, console)
    return demo


def _keep_serving(view: Any, console: Console) -> None:
    """Leave the live view up for a look at the last answer, until Ctrl-C."""
    console.print(f"the Foxglove view stays up at ws://localhost:{view.port}: Ctrl-C ends it")
    try:
        while True:
            time.sleep(0.2)
    finally:
        view.close()


def write_outputs(config: DemoConfig, demo: DemoResult) -> list[Path]:
    """scores.png (every update of `demo.history`), map.png, world.png, result.json,
    ground_truth.json, global.json, local.json."""
    from semloc.pictures.viz import (
        map_figure,
        new_figure,
        plot_localization,
        plot_scores,
        plot_world,
        save_figure,  # matplotlib (the pictures)
    )

    out, seq, result = config.out, demo.sequence, demo.result
    out.mkdir(parents=True, exist_ok=True)
    gmap = seq.global_maps[config.map_kind]
    fig, ax = new_figure(8, 4.5)
    title = f"top-2 association-set scores ({config.map_kind} map)"
    statuses = [s.status for s in demo.history]
    plot_scores(ax, demo.history, statuses=statuses, title=title, x_label="keyframe")
    files = [save_figure(fig, out / "scores.png")]
    best = result.best
    fig, ax = map_figure(gmap.positions[:, :2])
    status = result.status + (
        ""
        if demo.translation_error_m is None
        else f", error {demo.translation_error_m:.2f} m / {demo.rotation_error_deg:.1f}°"
    )  # noqa: E501
    plot_localization(
        ax, gmap, seq.local_map, result.pose, best.pairs if best else [],
        true_pose=seq.T_global_local,
        title=f"{config.map_kind} map, local objects placed by the estimated pose ({status})",
    )  # fmt: skip
    files.append(save_figure(fig, out / "map.png"))
    lo, hi = seq.world.bounds
    fig, ax = map_figure(np.array([lo, hi]))
    trajectory = np.array([kf.T_world_camera[:2, 3] for kf in seq.keyframes])
    plot_world(
        ax, seq.world, trajectory=trajectory, title=f"world (seed {config.seed}, {seq.world.size})"
    )
    files.append(save_figure(fig, out / "world.png"))
    files.append(save_map(gmap, out / "global.json"))
    files.append(save_map(seq.local_map, out / "local.json"))
    write_atomic(out / "result.json", result.to_json())
    write_atomic(out / "ground_truth.json", json.dumps(seq.ground_truth(), indent=1) + "\n")
    files += [out / "result.json", out / "ground_truth.json"]
    return files


def _report(demo: DemoResult, config: DemoConfig, console: Console) -> None:
    result = demo.result
    colour = STATUS_STYLE[result.status]
    console.print(f"final status: [bold {colour}]{result.status}[/]")
    if result.best is not None:
        console.print(
            f"best hypothesis: {len(result.best.pairs)} pairs, "
            f"{demo.correct_pairs} of them correct "
            f"(ground truth), score {result.best.score:.2f}"
        )
    if demo.translation_error_m is None:
        console.print("[red]no pose estimate[/]")
    else:
        ok = "[green]success[/]" if demo.success else "[red]outside 0.5 m / 15°[/]"
        console.print(
            f"pose error vs ground truth: {demo.translation_error_m:.3f} m, "
            f"{demo.rotation_error_deg:.2f}° ({ok})"
        )
    s = demo.seconds
    updates = sum(step.ms for step in demo.history) / 1000
    warm = "" if demo.warm_up is None else f"{demo.warm_up.describe()}, "
    console.print(
        f"time: simulation {s['simulate']:.1f} s, {warm}localization {s['localize']:.1f} s "
        f"({len(demo.history)} updates, {updates:.1f} s in them), total {s['total']:.1f} s"
    )
    names = ", ".join(p.name for p in demo.files)
    console.print(f"wrote {names} to {for_rich(config.out, None)}/")
