"""`semloc serve`: the localization service (`semloc.serve`) on a folder or a PostgreSQL store.

Everything is checked before the socket is bound (the extra, the token file, the store, the
settings file), so that a bad start is one line and exit status 2.  Without `--tokens` the
server answers everyone, so it only listens on a loopback address (a rule of the server's
settings, `semloc.serve.server.ServeSettings`, whoever starts it).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from pydantic import ValidationError

from semloc.cli.app import app, err_console, fail, first_error
from semloc.cli.extras import need
from semloc.cli.files import read_config
from semloc.localizer import LocalizerConfig

SERVE_EXIT_STATUSES = (
    "Exit status: 2 bad input or usage (nothing served); 130 stopped by Ctrl-C (SIGINT), 143 "
    "stopped by SIGTERM: both stop the service cleanly, requests in flight are answered first."
)


@app.command(epilog=SERVE_EXIT_STATUSES)
def serve(
    data: Annotated[
        Path | None,
        typer.Option(
            "--data", help="Folder of the store (SQLite file semloc.sqlite3); not needed with --db."
        ),
    ] = None,
    host: Annotated[str, typer.Option(help="Address to listen on.")] = "127.0.0.1",
    port: Annotated[
        int, typer.Option(min=0, max=65535, help="Port (0: any free port, printed).")
    ] = 8765,
    workers: Annotated[
        int,
        typer.Option(
            min=1, max=64, help="Worker processes over the one store (any serves any request)."
        ),
    ] = 1,
    tokens: Annotated[
        Path | None,
        typer.Option(help="Token file, JSON or YAML: who may read, localize, write which map."),
    ] = None,
    db: Annotated[
        str | None,
        typer.Option(
            help="A PostgreSQL database for the store, instead of --data: a URL such as "
            "postgresql://host/db."
        ),
    ] = None,
    db_pool: Annotated[
        int,
        typer.Option(
            "--db-pool",
            min=1,
            max=1000,
            help="With --db: PostgreSQL connections per worker process, at most (a pool).",
        ),
    ] = 10,
    session_idle: Annotated[
        float,
        typer.Option(
            "--session-idle", min=1, max=7 * 86400, help="Seconds after which an idle session ends."
        ),
    ] = 600.0,
    rate: Annotated[
        float,
        typer.Option(
            min=0, max=1e6, help="Requests a second per token, bursts of twice that (0: off)."
        ),
    ] = 100.0,
    max_body_mb: Annotated[
        float,
        typer.Option(
            "--max-body-mb", min=0.001, max=4096, help="Largest request body, MiB (413 beyond)."
        ),
    ] = 64.0,
    config: Annotated[
        Path | None,
        typer.Option(help="Localizer settings file, JSON or .yaml (`semloc config --dump`)."),
    ] = None,
    access_log: Annotated[
        bool,
        typer.Option(
            "--access-log", help="One JSON line per request on stderr (request id, never a token)."
        ),
    ] = False,
) -> None:
    """Serve shared maps over HTTP: uploads, versions, localization, live sessions, changes."""
    need("serve", "serve")
    from semloc.serve import server  # the serve extra: imported only here

    if tokens is not None:
        try:
            server.Access.from_file(tokens)
        except server.TokenFileError as exc:
            fail(str(exc))
    try:
        settings = server.ServeSettings(
            data=data, db=db, db_pool=db_pool, host=host, port=port, workers=workers,
            tokens=tokens, session_idle_s=session_idle, rate=rate,
            max_body=int(max_body_mb * 2**20), localizer=read_config(config), access_log=access_log,
        )  # fmt: skip
        LocalizerConfig(**settings.localizer)
    except ValidationError as exc:
        fail(f"invalid settings: {first_error(exc)}")
    if data is not None and data.exists() and not data.is_dir():
        fail(f"{data}: is a file; --data takes a folder")
    try:
        server.run(settings, announce=lambda line: err_console.print(line, soft_wrap=True))
    except ValueError as exc:
        fail(str(exc))
    except OSError as exc:
        fail(f"cannot serve on {host}:{port}: {exc.strerror or exc}")
