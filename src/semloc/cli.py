"""The `semloc` command line (typer): one function per sub-command, errors as one line + exit 2.

Every command runs inside `main()`, which turns `MapError`, `UsageError`-like problems and
`OSError`s into a single `semloc: error: ...` line on stderr and exit status 2, so that bad
input never ends in a traceback.
"""

from __future__ import annotations

import io
import json
import sys
from enum import StrEnum
from pathlib import Path
from typing import Annotated

import numpy as np
import typer
from pydantic import ValidationError
from rich.console import Console
from rich.table import Table

from semloc.eval.protocol import DEFAULT_METHODS, DESCRIPTOR_VARIANTS
from semloc.io import load_map, read_json, write_atomic
from semloc.localizer import LocalizerConfig, Result
from semloc.localizer import localize as run_localize
from semloc.maps import MapError

app = typer.Typer(
    name="semloc",
    help="Object-level relocalization: find where you are in a map of objects.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
console = Console()
err_console = Console(stderr=True)


class CliError(Exception):
    """A problem with the user's input that is reported as one line and exit status 2."""


def fail(message: str) -> None:
    """Report a bad-input problem and leave with status 2."""
    raise CliError(message)


@app.callback()
def _root() -> None:
    """semloc relocalizes a camera or robot against a prior map made of objects."""


# Commands are defined below this line (and registered by the modules that own them). -------


# --- Shape descriptors stored by the map writers (simulate, convert, crop) -----------------
class DescriptorKind(StrEnum):
    geometric = "geometric"
    voxnet = "voxnet"


_DescribeOption = Annotated[
    DescriptorKind | None,
    typer.Option(
        "--descriptor",
        help="Store shape descriptors of this kind for objects with points (semloc.descriptors).",
    ),
]


def _described(objmap, kind: DescriptorKind | None):
    """The map with descriptors of `kind` for its objects with points (unchanged for None)."""
    from semloc.descriptors import described

    return described(objmap, None if kind is None else kind.value)


# --- Simulation: `demo`, `simulate`, `view` (issue 3; heavy imports stay inside) ---------------
class MapKindChoice(StrEnum):
    reconstruction = "reconstruction"
    cad = "cad"
    dynamic = "dynamic"


class PathChoice(StrEnum):
    walk = "walk"
    orbit = "orbit"


_SIZE_HELP = (
    "World size: tiny (1 room), small (3), medium (6), large (12), building (24), or a room count."
)
_RES_HELP = "Depth image resolution WIDTHxHEIGHT (ScanNet intrinsics scaled)."


def _parse_resolution(text: str) -> tuple[int, int]:
    try:
        width, height = (int(v) for v in text.lower().split("x"))
    except ValueError:
        fail(f"--resolution must look like 240x180, got {text!r}")
    if not (16 <= width <= 1280 and 12 <= height <= 960):
        fail(f"--resolution must be between 16x12 and 1280x960, got {text}")
    return width, height


@app.command()
def demo(
    out: Annotated[
        Path, typer.Option(help="Folder for scores.png, map.png, world.png, result.json, maps.")
    ] = Path("demo_out"),
    seed: Annotated[int, typer.Option(help="World and noise seed.")] = 0,
    size: Annotated[str, typer.Option(help=_SIZE_HELP)] = "small",
    map_kind: Annotated[
        MapKindChoice | None,
        typer.Option(
            help="Global map: scan reconstruction, CAD models, or moved (default: "
            "reconstruction; with --scan of a Scan2CAD scene: cad)."
        ),
    ] = None,
    path: Annotated[
        PathChoice, typer.Option(help="Camera path: walk through rooms, or orbit in one room.")
    ] = PathChoice.walk,
    keyframes: Annotated[
        int | None, typer.Option(min=2, max=2000, help="Number of keyframes (40; --scan: 60).")
    ] = None,
    rooms: Annotated[int, typer.Option(min=1, help="Rooms the walk visits.")] = 2,
    resolution: Annotated[str, typer.Option(help=_RES_HELP)] = "240x180",
    gamma: Annotated[float, typer.Option(help="Merge threshold of the clustering.")] = 0.8,
    drift: Annotated[
        float,
        typer.Option(min=0, max=0.2, help="Odometry drift, m per m travelled (heading: 25x in °)."),
    ] = 0.0,
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
) -> None:
    """The main job: walk a camera through a generated world and relocalize incrementally.

    Simulated RGB-D frames -> detections -> local objects -> Localizer.update per keyframe.
    With --scan the frames are ray-cast from a real scan's mesh and its instance labels.

    Prints a live table and the pose error against ground truth; writes scores.png and map.png.
    """
    from semloc.demo import DemoConfig, run_demo

    common = {"seed": seed, "resolution": _parse_resolution(resolution), "gamma": gamma,
              "drift": drift, "out": out}  # fmt: skip
    if keyframes is not None:
        common["keyframes"] = keyframes
    try:
        if scan is not None:
            from semloc.scandemo import ScanDemoConfig, run_scan_demo

            kind = None if map_kind is None else map_kind.value
            run_scan_demo(ScanDemoConfig(scan=scan, map_kind=kind, shapenet=shapenet, **common),
                          console)  # fmt: skip
            return
        kind = (map_kind or MapKindChoice.reconstruction).value
        config = DemoConfig(size=size, map_kind=kind, path=path.value, rooms=rooms, **common)
        run_demo(config, console)
    except ValidationError as exc:
        fail(f"invalid option: {_first_error(exc)}")
    except (ValueError, MapError) as exc:
        fail(str(exc))


@app.command()
def simulate(
    out: Annotated[Path, typer.Argument(help="Folder to write (created if missing).")],
    seed: Annotated[int, typer.Option(help="World and noise seed.")] = 0,
    size: Annotated[str, typer.Option(help=_SIZE_HELP)] = "small",
    path: Annotated[
        PathChoice, typer.Option(help="Camera path: walk through rooms, or orbit in one room.")
    ] = PathChoice.walk,
    keyframes: Annotated[int, typer.Option(min=1, max=5000, help="Number of keyframes.")] = 40,
    rooms: Annotated[int, typer.Option(min=1, help="Rooms the walk visits.")] = 2,
    resolution: Annotated[str, typer.Option(help=_RES_HELP)] = "240x180",
    snapshots: Annotated[
        bool, typer.Option(help="Also write the local map after every keyframe.")
    ] = True,
    perfect: Annotated[
        bool, typer.Option(help="Perfect detections (no misses, confusions or mask errors).")
    ] = False,
    drift: Annotated[
        float, typer.Option(min=0, help="Odometry drift in metres per metre travelled.")
    ] = 0.0,
    drift_yaw: Annotated[
        float, typer.Option(min=0, help="Odometry heading drift in degrees per metre.")
    ] = 0.0,
    descriptor: _DescribeOption = None,
) -> None:
    """Write a world's global maps (reconstruction, CAD, dynamic), the local maps and ground truth.

    Files: world.json/.png, global_<kind>.json, local.json, keyframes/local_XXXX.json.

    ground_truth.json holds T_global_local, camera poses and correspondences per map kind.
    """
    from semloc.sim.export import write_sequence
    from semloc.sim.noise import DetectionNoise
    from semloc.sim.scenario import simulate_sequence

    noise = DetectionNoise.perfect() if perfect else DetectionNoise()
    noise = noise.model_copy(update={"drift_translation": drift, "drift_yaw_deg": drift_yaw})
    try:
        seq = simulate_sequence(
            seed, size, "all", path.value, n_keyframes=keyframes, n_rooms=rooms,
            resolution=_parse_resolution(resolution), noise=noise,
        )  # fmt: skip
    except ValueError as exc:
        fail(str(exc))
    files = write_sequence(
        seq, out, snapshots=snapshots, descriptor=None if descriptor is None else descriptor.value
    )
    table = Table(title=f"simulated world seed {seed} -> {out}", title_justify="left")
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
    output: Annotated[
        Path | None, typer.Option("--output", "-o", help="PNG to write (default: MAP.png).")
    ] = None,
    title: Annotated[str | None, typer.Option(help="Title of the picture.")] = None,
) -> None:
    """Draw MAP from above as a PNG, optionally with a localization result and a local map."""
    from semloc.viz import map_figure, plot_localization, save_figure

    objmap = load_map(map_file)
    pose, pairs, status = _read_result(result) if result is not None else (None, [], None)
    local_map = load_map(local) if local is not None else None
    if local_map is not None and pose is None:
        fail("--local needs a --result with a pose to place the local objects")
    heading = title or f"{map_file.name}: {len(objmap)} objects" + (
        f" ({status})" if status else ""
    )
    fig, ax = map_figure(objmap.positions[:, :2])
    plot_localization(ax, objmap, local_map, pose, pairs, title=heading)
    path = save_figure(fig, output or map_file.with_suffix(".png"))
    console.print(f"wrote {path}")


