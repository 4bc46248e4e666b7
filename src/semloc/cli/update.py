"""`semloc update-map`: the global map with what a localization found changed applied.

LOCAL is localized in GLOBAL (or the answer is read from `--result`, a JSON file of
`semloc localize --format json`); the best hypothesis' changes (`semloc.changes`) are applied:
a moved object is put where it was observed (its points shifted with it, its other fields
kept), a new object is added in the global frame (its id prefixed `new:` when taken), a missing
one is flagged `"missing": true` (kept: one look is no proof that it is gone; the flag goes
when a later view sees the object again, where it was or moved).  Every change is
listed; the new map is written all or nothing.  Nothing is written when the answer is not
`localized` (unless `--accept-ambiguous`): the command then says so and exits with status 1,
so that a script can tell.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from semloc.changes import Changes, answer_changes, apply_changes
from semloc.cli import remote
from semloc.cli.app import app, console, exit_statuses, fail
from semloc.cli.files import check_output, check_separate, map_outputs, map_paths, read_result
from semloc.cli.render import print_centres_only, print_changes
from semloc.io import load_map
from semloc.io.native import map_files
from semloc.io.output import write_files
from semloc.localizer import localize


@app.command("update-map", epilog=exit_statuses(not_localized=True))
def update_map(
    global_map: Annotated[
        Path, typer.Argument(help="Global (prior) map, semloc JSON (with --server: its id there).")
    ],
    local_map: Annotated[Path, typer.Argument(help="Local map of detected objects.")],
    output: Annotated[
        Path | None,
        typer.Option(
            "--output", "-o", help="The updated map file (with --server: optional, a copy)."
        ),
    ] = None,
    result_file: Annotated[
        Path | None,
        typer.Option("--result", help="Use this saved answer (`localize --format json`)."),
    ] = None,
    accept_ambiguous: Annotated[
        bool,
        typer.Option(
            "--accept-ambiguous",
            help="Also apply the changes of an `ambiguous` answer's best place.",
        ),
    ] = False,
    server: remote.ServerOption = None,
    token: remote.TokenOption = None,
) -> None:
    """Write GLOBAL with the changes LOCAL shows applied: moved, new, missing objects.

    With --server, the changes become the next version of the map GLOBAL on that server (the
    token needs `localize` and `write` on it; with -o also `read`)."""
    if server is not None:
        if result_file is not None:
            fail("--result: with --server the answer comes from the server (leave it out)")
        if output is not None:
            check_output(output)
            check_separate({"--output": map_outputs(output)}, {local_map: "the local map"})
        remote.update_map(server, token, str(global_map), local_map, output, accept_ambiguous)
        return
    if output is None:
        fail("--output / -o is needed: the file of the updated map (or --server URL)")
    check_output(output)
    prior, local = load_map(global_map), load_map(local_map)
    inputs = {**map_paths(global_map, prior, "the global map"),
              **map_paths(local_map, local, "the local map"), result_file: "the --result file"}  # fmt: skip
    check_separate({"--output": map_outputs(output)}, inputs)
    if result_file is None:
        result = localize(prior, local)
        status, pose, changes = result.status, result.pose, result.changes
    else:
        saved = read_result(result_file)
        status, pose = saved.status, saved.pose
        changes = Changes() if pose is None else answer_changes(prior, local, pose, saved.pairs)
    if pose is None or not (status == "localized" or (accept_ambiguous and status == "ambiguous")):
        console.print(f"not localized (status {status}): no map written")
        raise typer.Exit(1)
    print_changes(changes, console)
    print_centres_only(local, changes, console)
    updated = apply_changes(prior, local, pose, changes)
    write_files(map_files(updated, output))
    console.print(
        f"wrote {output}: {len(changes.moved)} moved, {len(changes.new)} new, "
        f"{len(changes.missing)} flagged missing"
    )
