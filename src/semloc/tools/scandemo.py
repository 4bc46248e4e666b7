"""The demo on a real scan: walk a camera through a ScanNet or Scan2CAD scene and relocalize, live.

`run_scan_demo(ScanDemoConfig(scan=...), console)` loads the scene (`semloc.sim.realscan`),
renders a walk through its free space into depth and instance images, detects (the simulator's
noise model) and fuses them into a local map in the odometry frame, then relocalizes
incrementally against the scene's reconstruction or CAD map with the same live table, report,
pictures (`scores.png`, `map.png`, `scan.png`), `result.json`, `ground_truth.json` and maps as
`semloc demo`, all files or none (`semloc.io.output.staged_folder`, `result.json` moved in
last).  A relative `scan` folder is also looked up in the real-data folder (`$SEMLOC_DATA`, else
`../shared/data/real`).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
from pydantic import BaseModel, ConfigDict, Field
from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

from semloc.eval.datasets import real_data_dir
from semloc.io.native import save_map
from semloc.io.output import staged_folder, write_atomic
from semloc.maps import MapError
from semloc.sim.noise import DetectionNoise
from semloc.sim.realscan import RealScan, load_real_scan, simulate_walk
from semloc.sim.scenario import SimulatedSequence
from semloc.sim.sensor import check_resolution
from semloc.tools.demo import DemoResult, _report, localize_sequence
from semloc.transforms import pose_error


class ScanDemoConfig(BaseModel):
    """What the real-scan demo walks through and how it localizes."""

    model_config = ConfigDict(extra="forbid")

    scan: Path = Field(description="ScanNet or Scan2CAD scene folder (or one under the data path).")
    map_kind: str | None = Field(
        None, description="reconstruction or cad (default: cad for Scan2CAD, else reconstruction)."
    )
    shapenet: Path | None = Field(None, description="ShapeNet root of a Scan2CAD scene.")
    seed: int = Field(0, description="Walk and noise seed.")
    keyframes: int = Field(60, ge=2, le=2000, description="Number of keyframes.")
    resolution: tuple[int, int] = Field((240, 180), description="Depth image width, height.")
    gamma: float = Field(0.8, gt=0, lt=1, description="Merge threshold of the clustering.")
    drift: float = Field(
        0.0, ge=0, le=1, description="Odometry drift, metres of position error per metre travelled."
    )
    drift_yaw: float = Field(
        0.0, ge=0, le=90, description="Odometry heading drift, degrees per metre travelled."
    )
    out: Path = Field(Path("demo_out"), description="Output folder.")


def resolve_scan(folder: Path) -> Path:
    """The scene folder: as given, else under the real-data folder; MapError when missing."""
    if folder.is_dir():
        return folder
    data = real_data_dir()
    if data is not None and not folder.is_absolute():
        for candidate in (data / folder, data / "scannet" / folder, data / "scan2cad" / folder):
            if candidate.is_dir():
                return candidate
    where = (
        f"nor under the data folder {data}"
        if data is not None
        else "and no data folder ($SEMLOC_DATA or ../shared/data/real) exists"
    )
    raise MapError(f"--scan {folder}: no such scene folder, {where}")


def map_kind_of(config: ScanDemoConfig, scan: RealScan) -> str:
    kind = config.map_kind or ("cad" if "cad" in scan.global_maps else "reconstruction")
    if kind not in scan.global_maps:
        raise ValueError(
            f"--map-kind {kind!r}: the {scan.source} scene {scan.name} has only "
            f"{sorted(scan.global_maps)} maps"
        )
    return kind


def walk(config: ScanDemoConfig, scan: RealScan, console: Console) -> SimulatedSequence:
    """The rendered, detected and fused walk, with a progress bar."""
    columns = (TextColumn("{task.description}"), BarColumn(),
               TextColumn("{task.completed}/{task.total}"), TimeElapsedColumn())  # fmt: skip
    noise = DetectionNoise(drift_translation=config.drift, drift_yaw_deg=config.drift_yaw)
    with Progress(*columns, console=console, transient=True) as progress:
        task = progress.add_task("rendering keyframes", total=config.keyframes)
        return simulate_walk(
            scan, n_keyframes=config.keyframes, seed=config.seed, resolution=config.resolution,
            noise=noise,
            progress=lambda done, total: progress.update(task, completed=done, total=total),
        )  # fmt: skip


def run_scan_demo(config: ScanDemoConfig, console: Console | None = None) -> DemoResult:
    """Load, walk, localize incrementally, report and write the pictures (module docstring)."""
    console = console or Console()
    check_resolution(*config.resolution)
    if config.out.exists() and not config.out.is_dir():  # said before the walk, not after
        raise MapError(f"{config.out}: exists and is not a folder")
    t0 = time.perf_counter()
    scan = load_real_scan(resolve_scan(config.scan), shapenet=config.shapenet)
    kind = map_kind_of(config, scan)
    seq = walk(config, scan, console)
    t1 = time.perf_counter()
    console.print(
        f"{scan.source} scene {scan.name}: {len(scan.objects)} labelled instances; global map "
        f"'{kind}' with {len(seq.global_maps[kind])} objects; {len(seq.keyframes)} keyframes "
        f"walked, {len(seq.local_map)} local objects fused"
    )
    result, history, warm = localize_sequence(seq, kind, config.gamma, console)
    t2 = time.perf_counter()
    rot = trans = None
    if result.pose is not None:
        rot, trans = pose_error(result.pose, seq.T_global_local)
    truth = set(seq.correspondences(kind))
    correct = sum(1 for p in (result.best.pairs if result.best else []) if p in truth)
    seconds = {"simulate": t1 - t0, "warm_up": warm.seconds, "localize": t2 - t1 - warm.seconds}
    demo = DemoResult(result, seq, rot, trans, correct, seconds, history=history, warm_up=warm)
    with staged_folder(config.out, index="result.json") as stage:  # all files or none
        files = write_outputs(stage, kind, scan, demo)
    demo.files = [config.out / f.relative_to(stage) for f in files]
    demo.seconds["total"] = time.perf_counter() - t0
    _report(demo, config, console)  # type: ignore[arg-type]  # reads config.out only
    return demo


def write_outputs(out: Path, kind: str, scan: RealScan, demo: DemoResult) -> list[Path]:
    """scores.png, map.png, scan.png, result.json, ground_truth.json, global.json, local.json."""
    from semloc.pictures.viz import (  # matplotlib (the pictures)
        label_colors,
        map_figure,
        new_figure,
        plot_localization,
        plot_scores,
        save_figure,
    )

    seq, result = demo.sequence, demo.result
    out.mkdir(parents=True, exist_ok=True)
    gmap = seq.global_maps[kind]
    fig, ax = new_figure(8, 4.5)
    statuses = [s.status for s in demo.history]
    plot_scores(ax, demo.history, statuses=statuses, x_label="keyframe",
                title=f"top-2 association-set scores ({scan.name}, {kind} map)")  # fmt: skip
    files = [save_figure(fig, out / "scores.png")]
    error = (
        ""
        if demo.translation_error_m is None
        else f", error {demo.translation_error_m:.2f} m / {demo.rotation_error_deg:.1f}°"
    )
    fig, ax = map_figure(gmap.positions[:, :2])
    best = result.best
    plot_localization(
        ax, gmap, seq.local_map, result.pose, best.pairs if best else [],
        true_pose=seq.T_global_local,
        title=f"{scan.name} {kind} map, local objects placed by the estimate ({result.status}"
        f"{error})",
    )  # fmt: skip
    files.append(save_figure(fig, out / "map.png"))
    fig, ax = map_figure(np.array(scan.bounds), width=8.0)
    draw_scan(ax, scan, seq, label_colors([o.label for o in scan.objects]))
    files.append(save_figure(fig, out / "scan.png"))
    files.append(save_map(gmap, out / "global.json"))
    files.append(save_map(seq.local_map, out / "local.json"))
    write_atomic(out / "result.json", result.to_json())
    write_atomic(out / "ground_truth.json", json.dumps(seq.ground_truth(), indent=1) + "\n")
    return [*files, out / "result.json", out / "ground_truth.json"]


def draw_scan(ax, scan: RealScan, seq: SimulatedSequence, colors: dict[str, str]) -> None:
    """Top-down view of the scan: mesh vertices coloured by instance label, and the walk."""
    vertices, faces = scan.mesh.vertices, scan.mesh.triangles
    labels = [o.label for o in scan.objects]
    ax.scatter(*vertices[::4, :2].T, s=0.3, c="#d0d0d0", linewidths=0)
    for index, label in enumerate(labels):
        ids = np.unique(faces[scan.face_instance == index])
        ax.scatter(*vertices[ids[::2], :2].T, s=0.6, c=colors[label], linewidths=0)
        centre = vertices[ids, :2].mean(axis=0)
        ax.text(*centre, label, fontsize=6, ha="center")
    poses = np.array([kf.T_world_camera for kf in seq.keyframes])
    ax.plot(poses[:, 0, 3], poses[:, 1, 3], "-", color="black", linewidth=1.2)
    ax.quiver(poses[:, 0, 3], poses[:, 1, 3], poses[:, 0, 2], poses[:, 1, 2], angles="xy",
              scale=25, width=0.003, color="black")  # fmt: skip
    ax.set_title(f"{scan.name}: instances and the camera walk ({len(poses)} keyframes)")
    ax.set_aspect("equal")
