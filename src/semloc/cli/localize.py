"""`semloc localize`: relocalize a local map in a global map, print or write the Result.

With `--gt` (a file holding the true `T_global_local`, as `semloc crop` writes) it also
prints the pose error and the paper's success at 15° / 0.5 m, and adds `ground_truth` to the
JSON output.  It reports how each local label was read against the map's labels (exact,
synonym, parent / child class, similar, embedding or unmatched: a table, or `labels` in the
JSON); an unmatched label is a warning on stderr, never an error.  Long replays show a progress bar on stderr when it is a terminal.

`--near X Y Z --radius R` (both or neither) is a position prior (`semloc.Prior`): the local
frame's origin lies within R metres of (X, Y, Z) in the global map; the JSON output carries
it as `prior`, and each hypothesis says whether it lies outside it (`outside_prior`).
"""

from __future__ import annotations

import io
from enum import StrEnum
from pathlib import Path
from typing import Annotated

import typer
from pydantic import ValidationError
from rich.console import Console

from semloc.association import DESCRIBERS
from semloc.cli import remote
from semloc.cli.app import (
    app,
    choices,
    console,
    err_console,
    exit_statuses,
    fail,
    first_error,
    with_default,
)
from semloc.cli.files import (
    check_finite,
    check_output,
    check_separate,
    emit,
    map_paths,
    read_config,
    read_label_map,
    read_pose,
)
from semloc.cli.options import NearOption, RadiusOption, prior_option
from semloc.cli.render import (
    print_centres_only,
    print_ground_truth,
    print_labels,
    print_result,
    replay_progress,
    warn_unmatched,
)
from semloc.compiling import warm_up
from semloc.eval.success import ground_truth_report
from semloc.io import load_map, write_atomic
from semloc.localizer import LocalizerConfig
from semloc.localizer import localize as run_localize

DescriptorKind = choices("DescriptorKind", DESCRIBERS)
DEFAULTS = LocalizerConfig()


class OutputFormat(StrEnum):
    text = "text"
    json = "json"


@app.command(epilog=exit_statuses("an answer, localized or not (it says why)"))
def localize(
    global_map: Annotated[
        Path, typer.Argument(help="Global (prior) map, semloc JSON (with --server: its id there).")
    ],
    local_map: Annotated[
        Path, typer.Argument(help="Local map of detected objects, semloc JSON; replayed by `seen`.")
    ],
    gamma: Annotated[
        float | None,
        typer.Option(help=with_default("Merge threshold on the distance ratio.", DEFAULTS.gamma)),
    ] = None,
    delta: Annotated[
        float | None,
        typer.Option(
            help=with_default(
                "Distance bound of the descriptors stored in the maps.", DEFAULTS.delta
            )
        ),
    ] = None,
    top_k: Annotated[
        int | None,
        typer.Option(help=with_default("Number of distinct hypotheses to report.", DEFAULTS.top_k)),
    ] = None,
    tolerance: Annotated[
        float | None,
        typer.Option(
            help=with_default(
                "Slack (m) on distance differences for biased centres.",
                DEFAULTS.clustering.distance_tolerance,
            )
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
    label_map: Annotated[
        Path | None,
        typer.Option(
            "--label-map",
            help="Labels mapped before comparing, JSON or .yaml: an object {local or map label: "
            'label}, e.g. {"sofa": "couch"}; it wins over the shipped taxonomy.',
        ),
    ] = None,
    config: Annotated[
        Path | None,
        typer.Option(
            help="Settings file, JSON or .yaml (`semloc config --dump` prints them all; flat or "
            "nested by stage); options given on the command line take precedence."
        ),
    ] = None,
    gt: Annotated[
        Path | None,
        typer.Option(
            "--gt",
            help="Ground truth: a JSON file with the true T_global_local (as `semloc crop` "
            "writes); prints the pose error and success at 15° / 0.5 m.",
        ),
    ] = None,
    output_format: Annotated[
        OutputFormat, typer.Option("--format", help="Text (tables) or JSON.")
    ] = OutputFormat.text,
    output: Annotated[
        Path | None, typer.Option("--output", "-o", help="Write the output to this file.")
    ] = None,
    near: NearOption = None,
    radius: RadiusOption = None,
    server: remote.ServerOption = None,
    token: remote.TokenOption = None,
) -> None:
    """Localize LOCAL in GLOBAL: association sets, hypotheses and the pose T_global_local."""
    prior = prior_option(near, radius)
    if server is not None:
        remote.refuse_local_settings(
            gamma=gamma, delta=delta, top_k=top_k, tolerance=tolerance, descriptor=descriptor,
            descriptor_delta=descriptor_delta, label_map=label_map, config=config,
        )  # fmt: skip
        if output is not None:
            check_output(output)
            check_separate({"--output": output}, {local_map: "the local map", gt: "the --gt file"})
        truth = read_pose(gt, "--gt takes a file with T_global_local") if gt is not None else None
        as_json = output_format is OutputFormat.json
        remote.localize(server, token, str(global_map), local_map, truth, as_json, output, prior)
        return
    check_finite(gamma=gamma, delta=delta, tolerance=tolerance, descriptor_delta=descriptor_delta)
    if output is not None:
        check_output(output)
    settings = read_config(config)
    given = dict(gamma=gamma, delta=delta, top_k=top_k, distance_tolerance=tolerance,
                 descriptor=None if descriptor is None else descriptor.value,
                 descriptor_delta=descriptor_delta)  # fmt: skip
    settings.update({key: value for key, value in given.items() if value is not None})
    if label_map is not None:
        settings["label_map"] = read_label_map(label_map)
    try:
        cfg = LocalizerConfig(**settings)
    except ValidationError as exc:
        fail(f"invalid settings: {first_error(exc)}")
    truth = read_pose(gt, "--gt takes a file with T_global_local") if gt is not None else None
    global_objects, local_objects = load_map(global_map), load_map(local_map)
    inputs = {**map_paths(global_map, global_objects, "the global map"),
              **map_paths(local_map, local_objects, "the local map"),
              config: "the --config file", label_map: "the --label-map file", gt: "the --gt file"}  # fmt: skip
    check_separate({"--output": output}, inputs)
    warm = warm_up(lambda text: err_console.print(f"{text}…", style="dim"))
    with replay_progress(err_console, local_objects) as progress:
        result = run_localize(global_objects, local_objects, cfg, progress=progress, prior=prior)
    report = None if truth is None else ground_truth_report(result.pose, result.hypotheses, truth)
    labels = result.labels  # read by the Localizer's own candidate gate
    if len(global_objects):  # an empty map: the result's reason says so, once
        warn_unmatched(labels, err_console)
    if output_format is OutputFormat.json:
        emit(result.to_json(warm_up_ms=warm.seconds * 1000, ground_truth=report), output)
        return
    target = console if output is None else Console(record=True, width=120, file=io.StringIO())
    print_result(result, target, warm)
    print_centres_only(local_objects, result.changes, target)
    print_labels(labels, target)
    if report is not None:
        print_ground_truth(report, target)
    if output is not None:
        write_atomic(output, target.export_text())
