"""A live `semloc serve` app on an ephemeral loopback port, in a thread of the test process."""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest
from helpers import box_points

pytest.importorskip("fastapi", reason="the serve extra is not installed")
pytest.importorskip("uvicorn", reason="the serve extra is not installed")


from semloc.compiling import warm_up  # noqa: E402
from semloc.io import map_from_dict, map_to_dict  # noqa: E402
from semloc.maps import ObjectMap  # noqa: E402
from semloc.serve.access import Access  # noqa: E402
from semloc.serve.app import create_app  # noqa: E402
from semloc.serve.server import ThreadedServer  # noqa: E402
from semloc.serve.service import Service  # noqa: E402
from semloc.serve.store import Store, open_store  # noqa: E402
from semloc.sim.layouts import layout  # noqa: E402
from semloc.transforms import yaw_pose  # noqa: E402


class LiveServer(ThreadedServer):
    """The app of `service` served on 127.0.0.1:<free port> until `stop()`."""

    def __init__(self, service: Service, access: Access | None = None, **options) -> None:
        self.service = service
        super().__init__(create_app(service, access, **options))


@pytest.fixture(scope="session")
def compiled() -> None:
    """The compiled loops loaded (or compiled) once, before a server answers its first request
    (`semloc serve` does the same before it listens)."""
    warm_up()


@pytest.fixture
def serve(tmp_path: Path, compiled: None) -> Iterator[Callable[..., LiveServer]]:
    """`serve(access=None, store=None, **options)` -> a started LiveServer (stopped after)."""
    started: list[LiveServer] = []

    def start(access: Access | None = None, store: Store | None = None, **options) -> LiveServer:
        service_options = {k: options.pop(k) for k in ("session_idle_s", "config") if k in options}
        service = Service(store or open_store(tmp_path / "data"), **service_options)
        server = LiveServer(service, access, **options)
        started.append(server)
        return server

    yield start
    for server in started:
        server.stop()


@pytest.fixture(scope="session")
def building() -> ObjectMap:
    """A 40-object floor with points, as the server stores it (JSON rounds to 1e-6)."""
    rng = np.random.default_rng(3)
    floor = layout(40, seed=5)
    objmap = ObjectMap([o.replace(points=box_points(rng, o, 300)) for o in floor], up=floor.up)
    return map_from_dict(map_to_dict(objmap))


def view(global_map: ObjectMap, indices, T_global_local: np.ndarray) -> ObjectMap:
    """Map objects seen in a local frame (exact positions), one per keyframe, ids l0, l1, ..."""
    inverse = np.linalg.inv(T_global_local)
    objects = [
        global_map[i].transformed(inverse).replace(id=f"l{k}", seen=k, extra={})
        for k, i in enumerate(indices)
    ]
    local = ObjectMap(objects, up=inverse[:3, :3] @ global_map.up, name="local")
    return map_from_dict(map_to_dict(local))  # as sent: rounded to 1e-6 like the server's copy


T_TRUE = yaw_pose(0.9, [2.0, -1.0, 0.3])


# A PostgreSQL server of the tests' own (Debian's postgresql package) -------------------------
def _postgres_bin() -> Path | None:
    found = sorted(Path("/usr/lib/postgresql").glob("*/bin/initdb"))
    if found:
        return found[-1].parent
    initdb = shutil.which("initdb")
    return None if initdb is None else Path(initdb).resolve().parent


@pytest.fixture(scope="session")
def postgres_url() -> Iterator[str]:
    """A throwaway PostgreSQL cluster on a free loopback port (stopped after the tests), or
    skip when the postgresql package is not installed (`.ci/run` installs it)."""
    pytest.importorskip("psycopg", reason="psycopg (the serve extra) is not installed")
    binaries = _postgres_bin()
    if binaries is None:
        pytest.skip("PostgreSQL is not installed (Debian package postgresql; .ci/run installs it)")
    folder = Path(tempfile.mkdtemp(prefix="semloc-postgres-"))  # in /tmp: postgres can reach it
    data = folder / "data"
    as_user: list[str] = []
    if os.geteuid() == 0:  # initdb and postgres refuse to run as root
        as_user = ["runuser", "-u", "postgres", "--"]
        shutil.chown(folder, "postgres")
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    run = lambda *args: subprocess.run([*as_user, *args], check=True, capture_output=True)  # noqa: E731
    run(str(binaries / "initdb"), "-D", str(data), "-U", "semloc", "--auth=trust", "-E", "UTF8")
    options = f"-p {port} -k {folder} -c listen_addresses=127.0.0.1 -c fsync=on"
    run(str(binaries / "pg_ctl"), "-D", str(data), "-o", options, "-w", "-t", "30",
        "-l", str(folder / "log"), "start")  # fmt: skip
    try:
        yield f"postgresql://semloc@127.0.0.1:{port}/postgres"
    finally:
        run(str(binaries / "pg_ctl"), "-D", str(data), "-m", "immediate", "-w", "stop")
        shutil.rmtree(folder, ignore_errors=True)


@pytest.fixture
def postgres_store(postgres_url) -> Iterator[Store]:
    """An empty PostgreSQL store (its tables dropped after the test)."""
    store = open_store(".", postgres_url)
    yield store
    with store._transaction(write=True) as cur:
        cur.execute("DROP TABLE IF EXISTS maps, map_versions, sessions, session_batches, "
                    "session_states, session_owners, request_keys, localizations, schema_version")  # fmt: skip
    store.close()