def _read_result(path: Path) -> tuple[np.ndarray | None, list[tuple[str, str]], str | None]:
    """Pose, best pairs and status of a result file (or the true pose of a ground_truth.json)."""
    data = read_json(path)
    if not isinstance(data, dict) or not ("pose" in data or "T_global_local" in data):
        fail(f"{path}: not a localization result (no 'pose') nor a ground truth file")
    raw = data.get("pose", data.get("T_global_local"))
    pose = None
    if raw is not None:
        try:
            pose = np.asarray(raw, dtype=float)
        except (TypeError, ValueError):
            fail(f"{path}: pose must be a 4 x 4 array of numbers")
        if pose.shape != (4, 4) or not np.all(np.isfinite(pose)):
            fail(f"{path}: pose must be a finite 4 x 4 array, got shape {pose.shape}")
    pairs: list[tuple[str, str]] = []
    hypotheses = data.get("hypotheses") or []
    if isinstance(hypotheses, list) and hypotheses and isinstance(hypotheses[0], dict):
        for pair in hypotheses[0].get("pairs", []):
            if isinstance(pair, dict) and "global" in pair and "local" in pair:
                pairs.append((str(pair["global"]), str(pair["local"])))
    status = data.get("status") if isinstance(data.get("status"), str) else None
    return pose, pairs, status


