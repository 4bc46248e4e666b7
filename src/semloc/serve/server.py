"""Running the service: settings, the app of one worker process, and uvicorn.

`ServeSettings` is everything `semloc serve` takes; `run(settings)` binds the socket (port 0:
any free port, printed), then serves it from one process or from `workers` processes over
the same store (uvicorn's supervisor).  Each worker builds its app with `app_from_environment`
from the settings passed in `SEMLOC_SERVE_SETTINGS`, so that any worker can serve any request:
the state is in the store, not in a process.
"""

from __future__ import annotations

import ipaddress
import json
import os
import signal
import socket
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from pydantic import BaseModel, ConfigDict, Field, model_validator

from semloc.compiling import warm_up
from semloc.io.interrupts import Interrupted
from semloc.localizer import LocalizerConfig
from semloc.serve.access import Access, TokenFileError
from semloc.serve.app import DEFAULT_MAX_BODY, create_app
from semloc.serve.service import Service
from semloc.serve.store import open_store

ENVIRONMENT = "SEMLOC_SERVE_SETTINGS"
__all__ = ["Access", "ServeSettings", "ThreadedServer", "TokenFileError", "build_app",
           "is_loopback", "run", "serving"]  # fmt: skip


class ServeSettings(BaseModel):
    """The settings of `semloc serve`.  Checked here, whoever starts the server (the command,
    `run`, `serving`): a store (`data` or `db`), and tokens unless it listens on a loopback
    address only (without tokens it answers anyone)."""

    model_config = ConfigDict(extra="forbid")

    data: Path | None = Field(None, description="Folder of the SQLite store (created if absent).")
    db: str | None = Field(None, description="A postgresql:// URL: the store instead of SQLite.")
    db_pool: int = Field(
        10, ge=1, le=1000, description="PostgreSQL connections per worker process, at most."
    )
    host: str = "127.0.0.1"
    port: int = Field(8765, ge=0, le=65535)
    workers: int = Field(1, ge=1, le=64)
    tokens: Path | None = Field(None, description="Token file (JSON or YAML).")
    session_idle_s: float = Field(600.0, gt=0, description="Sessions idle this long expire.")
    rate: float = Field(100.0, ge=0, description="Requests a second per token (0: no limit).")
    max_body: int = Field(DEFAULT_MAX_BODY, gt=0, description="Largest request body (bytes).")
    localizer: dict = Field(default_factory=dict, description="LocalizerConfig settings.")
    access_log: bool = Field(False, description="One JSON line per request (semloc.serve.access).")

    @model_validator(mode="after")
    def _store_and_access(self) -> ServeSettings:
        if self.data is None and self.db is None:
            raise ValueError("a store is needed: --data DIR (SQLite) or --db URL (PostgreSQL)")
        if self.tokens is None and not is_loopback(self.host):
            raise ValueError(LOOPBACK_ONLY.format(host=self.host))
        return self


LOOPBACK_ONLY = (
    "--host {host}: without --tokens the server answers anyone, so it listens on a loopback "
    "address only (127.0.0.1, ::1); give --tokens FILE to serve a network"
)


def is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def build_app(settings: ServeSettings):
    """The app of one worker: its own store connection, the token file, the settings."""
    access = Access.from_file(settings.tokens) if settings.tokens else Access.open()
    store = open_store(settings.data, settings.db, settings.db_pool)
    service = Service(store, LocalizerConfig(**settings.localizer), settings.session_idle_s)
    return create_app(service, access, settings.rate, settings.max_body, settings.access_log)


def app_from_environment():
    """uvicorn's factory for worker processes (`--workers N`)."""
    return build_app(ServeSettings.model_validate_json(os.environ[ENVIRONMENT]))


def bind(host: str, port: int) -> socket.socket:
    """A listening TCP socket.  Its connections send without delay (TCP_NODELAY): a reply's
    headers and body go out as two writes, and Nagle's algorithm would hold the second until
    the client's delayed acknowledgement, 40 ms on every kept-alive request.  (asyncio sets it
    only for sockets created with protocol IPPROTO_TCP.)"""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM, socket.IPPROTO_TCP)
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    sock.bind((host, port))
    sock.listen(2048)
    sock.set_inheritable(True)
    return sock


