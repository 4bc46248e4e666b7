"""`semloc demo` (also `--scan` of a real scan), `semloc simulate`, `semloc view`: the simulator's
commands and pictures."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import numpy as np
import typer
from pydantic import ValidationError
from rich.table import Table

from semloc.cli.app import MAX_SEED, app, console, fail, first_error, foxglove_option
from semloc.cli.extras import need
from semloc.cli.files import (
    ResultFile,
    check_finite,
    check_output,
    check_separate,
    check_suffix,
    map_paths,
    read_pose,
    read_result,
)
from semloc.cli.options import (
    RESOLUTION_HELP,
    SIZE_HELP,
    DescribeOption,
    MapKindChoice,
    PathChoice,
    parse_resolution,
)
from semloc.eval.success import (
    ROTATION_TOLERANCE_DEG,
    TRANSLATION_TOLERANCE_M,
    is_success,
)
from semloc.io import load_map, write_atomic
from semloc.io.output import staged_folder
from semloc.maps import ObjectMap
from semloc.pictures.display import for_rich
from semloc.ros.simbag import walk_bag
from semloc.sim.export import write_sequence
from semloc.sim.noise import DetectionNoise
from semloc.sim.scenario import simulate_sequence
from semloc.sim.sensor import Intrinsics
from semloc.sim.world import MAX_ROOMS
from semloc.tools.demo import DemoConfig, run_demo
from semloc.tools.scandemo import ScanDemoConfig, run_scan_demo
from semloc.transforms import pose_error

DemoFoxglove = foxglove_option(
    "Stream the run live to Foxglove on this port (8765 when given alone); the view stays up "
    "after the run until Ctrl-C."
)


DriftOption = Annotated[
    float,
    typer.Option(
        min=0, max=1, help="Odometry drift: metres of position error per metre travelled."
    ),
]
DriftYawOption = Annotated[
    float,
    typer.Option(
        "--drift-yaw", min=0, max=90, help="Odometry heading drift: degrees per metre travelled."
    ),
]


@app.command()
def demo(
    out: Annotated[
        Path,
        typer.Option(
            "--output", "-o", help="Folder for scores.png, map.png, world.png, result.json, maps."
        ),
    ] = Path("demo_out"),
    seed: Annotated[int, typer.Option(min=0, max=MAX_SEED, help="World and noise seed.")] = 0,
    size: Annotated[str, typer.Option(help=SIZE_HELP)] = "small",
    map_kind: Annotated[
        MapKindChoice | None,
        typer.Option(
            help="Global map: scan reconstruction, CAD models, or moved (default: "
            "reconstruction; with --scan of a Scan2CAD scene: cad)."
        ),
    ] = None,
    path: Annotated[
        PathChoice, typer.Option(help="Camera path: walk through rooms, or orbit in one room.")
    ] = PathChoice["walk"],
    keyframes: Annotated[
        int | None, typer.Option(min=2, max=2000, help="Number of keyframes (40; --scan: 60).")
    ] = None,
    rooms: Annotated[int, typer.Option(min=1, max=MAX_ROOMS, help="Rooms the walk visits.")] = 2,
    resolution: Annotated[str, typer.Option(help=RESOLUTION_HELP)] = "240x180",
    gamma: Annotated[float, typer.Option(help="Merge threshold of the clustering.")] = 0.8,
    drift: DriftOption = 0.0,
    drift_yaw: DriftYawOption = 0.0,
    scan: Annotated[
        Path | None,
        typer.Option(
            help="A real scan instead of a generated world: a ScanNet or Scan2CAD scene folder "
            "(also looked up under $SEMLOC_DATA or ../shared/data/real, e.g. scene0000_00)."
        ),
    ] = None,
    shapenet: Annotated[
        Path | None, typer.Option(help="ShapeNet root of a Scan2CAD --scan (default: beside it).")
    ] = None,
    rrd: Annotated[
        Path | None,
        typer.Option("--rrd", help="Also write a 3D Rerun recording of the updates (rerun FILE)."),
    ] = None,
    foxglove: DemoFoxglove = None,
) -> None:
    """The main job: walk a camera through a generated world and relocalize incrementally.

    Simulated RGB-D frames -> detections -> local objects -> Localizer.update per keyframe.
    With --scan the frames are ray-cast from a real scan's mesh and its instance labels.

    Prints a live table and the pose error against ground truth; writes scores.png and map.png.
    """
    check_finite(gamma=gamma, drift=drift, drift_yaw=drift_yaw)
    need("demo", "sim")
    need("demo", "viz", modules=("matplotlib",) if rrd is None else ("matplotlib", "rerun"))
    if foxglove is not None:
        need("demo --foxglove", "viz", modules=("foxglove", "websockets"))
    if scan is not None and (rrd is not None or foxglove is not None):
        fail("--rrd and --foxglove are not available with --scan")
    common = {"seed": seed, "resolution": parse_resolution(resolution), "gamma": gamma,
              "drift": drift, "drift_yaw": drift_yaw, "out": out}  # fmt: skip
    if keyframes is not None:
        common["keyframes"] = keyframes
    kind = None if map_kind is None else map_kind.value
    try:
        if scan is not None:
            config = ScanDemoConfig(scan=scan, map_kind=kind, shapenet=shapenet, **common)
            run_scan_demo(config, console)
        else:
            run_demo(DemoConfig(size=size, map_kind=kind or "reconstruction", path=path.value,
                                rooms=rooms, rrd=rrd, foxglove=foxglove, **common), console)  # fmt: skip
    except ValidationError as exc:
        fail(f"invalid option: {first_error(exc)}")
    except ValueError as exc:
        fail(str(exc))


@app.command()
def simulate(
    out: Annotated[Path, typer.Argument(help="Folder to write (created if missing).")],
    seed: Annotated[int, typer.Option(min=0, max=MAX_SEED, help="World and noise seed.")] = 0,
    size: Annotated[str, typer.Option(help=SIZE_HELP)] = "small",
    path: Annotated[
        PathChoice, typer.Option(help="Camera path: walk through rooms, or orbit in one room.")
    ] = PathChoice["walk"],
    keyframes: Annotated[int, typer.Option(min=1, max=5000, help="Number of keyframes.")] = 40,
    rooms: Annotated[int, typer.Option(min=1, max=MAX_ROOMS, help="Rooms the walk visits.")] = 2,
    resolution: Annotated[str, typer.Option(help=RESOLUTION_HELP)] = "240x180",
    snapshots: Annotated[
        bool, typer.Option(help="Also write the local map after every keyframe.")
    ] = True,
    perfect: Annotated[
        bool,
        typer.Option(
            "--perfect", help="Perfect detections (no misses, confusions or mask errors)."
        ),
    ] = False,
    drift: DriftOption = 0.0,
    drift_yaw: DriftYawOption = 0.0,
    descriptor: DescribeOption = None,
    bag: Annotated[
        bool,
        typer.Option(
            "--bag",
            help="Also write the walk as a ROS 2 bag, walk.mcap: /detections, /odom and "
            "/detections/points (the ros extra).",
        ),
    ] = False,
) -> None:
    """Write a world's global maps (reconstruction, CAD, dynamic), the local maps and ground truth.

    Files: world.json/.png, global_<kind>.json, local.json, keyframes/local_XXXX.json;
    with --bag also walk.mcap (detections, odometry and points, 10 per second).

    ground_truth.json holds T_global_local, camera poses and correspondences per map kind.

    All files are written, or none: they are built in a temporary folder beside OUT and moved
    into it at the end (ground_truth.json last).
    """
    check_finite(drift=drift, drift_yaw=drift_yaw)
    need("simulate", "sim")
    need("simulate", "viz", modules=("matplotlib",))
    if bag:
        need("simulate --bag", "ros")
    noise = DetectionNoise.perfect() if perfect else DetectionNoise()
    noise = noise.model_copy(update={"drift_translation": drift, "drift_yaw_deg": drift_yaw})
    try:
        seq = simulate_sequence(
            seed, size, "all", path.value, n_keyframes=keyframes, n_rooms=rooms,
            resolution=parse_resolution(resolution), noise=noise,
        )  # fmt: skip
    except ValueError as exc:
        fail(str(exc))
    with staged_folder(out, index="ground_truth.json") as stage:
        files = write_sequence(
            seq,
            stage,
            snapshots=snapshots,
            descriptor=None if descriptor is None else descriptor.value,
        )
        if bag:
            camera = Intrinsics.scannet(*parse_resolution(resolution))
            files.append(write_atomic(stage / "walk.mcap", walk_bag(seq, camera)))
    table = Table(
        title=f"simulated world seed {seed} -> {for_rich(out, None)}", title_justify="left"
    )
    for column in ("map", "objects", "file"):
        table.add_column(column)
    for kind, gmap in seq.global_maps.items():
        table.add_row(f"global {kind}", str(len(gmap)), f"global_{kind}.json")
    table.add_row("local (final)", str(len(seq.local_map)), "local.json")
    console.print(table)
    console.print(f"{len(seq.keyframes)} keyframes; {len(files)} files written")


@app.command()
def view(
    map_file: Annotated[Path, typer.Argument(metavar="MAP", help="A semloc map (JSON).")],
    result: Annotated[
        Path | None,
        typer.Option(help="Result JSON (semloc localize --format json) or ground_truth.json."),
    ] = None,
    local: Annotated[
        Path | None, typer.Option(help="Local map to place into MAP by the result's pose.")
    ] = None,
    gt: Annotated[
        Path | None,
        typer.Option(
            "--gt", help="Ground truth (T_global_local, as crop writes): also place --local by it."
        ),
    ] = None,
    output: Annotated[
        Path | None,
        typer.Option("--output", "-o", help="PNG to write (default: MAP.png, unless --rrd)."),
    ] = None,
    rrd: Annotated[
        Path | None,
        typer.Option("--rrd", help="Also (or, without -o, only) write a 3D Rerun recording."),
    ] = None,
    title: Annotated[str | None, typer.Option(help="Title of the picture.")] = None,
) -> None:
    """Draw MAP from above as a PNG (or in 3D with --rrd), with a result and a local map.

    With --result and --local the local objects are placed by the estimated pose; with --gt
    also by the true pose (the legend says which is which).
    """
    png = output
    if png is None and rrd is None:
        png = map_file.with_suffix(".png")
    check_suffix(png, ".png", "--output", "a PNG picture")
    check_suffix(rrd, ".rrd", "--rrd", "a Rerun recording")
    if png is not None:
        check_output(png)
        need("view", "viz", modules=("matplotlib",))
    if rrd is not None:
        need("view --rrd", "viz", modules=("rerun",))
    objmap = load_map(map_file)
    answer = read_result(result) if result is not None else ResultFile(None)
    pose, pairs, status = answer.pose, answer.pairs, answer.status
    truth = read_pose(gt, "--gt takes a file with T_global_local") if gt is not None else None
    local_map = load_map(local) if local is not None else None
    if local_map is not None and pose is None and truth is None:
        fail("--local needs a --result with a pose (or --gt) to place the local objects")
    inputs = {
        **map_paths(map_file, objmap, "MAP"),
        result: "the --result file",
        gt: "the --gt file",
    }
    if local is not None and local_map is not None:
        inputs.update(map_paths(local, local_map, "the --local map"))
    check_separate({"--output": png, "--rrd": rrd}, inputs)
    alone = local_map is None and pose is None
    role = "local" if alone and _looks_local(map_file, objmap.name) else "global"
    if png is not None:
        from semloc.pictures.viz import map_figure, plot_localization, save_figure  # matplotlib

        heading = title or _heading(map_file, objmap, answer, truth)
        rivals = answer.hypotheses[1:] if status == "ambiguous" else ()
        fig, ax = map_figure(objmap.positions[:, :2])
        plot_localization(ax, objmap, local_map, pose, pairs, true_pose=truth, title=heading,
                          map_role=role, rivals=rivals, names=True, moved=answer.moved,
                          zoom=local_map is not None or bool(rivals))  # fmt: skip
        console.print(f"wrote {for_rich(save_figure(fig, png), None)}")
    if rrd is not None:
        from semloc.pictures.viz3d import write_localization  # rerun

        written = write_localization(rrd, objmap, local_map, pose, pairs, truth, answer.moved)
        shown = for_rich(written, None)
        console.print(f"wrote {shown} (open with: rerun {shown})")


def _heading(path: Path, objmap: ObjectMap, answer: ResultFile, truth: np.ndarray | None) -> str:
    """The picture's title: the map, the answer's status and, with the truth, the pose error
    and the paper's success at 15° / 0.5 m."""
    heading = f"{path.name}: {len(objmap)} objects"
    if answer.status:
        heading += f" ({answer.status})"
    if answer.pose is not None and truth is not None:
        rotation, translation = pose_error(answer.pose, truth)
        verdict = "success" if is_success(answer.pose, truth) else "failure"
        heading += (
            f"\nerror {rotation:.2f}°, {translation:.3f} m: {verdict} at "
            f"{ROTATION_TOLERANCE_DEG:g}° / {TRANSLATION_TOLERANCE_M:g} m"
        )
    return heading


def _looks_local(path: Path, name: str) -> bool:
    """Whether a map drawn on its own is a local map (as simulate, crop and demo name them)."""
    words = f"{path.stem} {name}".lower()
    return "local" in words or "crop" in words