class OutputFormat(StrEnum):
    text = "text"
    json = "json"


@app.command()
def localize(
    global_map: Annotated[Path, typer.Argument(help="Global (prior) map, semloc JSON.")],
    local_map: Annotated[
        Path, typer.Argument(help="Local map of detected objects, semloc JSON; replayed by `seen`.")
    ],
    gamma: Annotated[
        float | None,
        typer.Option(help="Merge threshold on the distance ratio.", show_default="0.8"),
    ] = None,
    delta: Annotated[
        float | None,
        typer.Option(
            help="Distance bound of the descriptors stored in the maps.", show_default="0.5"
        ),
    ] = None,
    top_k: Annotated[
        int | None,
        typer.Option(help="Number of distinct hypotheses to report.", show_default="10"),
    ] = None,
    tolerance: Annotated[
        float | None,
        typer.Option(
            help="Slack (m) on distance differences for biased centres.",
            show_default=str(LocalizerConfig().clustering.distance_tolerance),
        ),
    ] = None,
    descriptor: Annotated[
        DescriptorKind | None,
        typer.Option(
            help="Compute shape descriptors of this kind for objects with points and gate "
            "candidates with them (semloc.descriptors)."
        ),
    ] = None,
    descriptor_delta: Annotated[
        float | None,
        typer.Option(help="Gate bound with --descriptor (default: the kind's calibrated δ)."),
    ] = None,
    config: Annotated[
        Path | None,
        typer.Option(
            help="JSON file with LocalizerConfig fields (flat or nested); options given on "
            "the command line take precedence."
        ),
    ] = None,
    output_format: Annotated[
        OutputFormat, typer.Option("--format", help="Text (tables) or JSON.")
    ] = OutputFormat.text,
    output: Annotated[
        Path | None, typer.Option("--output", "-o", help="Write the output to this file.")
    ] = None,
) -> None:
    """Localize LOCAL in GLOBAL: association sets, hypotheses and the pose T_global_local."""
    settings = _read_config(config)
    given = dict(gamma=gamma, delta=delta, top_k=top_k, distance_tolerance=tolerance,
                 descriptor=None if descriptor is None else descriptor.value,
                 descriptor_delta=descriptor_delta)  # fmt: skip
    settings.update({key: value for key, value in given.items() if value is not None})
    try:
        cfg = LocalizerConfig(**settings)
    except ValidationError as exc:
        fail(f"invalid settings: {_first_error(exc)}")
    result = run_localize(load_map(global_map), load_map(local_map), cfg)
    if output_format is OutputFormat.json:
        text = json.dumps(result.to_dict(), indent=1) + "\n"
        if output is None:
            sys.stdout.write(text)
        else:
            write_atomic(output, text)
        return
    if output is None:
        print_result(result, console)
    else:
        recorder = Console(record=True, width=120, file=io.StringIO())
        print_result(result, recorder)
        write_atomic(output, recorder.export_text())


