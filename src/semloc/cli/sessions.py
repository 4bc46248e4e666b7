"""`semloc sessions list | show | end`: the live sessions of a `semloc serve` server's map,
from the command line (`semloc.client.Client`).

Rights (the token file's): `list` and `show` need `read` on the map; the ids shown are this
token's own sessions' only (an id is a capability); `end` ends this token's own session, or
any session of a map the token may write.  A server's refusal is one line naming the server
and what it said, exit status 2.  `list` prints one tab-separated line per session.
"""

from __future__ import annotations

import json
from typing import Annotated, Any

import typer

from semloc.cli import remote
from semloc.cli.app import app, exit_statuses, fail
from semloc.cli.maps import MapIdArgument, ServerArgument

sessions_app = typer.Typer(
    name="sessions",
    help="The live sessions of a `semloc serve` server's map: list, show, end.",
    no_args_is_help=True,
)
app.add_typer(sessions_app)

SessionArgument = Annotated[str, typer.Argument(help="The session's id (from its creator).")]


def _line(entry: dict[str, Any]) -> str:
    """`ID  status  idle  version  mine` of one session (`-` for another token's id)."""
    last = entry.get("last") or {}
    return "\t".join([
        entry.get("session_id") or "-", str(last.get("status", "no answer yet")),
        f"idle {entry.get('idle_s', 0):.0f} s", f"map version {entry.get('map_version')}",
        "mine" if entry.get("mine") else "another token's",
    ])  # fmt: skip


@sessions_app.command(name="list", epilog=exit_statuses())
def list_sessions(
    map_id: MapIdArgument, server: ServerArgument, token: remote.TokenOption = None
) -> None:
    """The live sessions of MAP_ID: id (this token's own only), latest status, idle time,
    map version (needs `read`)."""
    client = remote.connect(server, token)
    found = remote.call(server, "listing the sessions", client.sessions, map_id)
    for entry in found:
        typer.echo(_line(entry))
    if not found:
        typer.echo(f"no live sessions of {map_id}")


@sessions_app.command(epilog=exit_statuses())
def show(
    map_id: MapIdArgument,
    session_id: SessionArgument,
    server: ServerArgument,
    token: remote.TokenOption = None,
) -> None:
    """One of this token's sessions of MAP_ID as JSON: its latest answer (status, pose, stamp),
    idle time, map version and up direction (needs `read`)."""
    client = remote.connect(server, token)
    found = remote.call(server, "listing the sessions", client.sessions, map_id)
    entry = next((e for e in found if e.get("session_id") == session_id), None)
    if entry is None:
        fail(f"{server}: no live session {session_id!r} of this token on map {map_id!r}")
    typer.echo(json.dumps(entry, indent=1))


@sessions_app.command(epilog=exit_statuses())
def end(
    session_id: SessionArgument, server: ServerArgument, token: remote.TokenOption = None
) -> None:
    """End a session: this token's own, or any session of a map the token may write."""
    client = remote.connect(server, token)
    remote.call(server, "ending the session", client.end_session, session_id)
    typer.echo(f"ended session {session_id} on {server}")
