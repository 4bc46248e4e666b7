"""`semloc maps put | get | list | versions | delete`: the maps of a `semloc serve` server, from the
command line (`semloc.client.Client`).

Rights (the token file's): `put` and `delete` need `write` on the map; `get`, `list` and `versions` need
`read` (`list` shows only the maps the token may read).  A server's refusal is one line naming
the server and what it said, exit status 2, as for `localize --server`.  Output is plain text
(`list` and `versions`: one tab-separated line per map or version, for scripts).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from semloc.cli import remote
from semloc.cli.app import app, exit_statuses, fail
from semloc.cli.files import check_output, check_separate, map_outputs
from semloc.io import load_map, write_files
from semloc.io.native import map_files

maps_app = typer.Typer(
    name="maps",
    help="The maps of a `semloc serve` server: upload, download, list, versions, delete.",
    no_args_is_help=True,
)
app.add_typer(maps_app)

ServerArgument = Annotated[
    str,
    typer.Option(
        "--server", envvar="SEMLOC_SERVER", help="The server's URL, http://host:port (or "
        "$SEMLOC_SERVER).",
    ),
]  # fmt: skip
MapIdArgument = Annotated[str, typer.Argument(help="The map's id on the server.")]


@maps_app.command(epilog=exit_statuses())
def put(
    map_id: MapIdArgument,
    map_file: Annotated[Path, typer.Argument(help="The map to upload, semloc JSON.")],
    server: ServerArgument,
    token: remote.TokenOption = None,
) -> None:
    """Upload MAP_FILE as the next version of MAP_ID (version 1 for a new map; needs `write`)."""
    client = remote.connect(server, token)
    objmap = load_map(map_file)
    version = remote.call(server, "the upload", client.put_map, map_id, objmap)
    typer.echo(f"{map_id}: version {version} ({len(objmap)} objects) on {server}")


@maps_app.command(epilog=exit_statuses())
def get(
    map_id: MapIdArgument,
    output: Annotated[
        Path, typer.Option("--output", "-o", help="Where to write the map (semloc JSON).")
    ],
    server: ServerArgument,
    version: Annotated[
        int | None, typer.Option(min=1, help="This version (default: the latest).")
    ] = None,
    token: remote.TokenOption = None,
) -> None:
    """Download MAP_ID (the latest version, or --version N) into a map file (needs `read`)."""
    check_output(output)
    check_separate({"--output": map_outputs(output)}, {})
    client = remote.connect(server, token)
    objmap = remote.call(server, "reading the map", client.get_map, map_id, version)
    write_files(map_files(objmap, output))
    which = "the latest version" if version is None else f"version {version}"
    typer.echo(f"wrote {output}: {map_id}, {which} ({len(objmap)} objects)")


@maps_app.command(name="list", epilog=exit_statuses())
def list_maps(server: ServerArgument, token: remote.TokenOption = None) -> None:
    """The maps this token may read, with their latest version (needs `read`)."""
    client = remote.connect(server, token)
    found = remote.call(server, "listing the maps", client.maps)
    for entry in found:
        typer.echo(f"{entry['map_id']}\tversion {entry['version']}")
    if not found:
        typer.echo("no maps this token may read")


@maps_app.command(epilog=exit_statuses())
def versions(
    map_id: MapIdArgument, server: ServerArgument, token: remote.TokenOption = None
) -> None:
    """The versions of MAP_ID: number, when (UTC) and from what (needs `read`)."""
    client = remote.connect(server, token)
    for entry in remote.call(server, "listing the versions", client.versions, map_id):
        typer.echo(f"{entry['version']}\t{entry['created']}\t{entry['source']}")


@maps_app.command(epilog=exit_statuses())
def delete(
    map_id: MapIdArgument,
    server: ServerArgument,
    yes: Annotated[
        bool, typer.Option("--yes", help="Yes, delete every version and end its sessions.")
    ] = False,
    token: remote.TokenOption = None,
) -> None:
    """Delete MAP_ID from the server: every version, and its live sessions end (needs
    `write`; uploaded again, the id goes on from the next version number)."""
    if not yes:
        fail(f"maps delete removes every version of {map_id!r} and ends its sessions: add --yes")
    client = remote.connect(server, token)
    remote.call(server, "the deletion", client.delete_map, map_id)
    typer.echo(f"deleted {map_id} from {server}")
