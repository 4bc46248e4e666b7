"""`semloc convert` (dataset scenes -> semloc maps, from the importer registry) and `semloc crop`."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from semloc.cli.app import MAX_SEED, app, choices, console, fail
from semloc.cli.extras import need
from semloc.cli.files import (
    check_finite,
    check_output,
    check_separate,
    map_outputs,
    map_paths,
    read_pose,
)
from semloc.cli.options import DescribeOption, with_descriptors
from semloc.io import importers, load_map
from semloc.io.importers import IMPORTERS
from semloc.io.native import map_files
from semloc.io.output import write_files
from semloc.maps import MapError
from semloc.pictures.display import for_rich
from semloc.sim.crop import crop_truth_to_dict, crop_with_truth

ConvertKind = choices("ConvertKind", IMPORTERS)
_SOURCE_HELP = "; ".join(f"{name}: {imp.source_help}" for name, imp in IMPORTERS.items())
_LABELS_HELP = "Label vocabulary: " + "; ".join(
    f"{name} {imp.labels_help}" for name, imp in IMPORTERS.items() if imp.labels_help
)


@app.command()
def convert(
    kind: Annotated[ConvertKind, typer.Argument(help="Dataset format of INPUT.")],
    source: Annotated[
        Path,
        typer.Argument(
            metavar="INPUT",
            help=_SOURCE_HELP + ".",
        ),
    ],
    output: Annotated[Path, typer.Option("--output", "-o", help="Map file to write (JSON).")],
    labels: Annotated[
        str | None,
        typer.Option(help=_LABELS_HELP + "."),
    ] = None,
    label_map: Annotated[
        Path | None,
        typer.Option(
            help="scannet: a JSON file {raw: label}, or ScanNet's label table (.tsv), mapping "
            'raw labels; dsg: a JSON file {"3": "chair"} naming label numbers.'
        ),
    ] = None,
    include_structure: Annotated[
        bool,
        typer.Option(
            "--include-structure", help="Keep walls, floors and ceilings (left out by default)."
        ),
    ] = False,
    keep_unlabeled: Annotated[
        bool,
        typer.Option(
            "--keep-unlabeled", help="replica, 3rscan: keep unannotated and placeholder objects."
        ),
    ] = False,
    voxel: Annotated[
        float,
        typer.Option(
            min=0, max=100, help="Voxel edge (m) for downsampling object points; 0 keeps all."
        ),
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
    seed: Annotated[
        int, typer.Option(min=0, max=MAX_SEED, help="Seed for sampled surface points.")
    ] = 0,
    descriptor: DescribeOption = None,
) -> None:
    """Convert a dataset scene into a semloc map (the formats: see KIND).

    With a second (scan-derived) map both files are written, or neither."""
    check_finite(voxel=voxel)
    if kind.value == "dsg":
        need("convert dsg", "dsg")
    check_output(output)
    second = None
    if kind.value == "scan2cad":
        second = scan_output or output.with_name(output.name.removesuffix(".json") + ".scan.json")
        check_output(second, "--scan-output")
    elif scan_output is not None:
        fail(f"--scan-output does not apply to {kind.value}")
    inputs = {source: "INPUT", label_map: "the --label-map file"}
    check_separate({"--output": map_outputs(output), "--scan-output": map_outputs(second)}, inputs)
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
    files = map_files(with_descriptors(maps[0], descriptor), output)
    scan_map = maps[1] if len(maps) > 1 else None
    if scan_map is not None and second is not None:
        files += map_files(with_descriptors(scan_map, descriptor), second)
    write_files(files)
    console.print(f"wrote {for_rich(output, None)}: {len(maps[0])} objects")
    if scan_map is not None and second is not None:
        console.print(f"wrote {for_rich(second, None)}: {len(scan_map)} objects (scan-derived)")


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
    seed: Annotated[
        int, typer.Option(min=0, max=MAX_SEED, help="Seed of the random transform.")
    ] = 0,
    recentre: Annotated[
        bool,
        typer.Option(
            "--recentre", help="Re-fit each object's centre and box to its visible points."
        ),
    ] = False,
    descriptor: DescribeOption = None,
) -> None:
    """Cut a local observation out of MAP (visible-side points, new frame, ground truth).

    The local map and its ground truth are written both, or neither."""
    check_finite(center=center, radius=radius)
    check_output(output)
    objmap = load_map(map_file)
    pose: str | np.ndarray | None
    if transform == "random":
        pose = "random"
    elif transform == "none":
        pose = None
    else:
        pose = read_pose(Path(transform), "--transform takes 'random', 'none' or a JSON file")
    truth_path = output.with_name(output.name.removesuffix(".json") + ".gt.json")
    inputs = map_paths(map_file, objmap, "MAP")
    if transform not in ("random", "none"):
        inputs[Path(transform)] = "the --transform file"
    check_separate({"--output": [*map_outputs(output), truth_path]}, inputs)
    local, truth = crop_with_truth(objmap, center, radius, pose, seed, recentre=recentre)
    if len(local) == 0:
        fail(f"no object of {map_file} has its centre within {radius} m of {list(center)}")
    document = crop_truth_to_dict(truth, objmap.name)
    truth_text = json.dumps(document, indent=1, allow_nan=False) + "\n"
    write_files([*map_files(with_descriptors(local, descriptor), output), (truth_path, truth_text)])
    shown = for_rich(output, None), for_rich(truth_path, None)
    console.print(f"wrote {shown[0]}: {len(local)} objects; ground truth in {shown[1]}")
