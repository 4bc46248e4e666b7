"""`semloc localize --server URL` and `semloc update-map --server URL`: the same commands
against a `semloc serve` server (`semloc.client`), where GLOBAL names the map on the server;
`connect` and `call` (one line for a refusal) also serve `semloc maps` (`cli/maps.py`).

The localizer's settings are the server's there, so the options that change them are refused
with `--server`.  A server's refusal is one line naming the server and what it said (exit 2);
`update-map` exits 1 when nothing was written (not localized, nothing changed, or the map
moved on since the answer: 409).
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console

from semloc import schema
from semloc.cli.app import console, fail
from semloc.cli.files import emit
from semloc.cli.render import print_changes, print_ground_truth, print_labels, print_result
from semloc.client import Client, ServerError
from semloc.eval.success import ground_truth_report
from semloc.io import load_map, write_atomic, write_files
from semloc.io.native import map_files
from semloc.priors import Prior
from semloc.results import Result, answer_text, parse_answer

ServerOption = Annotated[
    str | None,
    typer.Option(
        "--server",
        help="A `semloc serve` URL (http://host:port): localize there; GLOBAL is then the "
        "map's id on the server.",
    ),
]
TokenOption = Annotated[
    str | None,
    typer.Option(
        "--token", envvar="SEMLOC_TOKEN", help="The server's access token (or $SEMLOC_TOKEN)."
    ),
]


def refuse_local_settings(**given: object) -> None:
    """With --server the server's settings apply: refuse options that would change them."""
    for name, value in given.items():
        if value is not None:
            fail(f"--{name.replace('_', '-')}: with --server the server's settings apply "
                 "(semloc serve --config)")  # fmt: skip


def connect(server: str, token: str | None) -> Client:
    """A client of `server` (one line and exit 2 for a URL that is not one)."""
    try:
        return Client(server, token)
    except ValueError as exc:
        fail(f"--server: {exc}")
        raise  # unreachable: fail() raises


def call(server: str, what: str, function, *arguments):
    """`function(*arguments)`; a server's refusal is one line naming `what` (exit 2)."""
    try:
        return function(*arguments)
    except ServerError as exc:
        _refused(server, what, exc)


def _refused(server: str, what: str, exc: ServerError) -> None:
    """One line for a server's refusal (exit status 2)."""
    if exc.status == 0:
        fail(f"{server}: cannot reach the server ({exc.detail})")
    detail = f": {exc.detail}" if exc.detail else ""
    fail(f"{server}: {what} refused: {exc.status} {exc.error}{detail}")


def localize(
    server: str, token: str | None, map_id: str, local_map: Path, truth, as_json: bool,
    output: Path | None, prior: Prior | None = None,
) -> None:  # fmt: skip
    """Localize LOCAL in the server's map `map_id` (within `prior`); print or write the
    answer."""
    client = connect(server, token)
    local = load_map(local_map)
    served = _answer(server, call(server, "localize", client.localize, map_id, local, prior))
    result = Result.of_model(served)
    report = None if truth is None else ground_truth_report(result.pose, result.hypotheses, truth)
    if as_json:
        if report is not None:
            served.ground_truth = schema.GroundTruth.model_validate(report)
        emit(answer_text(served.model_dump(by_alias=True)), output)
        return
    target = console if output is None else Console(record=True, width=120, file=io.StringIO())
    target.print(f"server {server}, map {map_id} version {served.map_version}")
    print_result(result, target)
    print_labels(result.labels, target)
    if report is not None:
        print_ground_truth(report, target)
    if output is not None:
        write_atomic(output, target.export_text())


def update_map(
    server: str, token: str | None, map_id: str, local_map: Path, output: Path | None,
    accept_ambiguous: bool,
) -> None:  # fmt: skip
    """Localize LOCAL in the server's map and report its changes as the map's next version."""
    client = connect(server, token)
    local = load_map(local_map)
    answer = call(server, "localize", client.localize, map_id, local)
    served = _answer(server, answer)
    status = served.status
    if not (status == "localized" or (accept_ambiguous and status == "ambiguous")):
        console.print(f"not localized (status {status}): no version written")
        raise typer.Exit(1)
    report = {**answer, "accept_ambiguous": accept_ambiguous}
    try:
        created = client.report_changes(map_id, report, local=local)
    except ServerError as exc:
        if exc.status != 409:
            _refused(server, "the change report", exc)
        console.print(f"the map moved on since version {served.map_version} and these "
                      f"changes no longer apply ({exc.detail}): no version written")  # fmt: skip
        raise typer.Exit(1) from None
    print_changes(Result.of_model(served).changes, console)
    if not created.get("changed"):
        console.print(f"nothing changed: {map_id} stays at version {created['version']}")
        raise typer.Exit(1)
    console.print(f"{map_id}: version {created['version']} written on {server}")
    if output is not None:
        updated = call(server, "reading the map", client.get_map, map_id, created["version"])
        write_files(map_files(updated, output))
        console.print(f"wrote {output}")


def _answer(server: str, answer: object) -> schema.LocalizeAnswer:
    """A server's localization answer, parsed (one line and exit 2 for one that is not)."""
    try:
        return parse_answer(answer, schema.LocalizeAnswer)
    except ValueError as exc:
        fail(f"{server}: the answer is not a localization answer: {exc}")
        raise  # unreachable: fail() raises
