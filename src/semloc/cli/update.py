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

import numpy as np
import typer

from semloc.association import CandidateIndex
from semloc.changes import Changes, Moved, explain
from semloc.cli.app import app, console, exit_statuses
from semloc.cli.files import check_output, check_separate, map_outputs, map_paths, read_result
from semloc.cli.render import print_centres_only, print_changes
from semloc.io import load_map
from semloc.io.native import map_files, write_files
from semloc.localizer import LocalizerConfig, localize
from semloc.maps import ObjectMap, SemanticObject


@app.command("update-map", epilog=exit_statuses(not_localized=True))
def update_map(
    global_map: Annotated[Path, typer.Argument(help="Global (prior) map, semloc JSON.")],
    local_map: Annotated[Path, typer.Argument(help="Local map of detected objects.")],
    output: Annotated[Path, typer.Option("--output", "-o", help="The updated map file.")],
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
) -> None:
    """Write GLOBAL with the changes LOCAL shows applied: moved, new, missing objects."""
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
        changes = Changes() if pose is None else _explained(prior, local, pose, saved.pairs)
    if pose is None or not (status == "localized" or (accept_ambiguous and status == "ambiguous")):
        console.print(f"not localized (status {status}): no map written")
        raise typer.Exit(1)
    print_changes(changes, console)
    print_centres_only(local, changes, console)
    updated = applied(prior, local, pose, changes)
    write_files(map_files(updated, output))
    console.print(
        f"wrote {output}: {len(changes.moved)} moved, {len(changes.new)} new, "
        f"{len(changes.missing)} flagged missing"
    )


def applied(prior: ObjectMap, local: ObjectMap, pose: np.ndarray, changes: Changes) -> ObjectMap:
    """`prior` with `changes` applied (see the module docstring)."""
    seen = {o.id: o.transformed(pose) for o in local}
    moved = {m.global_id: m for m in changes.moved}
    missing = set(changes.missing)
    found = set(changes.matched) | set(moved)
    objects = []
    for obj in prior:
        if obj.id in moved:
            obj = _moved(obj, seen[moved[obj.id].local_id], moved[obj.id])
        if obj.id in missing:
            obj = obj.replace(extra={**obj.extra, "missing": True})
        elif obj.id in found and "missing" in obj.extra:  # flagged before, seen again
            obj = obj.replace(extra={k: v for k, v in obj.extra.items() if k != "missing"})
        objects.append(obj)
    taken = {o.id for o in objects}
    for local_id in changes.new:
        new = seen[local_id]
        new_id = local_id if local_id not in taken else f"new:{local_id}"
        taken.add(new_id)
        objects.append(new.replace(id=new_id, extra={**new.extra, "new": True}))
    return prior.with_objects(objects)


def _moved(obj: SemanticObject, observed: SemanticObject, change: Moved) -> SemanticObject:
    shift = observed.position - obj.position
    points = None if obj.points is None else obj.points + shift
    return obj.replace(
        position=observed.position,
        points=points,
        extra={**obj.extra, "moved_from": obj.position.tolist(), "moved_m": change.offset_m},
    )


def _explained(prior: ObjectMap, local: ObjectMap, pose, pairs) -> Changes:
    """The changes of a saved answer, with the Localizer's candidate rule."""
    config = LocalizerConfig()
    index = CandidateIndex(prior, config.association)
    candidates = {o.id: index.candidates(o) for o in local}
    return explain(prior, list(local), pose, pairs, candidates, config.changes)
