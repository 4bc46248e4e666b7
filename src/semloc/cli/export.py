"""`semloc export`: a map (and local objects placed by a result's pose) as a coloured PLY, or
(`--format dsg`) a map as a Spark-DSG scene graph (`semloc.io.dsg`, the `semloc[dsg]` extra).

Every point is coloured by its object's label (`semloc.pictures.colors`, as in the pictures); local
objects are drawn darker and flagged by the vertex property `local` = 1, so that a viewer
(MeshLab, CloudCompare, Open3D) shows where they landed.  Objects without points are one
point at their centre.  Needs only the core install.
"""

from __future__ import annotations

from enum import StrEnum
from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from semloc.cli.app import app, console, fail
from semloc.cli.extras import need
from semloc.cli.files import check_output, check_separate, check_suffix, map_paths, read_result
from semloc.io import load_map, write_atomic
from semloc.io.dsg import dsg_bytes
from semloc.io.ply import write_ply
from semloc.maps import ObjectMap
from semloc.pictures.colors import label_colors

LOCAL_SHADE = 0.6
"""Local objects keep their label's hue at this brightness."""

VERTEX = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("red", "u1"), ("green", "u1"),
                   ("blue", "u1"), ("local", "u1")])  # fmt: skip


def scene_vertices(global_map: ObjectMap, placed_local: ObjectMap | None) -> np.ndarray:
    """PLY vertex records of the global objects and (placed) local objects, label-coloured."""
    maps = [global_map] + ([] if placed_local is None else [placed_local])
    colors = label_colors(label for objmap in maps for label in objmap.labels)
    records = []
    for flag, objmap in enumerate(maps):
        points, rgb = objmap.cloud(colors)
        block = np.zeros(len(points), dtype=VERTEX)
        block["x"], block["y"], block["z"] = points.T
        shade = LOCAL_SHADE if flag else 1.0
        for channel, column in zip(("red", "green", "blue"), (rgb * 255 * shade).T):
            block[channel] = np.round(column)
        block["local"] = flag
        records.append(block)
    return np.concatenate(records)


class ExportFormat(StrEnum):
    ply = "ply"
    dsg = "dsg"


def _export_dsg(
    map_file: Path, output: Path, result: Path | None, local: Path | None, ascii_ply: bool
) -> None:
    """MAP as a Spark-DSG scene graph (ids, labels, positions, boxes, points, missing flags)."""
    if result is not None or local is not None or ascii_ply:
        fail("--format dsg writes MAP alone: --result, --local and --ascii do not apply")
    need("export --format dsg", "dsg")
    check_output(output)
    objmap = load_map(map_file)
    check_separate({"--output": [output]}, map_paths(map_file, objmap, "MAP"))
    write_atomic(output, dsg_bytes(objmap, output))
    console.print(f"wrote {output}: a scene graph of {len(objmap)} objects")


@app.command()
def export(
    map_file: Annotated[Path, typer.Argument(metavar="MAP", help="A semloc map (JSON).")],
    output: Annotated[
        Path, typer.Option("--output", "-o", help="PLY file to write (a graph with --format dsg).")
    ],
    result: Annotated[
        Path | None,
        typer.Option(help="Result JSON (semloc localize --format json) or a ground truth file."),
    ] = None,
    local: Annotated[
        Path | None, typer.Option(help="Local map to place into MAP by the result's pose.")
    ] = None,
    ascii_ply: Annotated[bool, typer.Option("--ascii", help="Text PLY instead of binary.")] = False,
    output_format: Annotated[
        ExportFormat,
        typer.Option(
            "--format",
            help="ply, or dsg: a Spark-DSG scene graph (.json, else binary; the dsg extra).",
        ),
    ] = ExportFormat.ply,
) -> None:
    """Write MAP's objects (and --local ones placed by --result) as a PLY coloured by label,
    or MAP as a Spark-DSG scene graph with --format dsg."""
    if output_format is ExportFormat.dsg:
        _export_dsg(map_file, output, result, local, ascii_ply)
        return
    check_suffix(output, ".ply", "--output", "a PLY point cloud")
    global_map = load_map(map_file)
    inputs = {**map_paths(map_file, global_map, "MAP"), result: "the --result file"}
    placed = None
    if local is not None:
        pose = read_result(result).pose if result is not None else None
        if pose is None:
            fail("--local needs a --result with a pose to place the local objects")
        local_map = load_map(local)
        inputs.update(map_paths(local, local_map, "the --local map"))
        placed = local_map.transformed(pose)
    elif result is not None:
        fail("--result places local objects: give them with --local")
    check_separate({"--output": output}, inputs)
    vertices = scene_vertices(global_map, placed)
    write_ply(output, vertices, binary=not ascii_ply)
    placed_text = "" if placed is None else f" and {len(placed)} local objects"
    console.print(
        f"wrote {output}: {len(global_map)} global objects{placed_text}, {len(vertices)} points"
    )
