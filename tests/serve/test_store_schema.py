"""The store's layout is versioned: a store written before `schema_version` existed (version
1, built here table by table as that semloc wrote it) is migrated when opened, its data kept;
a store of a newer semloc is refused; several processes opening one store migrate it once.
`ping()` says whether the store answers; PostgreSQL goes through a bounded connection pool."""

from __future__ import annotations

import sqlite3
import subprocess
import sys
import threading
import time
import zlib

import pytest

from semloc.serve.store import (
    MIGRATIONS,
    SCHEMA_VERSION,
    PostgresStore,
    StoreError,
    open_store,
)

# The layout of the first store, exactly as it was created before schema_version existed.
VERSION_1 = (
    "CREATE TABLE maps (map_id TEXT PRIMARY KEY, latest INTEGER NOT NULL)",
    "CREATE TABLE map_versions (map_id TEXT NOT NULL, version INTEGER NOT NULL, "
    "created DOUBLE PRECISION NOT NULL, source TEXT NOT NULL, document {blob} NOT NULL, "
    "PRIMARY KEY (map_id, version))",
    "CREATE TABLE sessions (session_id TEXT PRIMARY KEY, map_id TEXT NOT NULL, "
    "map_version INTEGER NOT NULL, up TEXT, created DOUBLE PRECISION NOT NULL, "
    "touched DOUBLE PRECISION NOT NULL, last TEXT)",
    "CREATE TABLE session_batches (session_id TEXT NOT NULL, seq INTEGER NOT NULL, "
    "stamp DOUBLE PRECISION NOT NULL, objects {blob} NOT NULL, PRIMARY KEY (session_id, seq))",
    "CREATE TABLE localizations (localization_id TEXT PRIMARY KEY, map_id TEXT NOT NULL, "
    "created DOUBLE PRECISION NOT NULL, local {blob} NOT NULL)",
)
DOC = {"format": "semloc-map", "version": 1, "objects": [{"id": "1", "label": "chair",
                                                          "position": [1.0, 2.0, 0.5]}]}  # fmt: skip


def _pack(document) -> bytes:
    import json

    return zlib.compress(json.dumps(document).encode(), 1)


def _old_rows(now: float) -> list[tuple[str, tuple]]:
    """Rows as the first semloc inserted them (positional inserts)."""
    return [
        ("INSERT INTO maps VALUES (?, ?)", ("office", 2)),
        ("INSERT INTO map_versions VALUES (?, ?, ?, ?, ?)", ("office", 1, now, "upload", _pack(DOC))),
        ("INSERT INTO map_versions VALUES (?, ?, ?, ?, ?)",
         ("office", 2, now, "changes (from version 1)", _pack({**DOC, "objects": []}))),
        ("INSERT INTO sessions VALUES (?, ?, ?, ?, ?, ?, ?)",
         ("s1", "office", 2, "[0, 0, 1]", now, now, None)),
        ("INSERT INTO session_batches VALUES (?, ?, ?, ?)", ("s1", 1, 0.5, _pack([DOC["objects"][0]]))),
    ]  # fmt: skip


def _build_old_sqlite(folder) -> None:
    folder.mkdir()
    connection = sqlite3.connect(folder / "semloc.sqlite3")
    for statement in VERSION_1:
        connection.execute(statement.format(blob="BLOB"))
    for statement, row in _old_rows(time.time()):
        connection.execute(statement, row)
    connection.commit()
    connection.close()


def _tables(folder) -> set[str]:
    connection = sqlite3.connect(folder / "semloc.sqlite3")
    names = {r[0] for r in connection.execute("SELECT name FROM sqlite_master")}
    connection.close()
    return names


def _check_migrated(store) -> None:
    assert store.schema_version() == SCHEMA_VERSION
    assert store.latest_version("office") == 2
    assert store.get_map("office", 1) == (1, DOC)
    assert [v.source for v in store.versions("office")] == ["upload", "changes (from version 1)"]
    session = store.session("s1")
    assert session.map_version == 2 and session.up == [0, 0, 1]
    assert [b.objects for b in store.batches("s1")] == [[DOC["objects"][0]]]
    assert store.put_map("office", DOC, "upload") == 3  # writes go on after the migration
    assert store.append_batch("s1", 1.0, [], idle_seconds=3600) == 2
    assert store.migrate() == []  # nothing left to apply


