"""`semloc align`: map-to-map alignment of two sessions' or two robots' object maps.

B is aligned into A (`semloc.align`); `-o` gets B in A's frame (same ids), `--merged` one map
with every object once and its provenance (`semloc.tools.merge`), `--g2o` the relative pose as
one `EDGE_SE3:QUAT` line with its information matrix (`semloc.io.g2o`), `--result` the Result as
JSON (the shape of `semloc localize --format json`).  All of them are written or none, and
none may be an input or another output's file (a map's points file included).  When B
cannot be placed (status `failed`, or `ambiguous` unless `--accept-ambiguous`) the result and
its reason are printed, no map or edge is written, and the exit status is still 0: the inputs
were valid.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import numpy as np
import typer
from pydantic import ValidationError

from semloc.alignment import align as run_align
from semloc.alignment import pose_information
from semloc.cli.app import app, console, exit_statuses, fail, first_error
from semloc.cli.files import (
    check_finite,
    check_output,
    check_separate,
    map_outputs,
    map_paths,
    read_config,
)
from semloc.cli.render import print_result
from semloc.io import load_map
from semloc.io.g2o import edge_line
from semloc.io.native import map_files
from semloc.io.output import write_files
from semloc.localizer import LocalizerConfig
from semloc.maps import ObjectMap
from semloc.pictures.display import for_rich
from semloc.results import Result
from semloc.tools.merge import merged_map


@app.command(
    epilog=exit_statuses("an answer, placed or not (not placed: only --result is written)")
)
def align(
    map_a: Annotated[Path, typer.Argument(help="First map (the reference frame), semloc JSON.")],
    map_b: Annotated[Path, typer.Argument(help="Second map, aligned into the first.")],
    output: Annotated[
        Path | None,
        typer.Option("--output", "-o", help="Write B in A's frame (same ids) to this map file."),
    ] = None,
    merged: Annotated[
        Path | None,
        typer.Option(help="Write A and B as one map: matched objects fused, with provenance."),
    ] = None,
    g2o: Annotated[
        Path | None,
        typer.Option(
            "--g2o",
            help="Write T_A_B and its information matrix as one g2o EDGE_SE3:QUAT line.",
        ),
    ] = None,
    result_file: Annotated[
        Path | None, typer.Option("--result", help="Write the Result as JSON to this file.")
    ] = None,
    gamma: Annotated[
        float | None, typer.Option(help="Merge threshold on the distance ratio.")
    ] = None,
    config: Annotated[
        Path | None, typer.Option(help="Settings file, JSON or .yaml (as for `localize`).")
    ] = None,
    accept_ambiguous: Annotated[
        bool,
        typer.Option(
            "--accept-ambiguous",
            help="Also write the outputs of an `ambiguous` answer's best place.",
        ),
    ] = False,
) -> None:
    """Align map B into map A: the transform T_A_B, the correspondences, and B in A's frame.

    Only --result is written unless B is placed: `localized` (or `ambiguous`, --accept-ambiguous).

    The files are written all or none; none may be an input or another output's file.
    """
    check_finite(gamma=gamma)
    targets = {"--output": output, "--merged": merged, "--g2o": g2o, "--result": result_file}
    for option, path in targets.items():
        if path is not None:
            check_output(path, option)
    settings = read_config(config)
    if gamma is not None:
        settings["gamma"] = gamma
    try:
        cfg = LocalizerConfig(**settings)
    except ValidationError as exc:
        fail(f"invalid settings: {first_error(exc)}")
    a, b = load_map(map_a), load_map(map_b)
    writes = {
        option: map_outputs(path) if option in ("--output", "--merged") else path
        for option, path in targets.items()
    }
    inputs = {**map_paths(map_a, a, "map A"), **map_paths(map_b, b, "map B")}
    check_separate(writes, {**inputs, config: "the --config file"})
    result = run_align(a, b, cfg)
    print_result(result, console, frames=("A", "B"))
    placed = result.status == "localized" or (accept_ambiguous and result.status == "ambiguous")
    files: list[tuple[Path, bytes | str]] = []
    if placed and result.pose is not None:
        files = _outputs(a, b, result, output, merged, g2o)
    elif output or merged or g2o:
        console.print(f"[yellow]not written[/] (status {result.status}): {for_rich(result.reason)}")
    if result_file is not None:
        files.append((result_file, result.to_json()))
    if files:
        for path in write_files(files):
            console.print(f"wrote {for_rich(path, None)}")


def _outputs(
    a: ObjectMap, b: ObjectMap, result: Result, output: Path | None, merged: Path | None,
    g2o: Path | None,
) -> list[tuple[Path, bytes | str]]:  # fmt: skip
    """The files of a placed B: B in A's frame, the merged map, the g2o edge."""
    pose = result.pose
    assert pose is not None
    b_in_a = b.transformed(pose)
    pairs = result.hypotheses[0].pairs
    files: list[tuple[Path, bytes | str]] = []
    if output is not None:
        files += map_files(b_in_a, output)
    if merged is not None:
        files += map_files(merged_map(a, b_in_a, pairs), merged)
    if g2o is not None:
        local = np.array([b.get(l).position for _, l in pairs])
        glob = np.array([a.get(g).position for g, _ in pairs])
        files.append((g2o, edge_line(pose, pose_information(pose, local, glob))))
    return files