def _read_config(path: Path | None) -> dict:
    if path is None:
        return {}
    data = read_json(path)
    if not isinstance(data, dict):
        fail(f"{path}: must hold a JSON object of settings")
    return data


def _first_error(exc: ValidationError) -> str:
    error = exc.errors()[0]
    where = ".".join(str(p) for p in error["loc"])
    return f"{where}: {error['msg']}" if where else error["msg"]


def print_result(result: Result, out: Console) -> None:
    """Rich rendering of a Result: status line, pose, top hypotheses, timing."""
    colour = {"localized": "green", "ambiguous": "yellow", "failed": "red"}[result.status]
    out.print(f"status: [bold {colour}]{result.status}[/]")
    if result.pose is not None:
        out.print("pose T_global_local:")
        for row in result.pose:
            out.print("  " + "  ".join(f"{v:9.4f}" for v in row))
    table = Table(title="hypotheses (best first)")
    for column, width in (("rank", 4), ("score", 7), ("pairs", 5), ("fitness", 7),
                          ("yaw°", 6), ("t (m)", 17)):  # fmt: skip
        table.add_column(column, justify="right", no_wrap=True, min_width=width)
    table.add_column("associations local→global", no_wrap=True, overflow="ellipsis")
    for h in result.hypotheses:
        yaw = translation = "-"
        if h.pose is not None:
            yaw = f"{np.degrees(np.arctan2(h.pose[1, 0], h.pose[0, 0])):.1f}"
            translation = " ".join(f"{v:.2f}" for v in h.pose[:3, 3])
        shown = ", ".join(f"{l}→{g}" for g, l in h.pairs[:6]) + (" …" if len(h.pairs) > 6 else "")
        fitness = "-" if h.fitness is None else f"{h.fitness:.2f}"
        table.add_row(str(h.rank), f"{h.score:.2f}", str(len(h.pairs)), fitness, yaw,
                      translation, shown)  # fmt: skip
    if result.hypotheses:
        out.print(table)
    steps = len(result.steps)
    total = result.timing_ms.get("total", 0.0)
    out.print(f"{steps} update(s), {total:.1f} ms in all")


# Importers and crops (issue 6): `semloc convert`, `semloc crop`. ----------------------------


class ConvertKind(StrEnum):
    scannet = "scannet"
    scan2cad = "scan2cad"
    replica = "replica"
    rscan = "3rscan"