class ThreadedServer:
    """uvicorn serving `app` in a thread of this process on `host`:`port` (0: a free port)
    until `stop()`: for tests, notebooks and programs that embed the service."""

    def __init__(self, app, host: str = "127.0.0.1", port: int = 0) -> None:
        import uvicorn

        self.sock = bind(host, port)
        self.url = f"http://{host}:{self.sock.getsockname()[1]}"
        config = uvicorn.Config(app, log_level="error", access_log=False)
        self.server = uvicorn.Server(config)
        self.server.install_signal_handlers = lambda: None  # not the main thread
        self.thread = threading.Thread(
            target=self.server.run, kwargs={"sockets": [self.sock]}, daemon=True
        )
        self.thread.start()
        deadline = time.monotonic() + 30
        while not self.server.started:
            if not self.thread.is_alive() or time.monotonic() > deadline:
                self.sock.close()
                raise RuntimeError("the server did not start")
            time.sleep(0.01)

    def stop(self) -> None:
        self.server.should_exit = True
        self.thread.join(10)
        self.sock.close()


@contextmanager
def serving(data: str | Path | None, **settings) -> Iterator[str]:
    """The service over the store in `data` (or `db=URL`; other `ServeSettings` as keywords),
    served from a thread of this process on a free loopback port while the block runs; yields
    its URL."""
    folder = None if data is None else Path(data)
    server = ThreadedServer(build_app(ServeSettings(data=folder, port=0, **settings)))
    try:
        yield server.url
    finally:
        server.stop()


def run(settings: ServeSettings, announce: Callable[[str], None] = print) -> None:
    """Serve until SIGINT or SIGTERM, which end it cleanly (requests in flight are answered)
    and then go on as the signal they are: `Interrupted` in the command (status 130, 143)."""
    import uvicorn

    app = build_app(settings)  # checks the store and the token file before binding
    warm_up(lambda text: announce(f"{text}…"))  # compiled before the first request, not in it
    sock = bind(settings.host, settings.port)
    host, port = sock.getsockname()[:2]
    url = f"http://{'[' + host + ']' if ':' in host else host}:{port}"
    access = "tokens required" if settings.tokens else "no tokens: loopback only"
    store = settings.db.split("@")[-1] if settings.db else str(settings.data)
    announce(f"semloc serve: listening on {url} ({access}; store {store}; "
             f"{settings.workers} worker{'s' if settings.workers > 1 else ''})")  # fmt: skip
    if settings.workers == 1:
        config = uvicorn.Config(app, log_level="warning", access_log=False, timeout_keep_alive=30)
        uvicorn.Server(config).run(sockets=[sock])
        return
    os.environ[ENVIRONMENT] = json.dumps(settings.model_dump(mode="json"))
    # the workers' metrics in shared files, summed at each scrape (prometheus-client)
    metrics = tempfile.TemporaryDirectory(prefix="semloc-metrics-")
    os.environ.setdefault("PROMETHEUS_MULTIPROC_DIR", metrics.name)
    config = uvicorn.Config(
        "semloc.serve.server:app_from_environment",
        factory=True,
        workers=settings.workers,
        log_level="warning",
        access_log=False,
        timeout_keep_alive=30,
    )
    supervisor = _supervisor_class()(config, sockets=[sock])
    supervisor.run()
    if supervisor.stopped_by is not None:  # as the one-process server: the signal goes on
        raise Interrupted(supervisor.stopped_by)


def _supervisor_class():
    """uvicorn's supervisor of worker processes, remembering the signal that stopped it."""
    from uvicorn.supervisors import Multiprocess

    class Supervisor(Multiprocess):
        stopped_by: int | None = None

        def handle_int(self) -> None:
            self.stopped_by = signal.SIGINT
            super().handle_int()

        def handle_term(self) -> None:
            self.stopped_by = signal.SIGTERM
            super().handle_term()

    return Supervisor