def test_an_old_sqlite_store_is_migrated_and_keeps_its_data(tmp_path):
    folder = tmp_path / "old"
    _build_old_sqlite(folder)
    assert "schema_version" not in _tables(folder)
    store = open_store(folder)
    _check_migrated(store)
    assert {"schema_version", "sessions_by_map", "sessions_by_touched",
            "localizations_by_created"} <= _tables(folder)  # fmt: skip
    store.close()


def test_a_new_store_records_every_migration_once(tmp_path):
    store = open_store(tmp_path)
    connection = sqlite3.connect(tmp_path / "semloc.sqlite3")
    rows = connection.execute("SELECT version, description FROM schema_version ORDER BY version")
    assert [(v, d) for v, d in rows] == [(m.version, m.description) for m in MIGRATIONS]
    connection.close()
    assert [m.version for m in MIGRATIONS] == list(range(1, SCHEMA_VERSION + 1))
    assert store.ping()


def test_a_store_of_a_newer_semloc_is_refused_unchanged(tmp_path):
    open_store(tmp_path).close()
    connection = sqlite3.connect(tmp_path / "semloc.sqlite3")
    connection.execute(
        "INSERT INTO schema_version VALUES (?, ?, ?)", (SCHEMA_VERSION + 1, 0.0, "x")
    )
    connection.commit()
    connection.close()
    with pytest.raises(StoreError, match=f"version {SCHEMA_VERSION + 1}, newer than"):
        open_store(tmp_path)


OPEN_ONE = "import sys; from semloc.serve.store import open_store; open_store(sys.argv[1])"


@pytest.mark.slow
def test_processes_opening_an_old_store_at_once_migrate_it_once(tmp_path):
    folder = tmp_path / "old"
    _build_old_sqlite(folder)
    procs = [subprocess.Popen([sys.executable, "-c", OPEN_ONE, str(folder)],
                              stderr=subprocess.PIPE, text=True) for _ in range(4)]  # fmt: skip
    for proc in procs:
        _, err = proc.communicate(timeout=60)
        assert proc.returncode == 0, err
    connection = sqlite3.connect(folder / "semloc.sqlite3")
    versions = [r[0] for r in connection.execute("SELECT version FROM schema_version")]
    connection.close()
    assert versions == [m.version for m in MIGRATIONS if m.version > 1]
    _check_migrated(open_store(folder))


# PostgreSQL ---------------------------------------------------------------------------------
def test_an_old_postgresql_store_is_migrated_and_keeps_its_data(postgres_url):
    import psycopg

    with psycopg.connect(postgres_url, autocommit=True) as connection:
        connection.execute("DROP TABLE IF EXISTS maps, map_versions, sessions, session_batches, "
                           "localizations, schema_version")  # fmt: skip
        for statement in VERSION_1:
            connection.execute(statement.format(blob="BYTEA"))
        for statement, row in _old_rows(time.time()):
            connection.execute(statement.replace("?", "%s"), row)
    store = open_store(None, postgres_url, pool_size=2)
    try:
        _check_migrated(store)
    finally:
        with store._transaction(write=True) as cur:
            cur.execute("DROP TABLE maps, map_versions, sessions, session_batches, "
                        "localizations, schema_version")  # fmt: skip
        store.close()


def test_postgresql_connections_stay_within_the_pool(postgres_url):
    """40 threads reading at once over a pool of 3: this store's work goes through at most 3
    server connections (backend processes), not one per thread."""
    store = open_store(None, postgres_url, pool_size=3)
    try:
        store.put_map("m", DOC, "upload")
        backends: set[int] = set()

        def read() -> None:
            for _ in range(5):
                assert store.get_map("m") == (1, DOC)
                with store._transaction() as cur:
                    cur.execute("SELECT pg_backend_pid()")
                    backends.add(int(cur.fetchone()[0]))

        threads = [threading.Thread(target=read) for _ in range(40)]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join(60)
        assert 1 <= len(backends) <= 3, backends
        assert store.ping()
    finally:
        with store._transaction(write=True) as cur:
            cur.execute("DROP TABLE maps, map_versions, sessions, session_batches, "
                        "localizations, schema_version")  # fmt: skip
        store.close()
    assert not store.ping()  # a closed pool does not answer


def test_an_unreachable_postgresql_is_one_clear_error(monkeypatch):
    pytest.importorskip("psycopg_pool", reason="psycopg_pool (the serve extra) is not installed")
    import socket

    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]  # nothing listens there
    monkeypatch.setattr(PostgresStore, "CONNECT_TIMEOUT_S", 1.0)
    with pytest.raises(StoreError, match=f"127.0.0.1:{port}/db: PostgreSQL does not answer"):
        open_store(None, f"postgresql://semloc@127.0.0.1:{port}/db")