@app.command()
def convert(
    kind: Annotated[ConvertKind, typer.Argument(help="Dataset format of INPUT.")],
    source: Annotated[
        Path,
        typer.Argument(
            metavar="INPUT",
            help="scannet: scene folder or .aggregation.json; scan2cad: annotation JSON or its "
            "folder; replica: info_semantic.json or its folder; 3rscan: data.npy or its folder.",
        ),
    ],
    output: Annotated[Path, typer.Option("--output", "-o", help="Map file to write (JSON).")],
    labels: Annotated[
        str | None,
        typer.Option(
            help="Label vocabulary: scannet raw|nyu40 (default raw); 3rscan nyu40|rio27|eigen13 "
            "(default nyu40); scan2cad nyu40|shapenet (default nyu40)."
        ),
    ] = None,
    label_map: Annotated[
        Path | None,
        typer.Option(
            help="scannet: JSON {raw: label} or scannetv2-labels.combined.tsv mapping raw labels."
        ),
    ] = None,
    include_structure: Annotated[
        bool, typer.Option(help="Keep walls, floors and ceilings (left out by default).")
    ] = False,
    keep_unlabeled: Annotated[
        bool, typer.Option(help="replica, 3rscan: keep unannotated/placeholder objects.")
    ] = False,
    voxel: Annotated[
        float, typer.Option(help="Voxel edge (m) for downsampling object points; 0 keeps all.")
    ] = 0.05,
    shapenet: Annotated[
        Path | None, typer.Option(help="scan2cad: ShapeNet root (default: ./shapenet nearby).")
    ] = None,
    scan_dir: Annotated[
        Path | None,
        typer.Option(help="scan2cad: folder of the scan's labelled mesh (default: INPUT's)."),
    ] = None,
    scene: Annotated[
        str | None, typer.Option(help="scan2cad: which scan of a multi-scan annotation file.")
    ] = None,
    scan_output: Annotated[
        Path | None,
        typer.Option(help="scan2cad: where to write the scan-derived map (default OUT.scan.json)."),
    ] = None,
    seed: Annotated[int, typer.Option(help="Seed for sampled surface points.")] = 0,
    descriptor: _DescribeOption = None,
) -> None:
    """Convert a dataset scene into a semloc map (ScanNet, Scan2CAD, Replica, 3RScan)."""
    from semloc.io import importers, save_map

    options = dict(
        labels=labels,
        label_map=label_map,
        include_structure=include_structure,
        keep_unlabeled=keep_unlabeled,
        voxel=voxel,
        shapenet=shapenet,
        scan_dir=scan_dir,
        scene=scene,
        seed=seed,
    )
    try:
        maps = importers.convert(kind.value, source, **options)
    except ValueError as exc:
        if isinstance(exc, MapError):
            raise
        fail(str(exc))
    save_map(_described(maps[0], descriptor), output)
    console.print(f"wrote {output}: {len(maps[0])} objects")
    if len(maps) > 1 and maps[1] is not None:
        second = scan_output or output.with_name(output.name.removesuffix(".json") + ".scan.json")
        save_map(_described(maps[1], descriptor), second)
        console.print(f"wrote {second}: {len(maps[1])} objects (scan-derived)")


@app.command()
def crop(
    map_file: Annotated[Path, typer.Argument(metavar="MAP", help="Map to cut from (semloc JSON).")],
    center: Annotated[
        tuple[float, float, float], typer.Option(help="Viewpoint X Y Z in the map frame (m).")
    ],
    radius: Annotated[float, typer.Option(help="Objects whose centre is within this (m).")],
    output: Annotated[
        Path, typer.Option("--output", "-o", help="Local map to write; truth goes to .gt.json.")
    ],
    transform: Annotated[
        str,
        typer.Option(
            help="'random' (a frame at the viewpoint, random yaw about up), 'none', or a JSON "
            'file with a 4x4 T_global_local (a list of 4 rows, or {"T_global_local": ...}).'
        ),
    ] = "random",
    seed: Annotated[int, typer.Option(help="Seed of the random transform.")] = 0,
    recentre: Annotated[
        bool, typer.Option(help="Re-fit each object's centre and box to its visible points.")
    ] = False,
    descriptor: _DescribeOption = None,
) -> None:
    """Cut a local observation out of MAP (visible-side points, new frame, ground truth)."""
    from semloc.crop import crop_truth_to_dict, crop_with_truth
    from semloc.io import save_map

    objmap = load_map(map_file)
    pose: str | np.ndarray | None
    if transform == "random":
        pose = "random"
    elif transform == "none":
        pose = None
    else:
        pose = _read_pose(Path(transform))
    local, truth = crop_with_truth(objmap, center, radius, pose, seed, recentre=recentre)
    if len(local) == 0:
        fail(f"no object of {map_file} has its centre within {radius} m of {list(center)}")
    save_map(_described(local, descriptor), output)
    truth_path = output.with_name(output.name.removesuffix(".json") + ".gt.json")
    document = crop_truth_to_dict(truth, objmap.name)
    write_atomic(truth_path, json.dumps(document, indent=1) + "\n")
    console.print(f"wrote {output}: {len(local)} objects; ground truth in {truth_path}")


