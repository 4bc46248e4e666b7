"""`semloc localize`: relocalize a local map in a global map, print or write the Result."""

from __future__ import annotations

import io
import json
import sys
from enum import StrEnum
from pathlib import Path
from typing import Annotated

import typer
from pydantic import ValidationError
from rich.console import Console

from semloc.association import DESCRIBERS
from semloc.cli.app import app, choices, console, fail, first_error
from semloc.cli.files import check_finite, check_output, read_config
from semloc.cli.render import print_result
from semloc.io import load_map, write_atomic
from semloc.localizer import LocalizerConfig
from semloc.localizer import localize as run_localize

DescriptorKind = choices("DescriptorKind", DESCRIBERS)


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
    check_finite(gamma=gamma, delta=delta, tolerance=tolerance, descriptor_delta=descriptor_delta)
    if output is not None:
        check_output(output)
    settings = read_config(config)
    given = dict(gamma=gamma, delta=delta, top_k=top_k, distance_tolerance=tolerance,
                 descriptor=None if descriptor is None else descriptor.value,
                 descriptor_delta=descriptor_delta)  # fmt: skip
    settings.update({key: value for key, value in given.items() if value is not None})
    try:
        cfg = LocalizerConfig(**settings)
    except ValidationError as exc:
        fail(f"invalid settings: {first_error(exc)}")
    result = run_localize(load_map(global_map), load_map(local_map), cfg)
    if output_format is OutputFormat.json:
        text = json.dumps(result.to_dict(), indent=1, allow_nan=False) + "\n"
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