def _read_pose(path: Path) -> np.ndarray:
    data = read_json(path, what="--transform takes 'random', 'none' or a JSON file")
    if isinstance(data, dict):
        data = data.get("T_global_local")
    try:
        pose = np.asarray(data, dtype=float)
    except (TypeError, ValueError):
        pose = np.zeros(0)
    if pose.shape != (4, 4):
        fail(f"{path}: expected a 4x4 matrix (4 rows of 4 numbers)")
    return pose


# --- Benchmark: `bench` (issue 4; heavy imports stay inside) ----------------------------------


@app.command()
def bench(
    quick: Annotated[
        bool, typer.Option(help="Small but meaningful subset (2 sequences x 3 starts): minutes.")
    ] = False,
    out: Annotated[
        Path, typer.Option(help="Folder for results.csv, hypotheses.csv, the PNGs and report.md.")
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
    seed: Annotated[int, typer.Option(help="Seed of the worlds, start keyframes and methods.")] = 0,
    methods: Annotated[
        str,
        typer.Option(
            help=f"Comma-separated methods to compare: {','.join(DEFAULT_METHODS)}; opt-in: "
            f"{','.join(DESCRIPTOR_VARIANTS)} (semloc with the shape-descriptor gate)."
        ),
    ] = ",".join(DEFAULT_METHODS),
    sequences: Annotated[
        int | None, typer.Option(min=1, max=1000, help="Simulated sequences (default 6; quick 2).")
    ] = None,
    starts: Annotated[
        int | None,
        typer.Option(min=1, max=1000, help="Random starts per sequence (default 8; quick 3)."),
    ] = None,
    progress: Annotated[bool, typer.Option(help="Show a progress bar.")] = True,
    real_walks: Annotated[
        bool,
        typer.Option(
            help="Also the protocol on camera walks through the real scans (ScanNet "
            "scene0000_00, Scan2CAD scene0470_00): real_walks.csv, .png, .md."
        ),
    ] = False,
) -> None:
    """Reproduce the paper's comparison: semloc vs CLIPPER, random-walk, SegMatch, FPFH+RANSAC.

    Attempts from random keyframes of simulated sequences (when > 2 objects
    are seen, then +15 and +30 keyframes) against reconstruction, CAD and
    dynamic global maps, plus ablations over gamma and the local objects.
    """
    from semloc.eval.protocol import BenchConfig

    chosen = [m.strip() for m in methods.split(",") if m.strip()]
    known = DEFAULT_METHODS + DESCRIPTOR_VARIANTS
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
    if real_walks:
        from semloc.eval.realwalks import real_walk_data

        if real_walk_data() is None:
            fail("--real-walks: the real scans scannet/scene0000_00 and scan2cad/scene0470_00 "
                 "are not under $SEMLOC_DATA or ../shared/data/real")  # fmt: skip
        overrides["real_walks"] = True
    config = BenchConfig.quick(**overrides) if quick else BenchConfig(**overrides)
    from semloc.eval.report import summary_table
    from semloc.eval.runner import run_benchmark

    try:
        output = run_benchmark(config, out, scheduler, workers, progress=progress)
    except ValueError as exc:
        fail(str(exc))
    console.print(summary_table(output.rows, config.methods), soft_wrap=True)
    if output.real_walks is not None:
        console.print("real walks:")
        console.print(summary_table(output.real_walks, config.methods), soft_wrap=True)
    console.print(f"{len(output.rows)} attempts in {output.seconds:.0f} s; wrote {out}/report.md")


# Shape descriptors (issue 5): `semloc train-descriptor`, `semloc descriptors-eval`. -----------


class DescriptorChoice(StrEnum):
    geometric = "geometric"
    voxnet = "voxnet"
    both = "both"


@app.command("train-descriptor")
def train_descriptor(
    out: Annotated[Path, typer.Option(help="Weights file to write (.npz).")] = Path(
        "voxnet_weights.npz"
    ),
    seed: Annotated[
        int, typer.Option(help="Seed of the data, the initialisation and batches.")
    ] = 0,
    epochs: Annotated[int, typer.Option(min=1, help="Training epochs.")] = 6,
    views: Annotated[int, typer.Option(min=6, help="Partial views per training instance.")] = 48,
    full_views: Annotated[
        int, typer.Option(min=2, help="Whole-surface (CAD-style) views per instance.")
    ] = 12,
    batches: Annotated[int, typer.Option(min=1, help="Batches per epoch.")] = 30,
    fixture: Annotated[
        Path | None,
        typer.Option(help="Also write test grids + torch embeddings (.npz) for the numpy test."),
    ] = None,
) -> None:
    """Train the VoxNet descriptor (triplet loss on simulated objects); needs torch.

    The defaults reproduce the shipped weights (src/semloc/descriptors/voxnet_weights.npz).
    """
    import importlib.util

    if importlib.util.find_spec("torch") is None:
        from semloc.descriptors.train import TORCH_HINT

        fail(TORCH_HINT)
    from semloc.descriptors.train import TrainConfig, save_weights, train
    from semloc.descriptors.voxnet import WEIGHTS_FILE, load_weights

    config = TrainConfig(
        seed=seed, epochs=epochs, views=views, full_views=full_views, batches_per_epoch=batches
    )
    weights, summary = train(config, log=console.print)
    save_weights(weights, out)
    size = out.stat().st_size / 1e6
    console.print(f"wrote {out} ({size:.2f} MB) in {summary['seconds']:.0f} s")
    if fixture is not None:
        save_weights(summary["fixture"], fixture)
        console.print(f"wrote {fixture}")
    if WEIGHTS_FILE.exists() and out.resolve() != WEIGHTS_FILE.resolve():
        shipped = load_weights()
        diff = max(float(np.abs(shipped[k] - weights[k]).max()) for k in weights)
        same = "identical to" if diff == 0 else f"max |diff| {diff:.2e} from"
        console.print(f"{same} the shipped weights")


@app.command("descriptors-eval")
def descriptors_eval(
    kind: Annotated[DescriptorChoice, typer.Option(help="Descriptor kind(s) to evaluate.")] = (
        DescriptorChoice.both
    ),
    out: Annotated[
        Path | None, typer.Option(help="Folder for descriptors_eval.json and figures.")
    ] = None,
    seed: Annotated[int, typer.Option(help="Seed of the evaluation views.")] = 1,
    views: Annotated[int, typer.Option(min=1, help="Partial views per instance.")] = 20,
    sequences: Annotated[
        int, typer.Option(min=0, help="Simulated sequences for calibration and the gate effect.")
    ] = 3,
    attempts: Annotated[
        int, typer.Option(min=1, help="Relocalization attempts per sequence and map kind.")
    ] = 8,
    window: Annotated[
        int, typer.Option(min=2, help="Keyframes fused into the local map of an attempt.")
    ] = 6,
) -> None:
    """Retrieval (top-1/top-5) on held-out styles, the Scan2CAD check, δ and the gate's effect."""
    from semloc.descriptors.evaluate import EvalConfig, print_report, run_evaluation

    kinds = ["geometric", "voxnet"] if kind is DescriptorChoice.both else [kind.value]
    config = EvalConfig(
        kinds=kinds, seed=seed, views=views, sequences=sequences, attempts=attempts, window=window
    )
    report = run_evaluation(config, log=console.print)
    print_report(report, console)
    if out is not None:
        from semloc.descriptors.evaluate import write_report

        for path in write_report(report, out):
            console.print(f"wrote {path}")


def main(argv: list[str] | None = None) -> int:
    """Entry point of the `semloc` script: runs the app and maps errors to exit status 2."""
    try:
        app(args=argv, standalone_mode=False)
    except (MapError, CliError) as exc:
        print(f"semloc: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"semloc: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("semloc: interrupted", file=sys.stderr)
        return 130
    except SystemExit as exc:  # --help and typer.Exit pass through unchanged
        return int(exc.code or 0)
    except typer.Abort:
        return 130
    except Exception as exc:
        # click (vendored by typer) usage errors: one line, status 2 like click's own
        if hasattr(exc, "format_message") and hasattr(exc, "exit_code"):
            print(f"semloc: error: {exc.format_message()}", file=sys.stderr)
            return 2
        raise
    return 0


if __name__ == "__main__":
    sys.exit(main())
