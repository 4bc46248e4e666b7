"""Where the service keeps its state: map versions and live sessions, in SQLite or PostgreSQL.

One storage layer, two databases: `open_store(url)` gives an SQLite store for a file path (the
default, `DIR/semloc.sqlite3`, nothing to install) or a PostgreSQL store for a
`postgresql://` URL (several machines share it).  Every write is one transaction, so a crash or
`kill -9` at any moment leaves the store as it was before the request or as after it: a map
version is stored whole or not at all, and a session's update batch likewise.

Tables:
    maps(map_id, latest)                                 the newest version of each map
    map_versions(map_id, version, created, source, document)   every version, JSON (zlib)
    sessions(session_id, map_id, map_version, up, created, touched, last)
    session_batches(session_id, seq, stamp, objects)     the updates that rebuild its window
    session_states(session_id, seq, state)               its Localizer's state after batch seq
    localizations(localization_id, map_id, created, local)     a one-shot localization's
                                                         local map and answer, for its change report
    session_owners(session_id, owner)                    who opened a session (a token's digest)
    request_keys(scope, key, digest, created, ref, answer)     the Idempotency-Key of a write,
                                                         its body's digest, what it wrote (a
                                                         version or a batch) and its answer

    schema_version(version, applied, description)        the migrations applied, in order

Map versions are integers from 1.  `derive_map` runs a caller's function on the latest version
while holding that map's write lock (SQLite: the database's; PostgreSQL: the `maps` row's), so
that two writers of one map are serialised: each sees the other's version or gets a conflict.

The layout is versioned: `MIGRATIONS` are applied in order, each once and in its own
transaction with its row in `schema_version`, when a store is opened (by the first of several
workers that open it at once; the others wait and find them applied).  A store written before
`schema_version` existed is version 1.  A store of a newer semloc is refused (`StoreError`),
never changed.  Inserts name their columns, so that a column added by a migration (with a
default) does not shift them.  `ping()` is the cheap check that the store answers.

A PostgreSQL store keeps a pool of connections per process (`psycopg_pool`, at most
`pool_size`, opened on demand) shared by the threads of the worker: 40 threads of a worker use
a handful, not 40, of the server's (by default 100) connections.

A write with a request key stores the key in the same transaction, checked under that lock:
the key is taken (`KeyTaken`, nothing written) or the write is stored with it, never twice.
"""

from __future__ import annotations

import json
import sqlite3
import threading
import time
import zlib
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any


@dataclass(frozen=True)
class Migration:
    """One step of the store's layout: `version` (from 1, in order), what it does, and its
    statements (`{blob}`: the database's binary type)."""

    version: int
    description: str
    statements: tuple[str, ...]


MIGRATIONS = (
    Migration(1, "maps, versions, sessions, update batches, one-shot localizations", (
        "CREATE TABLE IF NOT EXISTS maps (map_id TEXT PRIMARY KEY, latest INTEGER NOT NULL)",
        "CREATE TABLE IF NOT EXISTS map_versions (map_id TEXT NOT NULL, version INTEGER NOT NULL, "
        "created DOUBLE PRECISION NOT NULL, source TEXT NOT NULL, document {blob} NOT NULL, "
        "PRIMARY KEY (map_id, version))",
        "CREATE TABLE IF NOT EXISTS sessions (session_id TEXT PRIMARY KEY, map_id TEXT NOT NULL, "
        "map_version INTEGER NOT NULL, up TEXT, created DOUBLE PRECISION NOT NULL, "
        "touched DOUBLE PRECISION NOT NULL, last TEXT)",
        "CREATE TABLE IF NOT EXISTS session_batches (session_id TEXT NOT NULL, "
        "seq INTEGER NOT NULL, stamp DOUBLE PRECISION NOT NULL, objects {blob} NOT NULL, "
        "PRIMARY KEY (session_id, seq))",
        "CREATE TABLE IF NOT EXISTS localizations (localization_id TEXT PRIMARY KEY, "
        "map_id TEXT NOT NULL, created DOUBLE PRECISION NOT NULL, local {blob} NOT NULL)",
    )),
    Migration(2, "indexes: sessions by map and by idle time, localizations by age", (
        "CREATE INDEX IF NOT EXISTS sessions_by_map ON sessions (map_id, created)",
        "CREATE INDEX IF NOT EXISTS sessions_by_touched ON sessions (touched)",
        "CREATE INDEX IF NOT EXISTS localizations_by_created ON localizations (created)",
    )),
    Migration(3, "a session's Localizer state, which rebuilds its window", (
        "CREATE TABLE IF NOT EXISTS session_states (session_id TEXT PRIMARY KEY, "
        "seq INTEGER NOT NULL, state {blob} NOT NULL)",
    )),
    Migration(4, "sessions' owners; request keys of writes that may be retried", (
        "CREATE TABLE IF NOT EXISTS session_owners (session_id TEXT PRIMARY KEY, "
        "owner TEXT NOT NULL)",
        "CREATE TABLE IF NOT EXISTS request_keys (scope TEXT NOT NULL, key TEXT NOT NULL, "
        "digest TEXT NOT NULL, created DOUBLE PRECISION NOT NULL, ref INTEGER NOT NULL, "
        "answer {blob}, PRIMARY KEY (scope, key))",
    )),
)  # fmt: skip
"""The store's layout, oldest first; a new step goes at the end with the next version."""

SCHEMA_VERSION = MIGRATIONS[-1].version


class StoreError(ValueError):
    """The store cannot be used: written by a newer semloc, or not reachable (the message
    says which store and why)."""


REQUEST_KEY_TTL_S = 24 * 3600.0
"""Request keys are kept this long (a retry comes within seconds; a day covers a device that
lost its network for the night)."""


class Conflict(Exception):
    """A derived version cannot be written: the map moved on and the change no longer applies."""


@dataclass(frozen=True)
class VersionInfo:
    version: int
    created: float  # seconds since the epoch (UTC)
    source: str


@dataclass(frozen=True)
class SessionRow:
    session_id: str
    map_id: str
    map_version: int
    up: list[float] | None
    created: float
    touched: float
    last: dict[str, Any] | None  # a summary of the latest answer (status, pose, stamp)
    owner: str = ""  # who opened it (a token's digest; "" without tokens)


@dataclass(frozen=True)
class RequestKey:
    """The Idempotency-Key of a write: `scope` (whose, and what it writes), the key, and the
    digest of the request's body."""

    scope: str
    key: str
    digest: str


@dataclass(frozen=True)
class Remembered:
    """What a request key wrote: the body's digest, `ref` (the map version or the session's
    batch number) and the answer (None until it was stored)."""

    digest: str
    ref: int
    answer: dict[str, Any] | None


class KeyTaken(Exception):
    """A write's request key was used before: nothing written; `remembered` is what it wrote."""

    def __init__(self, remembered: Remembered) -> None:
        super().__init__("request key used before")
        self.remembered = remembered


@dataclass(frozen=True)
class Batch:
    seq: int
    stamp: float
    objects: list[dict[str, Any]]
    position: list[float] | None = None  # the device in its frame, when it said
    sets_prior: bool = False  # the batch set the session's position prior ...
    prior: dict[str, Any] | None = None  # ... to this one (`Prior.to_dict`; None: no prior)
    coverage: dict[str, Any] | None = None  # what the sensor covered (`Coverage.to_dict`)


def _pack(document: Any) -> bytes:
    return zlib.compress(json.dumps(document, allow_nan=False).encode(), 1)


def _unpack(blob: bytes) -> Any:
    return json.loads(zlib.decompress(bytes(blob)))


class Store:
    """The operations the service needs; subclasses provide connections and the write lock."""

    placeholder = "?"
    blob = "BLOB"

    def __init__(self) -> None:
        self._local = threading.local()
        self.migrate()

    # the layout -------------------------------------------------------------------------------
    def migrate(self) -> list[int]:
        """Apply the migrations this store lacks, in order, each in its own transaction; the
        versions applied.  `StoreError` for a store of a newer semloc."""
        applied = []
        for migration in MIGRATIONS:
            with self._transaction(write=True) as cur:
                self._lock_schema(cur)
                cur.execute(
                    "CREATE TABLE IF NOT EXISTS schema_version (version INTEGER PRIMARY KEY, "
                    "applied DOUBLE PRECISION NOT NULL, description TEXT NOT NULL)"
                )
                current = self._schema_version(cur)
                if current > SCHEMA_VERSION:
                    raise StoreError(
                        f"the store's layout is version {current}, newer than this semloc's "
                        f"({SCHEMA_VERSION}): upgrade semloc to use it"
                    )
                if migration.version <= current:
                    continue
                for statement in migration.statements:
                    cur.execute(statement.format(blob=self.blob))
                cur.execute(
                    self._sql("INSERT INTO schema_version (version, applied, description) "
                              "VALUES (?, ?, ?)"),
                    (migration.version, time.time(), migration.description),
                )  # fmt: skip
                applied.append(migration.version)
        return applied

    def schema_version(self) -> int:
        """The version of the store's layout (0: an empty store)."""
        with self._transaction() as cur:
            return self._schema_version(cur)

    def _schema_version(self, cur: Any) -> int:
        """Inside a transaction: the layout's version; a store without `schema_version` rows
        but with `maps` is version 1 (written before the layout was versioned)."""
        if self._has_table(cur, "schema_version"):
            cur.execute("SELECT MAX(version) FROM schema_version")
            found = cur.fetchone()[0]
            if found is not None:
                return int(found)
        return 1 if self._has_table(cur, "maps") else 0

    def _has_table(self, cur: Any, name: str) -> bool:
        raise NotImplementedError

    def _lock_schema(self, cur: Any) -> None:
        """Inside a write transaction: hold off other processes migrating the same store
        (SQLite's write transaction already does)."""

    def ping(self) -> bool:
        """Whether the store answers a trivial query now (for a readiness check); never raises."""
        try:
            self.check()
        except Exception:
            return False
        return True

    def check(self) -> None:
        """Raise (the database's own error) unless the store answers a trivial query now."""
        with self._transaction() as cur:
            cur.execute("SELECT 1")
            if cur.fetchone()[0] != 1:
                raise StoreError("the store answered SELECT 1 with something else")

    # connections and transactions (per thread) ------------------------------------------------
    def _connect(self) -> Any:
        raise NotImplementedError

    def _connection(self) -> Any:
        connection = getattr(self._local, "connection", None)
        if connection is None:
            connection = self._local.connection = self._connect()
        return connection

    @contextmanager
    def _transaction(self, write: bool = False, durable: bool = True) -> Iterator[Any]:
        """One transaction; a `durable` write is on disk when it returns (map versions), a
        non-durable one survives a crash of the process but maybe not of the machine (session
        updates: an update lost with the machine is one the device sends again)."""
        raise NotImplementedError

    def _sql(self, statement: str) -> str:
        return statement if self.placeholder == "?" else statement.replace("?", self.placeholder)

    def _lock_map(self, cur: Any, map_id: str) -> int | None:
        """Inside a write transaction: the latest version of `map_id` as stored (None if
        unknown; minus the last version of a deleted map), locked until the transaction ends."""
        cur.execute(self._sql("SELECT latest FROM maps WHERE map_id = ?"), (map_id,))
        row = cur.fetchone()
        return None if row is None else int(row[0])

    def live_sessions(self, idle_seconds: float) -> int:
        """How many sessions were touched within `idle_seconds`."""
        with self._transaction() as cur:
            cur.execute(
                self._sql("SELECT COUNT(*) FROM sessions WHERE touched >= ?"),
                (time.time() - idle_seconds,),
            )
            return int(cur.fetchone()[0])

    def close(self) -> None:
        connection = getattr(self._local, "connection", None)
        if connection is not None:
            connection.close()
            self._local.connection = None

    # maps -------------------------------------------------------------------------------------
    def put_map(
        self,
        map_id: str,
        document: dict[str, Any],
        source: str,
        check: Callable[[int | None], None] | None = None,
        key: RequestKey | None = None,
        answer: Callable[[int], dict[str, Any]] | None = None,
    ) -> int:
        """Store `document` as the next version of `map_id` (1 for a new map); its number.
        `check(latest)` may refuse the write by raising (an If-Match that no longer holds)."""

        def build(latest: int | None, old: dict | None) -> dict[str, Any]:
            if check is not None:
                check(latest)
            return document

        return self.derive_map(map_id, build, source, create=True, key=key, answer=answer)

    def derive_map(
        self,
        map_id: str,
        build: Callable[[int | None, dict[str, Any] | None], dict[str, Any]],
        source: str,
        create: bool = False,
        key: RequestKey | None = None,
        answer: Callable[[int], dict[str, Any]] | None = None,
    ) -> int:
        """Write `build(latest_version, latest_document)` as the next version, all in one
        transaction holding the map's lock; `build` may raise `Conflict` (nothing written).
        Without `create`, an unknown map raises KeyError.  With a request `key`, the key and
        `answer(version)` are stored with the version (`KeyTaken` when the key was used)."""
        blob_out: bytes
        with self._transaction(write=True) as cur:
            stored = self._lock_map(cur, map_id)
            latest = stored if stored is not None and stored > 0 else None  # < 0: deleted
            if key is not None:
                self._check_key(cur, key)
            if latest is None and not create:
                raise KeyError(map_id)
            old = None if latest is None else self._document(cur, map_id, latest)
            blob_out = _pack(build(latest, old))
            version = 1 if stored is None else abs(stored) + 1  # never a number used before
            if stored is None:
                cur.execute(
                    self._sql("INSERT INTO maps (map_id, latest) VALUES (?, ?)"), (map_id, version)
                )
            else:
                cur.execute(
                    self._sql("UPDATE maps SET latest = ? WHERE map_id = ?"), (version, map_id)
                )
            cur.execute(
                self._sql(
                    "INSERT INTO map_versions (map_id, version, created, source, document) "
                    "VALUES (?, ?, ?, ?, ?)"
                ),
                (map_id, version, time.time(), source, blob_out),
            )
            if key is not None:
                self._insert_key(cur, key, version, None if answer is None else answer(version))
        return version

    # request keys ------------------------------------------------------------------------------
    def _check_key(self, cur: Any, key: RequestKey) -> None:
        """Inside a write transaction holding the lock of what the key writes: `KeyTaken` when
        the key was used."""
        found = self._recall(cur, key)
        if found is not None:
            raise KeyTaken(found)

    def _recall(self, cur: Any, key: RequestKey) -> Remembered | None:
        cur.execute(
            self._sql("SELECT digest, ref, answer FROM request_keys WHERE scope = ? AND key = ?"),
            (key.scope, key.key),
        )
        row = cur.fetchone()
        if row is None:
            return None
        return Remembered(row[0], int(row[1]), None if row[2] is None else _unpack(row[2]))

    def _insert_key(self, cur: Any, key: RequestKey, ref: int, answer: dict | None) -> None:
        cur.execute(
            self._sql(
                "INSERT INTO request_keys (scope, key, digest, created, ref, answer) "
                "VALUES (?, ?, ?, ?, ?, ?)"
            ),
            (key.scope, key.key, key.digest, time.time(), ref,
             None if answer is None else _pack(answer)),
        )  # fmt: skip

    def recall(self, key: RequestKey) -> Remembered | None:
        """What an earlier request with this key wrote and answered, or None."""
        with self._transaction() as cur:
            return self._recall(cur, key)

    def remember(self, key: RequestKey, ref: int, answer: dict[str, Any]) -> Remembered | None:
        """Store a key's answer of a request that wrote nothing (a report that changed
        nothing); what the key holds when it was taken already, else None."""
        with self._transaction(write=True, durable=False) as cur:
            found = self._recall(cur, key)
            if found is None:
                self._insert_key(cur, key, ref, answer)
        return found

    def _document(self, cur: Any, map_id: str, version: int) -> dict[str, Any] | None:
        cur.execute(
            self._sql("SELECT document FROM map_versions WHERE map_id = ? AND version = ?"),
            (map_id, version),
        )
        row = cur.fetchone()
        return None if row is None else _unpack(row[0])

    def latest_version(self, map_id: str) -> int | None:
        with self._transaction() as cur:
            cur.execute(
                self._sql("SELECT latest FROM maps WHERE map_id = ? AND latest > 0"), (map_id,)
            )
            row = cur.fetchone()
        return None if row is None else int(row[0])

    def get_map(self, map_id: str, version: int | None = None) -> tuple[int, dict] | None:
        """(version, document) of `version` (the latest without one), or None if absent."""
        with self._transaction() as cur:
            if version is None:
                cur.execute(
                    self._sql("SELECT latest FROM maps WHERE map_id = ? AND latest > 0"), (map_id,)
                )
                row = cur.fetchone()
                if row is None:
                    return None
                version = int(row[0])
            document = self._document(cur, map_id, version)
        return None if document is None else (version, document)

    def versions(self, map_id: str) -> list[VersionInfo]:
        with self._transaction() as cur:
            cur.execute(
                self._sql(
                    "SELECT version, created, source FROM map_versions WHERE map_id = ? "
                    "ORDER BY version"
                ),
                (map_id,),
            )
            return [VersionInfo(int(v), float(c), s) for v, c, s in cur.fetchall()]

    def map_ids(self) -> list[tuple[str, int]]:
        """Every map with its latest version, by id."""
        with self._transaction() as cur:
            cur.execute("SELECT map_id, latest FROM maps WHERE latest > 0 ORDER BY map_id")
            return [(m, int(v)) for m, v in cur.fetchall()]

    def delete_map(self, map_id: str) -> bool:
        """Delete a map: every version, its sessions and its one-shot localizations; whether
        it was there.  Its id stays known with minus its last version, so that a map uploaded
        again under the id goes on from the next number: a version number never names two
        documents (caches and If-Match rely on it)."""
        with self._transaction(write=True) as cur:
            latest = self._lock_map(cur, map_id)
            if latest is None or latest < 0:
                return False
            cur.execute(self._sql("SELECT session_id FROM sessions WHERE map_id = ?"), (map_id,))
            for (session_id,) in list(cur.fetchall()):
                self._delete_session(cur, session_id)
            for table in ("localizations", "map_versions"):
                cur.execute(self._sql(f"DELETE FROM {table} WHERE map_id = ?"), (map_id,))
            cur.execute(self._sql("UPDATE maps SET latest = ? WHERE map_id = ?"), (-latest, map_id))
        return True

    # sessions ---------------------------------------------------------------------------------
    def create_session(
        self, session_id: str, map_id: str, map_version: int, up: list[float] | None,
        owner: str = "", state: dict[str, Any] | None = None,
    ) -> None:  # fmt: skip
        """A new session; with `state`, the Localizer state it starts from (after batch 0)."""
        now = time.time()
        with self._transaction(write=True, durable=False) as cur:
            cur.execute(
                self._sql("INSERT INTO sessions (session_id, map_id, map_version, up, created, "
                          "touched, last) VALUES (?, ?, ?, ?, ?, ?, ?)"),
                (session_id, map_id, map_version, None if up is None else json.dumps(up),
                 now, now, None),
            )  # fmt: skip
            cur.execute(
                self._sql("INSERT INTO session_owners (session_id, owner) VALUES (?, ?)"),
                (session_id, owner),
            )
            if state is not None:
                cur.execute(
                    self._sql(
                        "INSERT INTO session_states (session_id, seq, state) VALUES (?, ?, ?)"
                    ),
                    (session_id, 0, _pack(state)),
                )

    def session(self, session_id: str) -> SessionRow | None:
        with self._transaction() as cur:
            cur.execute(
                self._sql(
                    "SELECT s.session_id, s.map_id, s.map_version, s.up, s.created, s.touched, "
                    "s.last, o.owner FROM sessions s LEFT JOIN session_owners o "
                    "ON o.session_id = s.session_id WHERE s.session_id = ?"
                ),
                (session_id,),
            )
            row = cur.fetchone()
        if row is None:
            return None
        sid, map_id, version, up, created, touched, last, owner = row
        return SessionRow(
            sid, map_id, int(version), None if up is None else json.loads(up),
            float(created), float(touched), None if last is None else json.loads(last),
            owner or "",
        )  # fmt: skip

    def sessions_of(self, map_id: str) -> list[SessionRow]:
        with self._transaction() as cur:
            cur.execute(
                self._sql("SELECT session_id FROM sessions WHERE map_id = ? ORDER BY created"),
                (map_id,),
            )
            ids = [r[0] for r in cur.fetchall()]
        return [s for s in map(self.session, ids) if s is not None]

    def append_batch(
        self,
        session_id: str,
        stamp: float,
        objects: list[dict],
        idle_seconds: float,
        key: RequestKey | None = None,
        position: list[float] | None = None,
        sets_prior: bool = False,
        prior: dict[str, Any] | None = None,
        coverage: dict[str, Any] | None = None,
    ) -> int | None:
        """Store the next batch of a session and touch it; its sequence number (from 1), or
        None when the session is gone or was idle for longer than `idle_seconds`.  With a
        request `key`, the key is stored with the batch (`KeyTaken` when it was used).
        `sets_prior`: the batch sets the session's position prior to `prior` (None: none);
        `coverage`: what the sensor covered at the batch (`Coverage.to_dict`)."""
        now = time.time()
        document: Any = objects
        if position is not None or sets_prior or coverage is not None:
            document = {"objects": objects, "position": position}
            if sets_prior:
                document["prior"] = prior
            if coverage is not None:
                document["coverage"] = coverage
        with self._transaction(write=True, durable=False) as cur:
            # the row lock (PostgreSQL) serialises a session's appends
            cur.execute(
                self._sql("UPDATE sessions SET touched = ? WHERE session_id = ? AND touched >= ?"),
                (now, session_id, now - idle_seconds),
            )
            if cur.rowcount != 1:
                return None
            if key is not None:
                self._check_key(cur, key)
            cur.execute(
                self._sql("SELECT COALESCE(MAX(seq), 0) FROM session_batches WHERE session_id = ?"),
                (session_id,),
            )
            seq = int(cur.fetchone()[0]) + 1
            cur.execute(
                self._sql(
                    "INSERT INTO session_batches (session_id, seq, stamp, objects) "
                    "VALUES (?, ?, ?, ?)"
                ),
                (session_id, seq, stamp, _pack(document)),
            )
            if key is not None:
                self._insert_key(cur, key, seq, None)
        return seq

    def batches(self, session_id: str, after: int = 0, upto: int | None = None) -> list[Batch]:
        """The kept batches of a session with `after < seq <= upto`, in order."""
        with self._transaction() as cur:
            cur.execute(
                self._sql(
                    "SELECT seq, stamp, objects FROM session_batches WHERE session_id = ? "
                    "AND seq > ? AND seq <= ? ORDER BY seq"
                ),
                (session_id, after, 2**62 if upto is None else upto),
            )
            rows = cur.fetchall()
        batches = []
        for seq, stamp, blob in rows:
            document = _unpack(blob)
            if isinstance(document, dict):
                batches.append(
                    Batch(
                        int(seq),
                        float(stamp),
                        document["objects"],
                        document["position"],
                        "prior" in document,
                        document.get("prior"),
                        document.get("coverage"),
                    )  # fmt: skip
                )
            else:
                batches.append(Batch(int(seq), float(stamp), document))
        return batches

    def save_state(self, session_id: str, seq: int, state: dict[str, Any], keep: set[int]) -> None:
        """Keep a session's Localizer state after batch `seq` (unless a later one is kept) and
        let go of the batches up to `seq` that it does not need (all but `keep` and `seq`)."""
        kept = sorted({*keep, seq})
        with self._transaction(write=True, durable=False) as cur:
            cur.execute(
                self._sql(
                    "INSERT INTO session_states (session_id, seq, state) VALUES (?, ?, ?) "
                    "ON CONFLICT (session_id) DO "
                    "UPDATE SET seq = excluded.seq, state = excluded.state "
                    "WHERE session_states.seq < excluded.seq"
                ),
                (session_id, seq, _pack(state)),
            )
            marks = ", ".join("?" * len(kept))
            cur.execute(
                self._sql(
                    "DELETE FROM session_batches WHERE session_id = ? AND seq <= ? "
                    f"AND seq NOT IN ({marks})"
                ),
                (session_id, seq, *kept),
            )

    def session_state(self, session_id: str) -> tuple[int, dict[str, Any]] | None:
        """The latest kept Localizer state of a session and the batch it follows."""
        with self._transaction() as cur:
            cur.execute(
                self._sql("SELECT seq, state FROM session_states WHERE session_id = ?"),
                (session_id,),
            )
            row = cur.fetchone()
        return None if row is None else (int(row[0]), _unpack(row[1]))

    def set_last(
        self, session_id: str, last: dict[str, Any], key: RequestKey | None = None,
        answer: dict[str, Any] | None = None,
    ) -> None:  # fmt: skip
        """Keep a summary of a session's latest answer (and the whole `answer` under the
        update's request `key`)."""
        with self._transaction(write=True, durable=False) as cur:
            cur.execute(
                self._sql("UPDATE sessions SET last = ? WHERE session_id = ?"),
                (json.dumps(last, allow_nan=False), session_id),
            )
            if key is not None and answer is not None:
                cur.execute(
                    self._sql("UPDATE request_keys SET answer = ? WHERE scope = ? AND key = ?"),
                    (_pack(answer), key.scope, key.key),
                )

    def delete_session(self, session_id: str) -> bool:
        with self._transaction(write=True) as cur:
            return self._delete_session(cur, session_id)

    def _delete_session(self, cur: Any, session_id: str) -> bool:
        """Delete a session, its batches, its owner and its request keys."""
        for table in ("session_batches", "session_states", "session_owners"):
            cur.execute(self._sql(f"DELETE FROM {table} WHERE session_id = ?"), (session_id,))
        cur.execute(
            self._sql("DELETE FROM request_keys WHERE scope = ?"), (session_scope(session_id),)
        )
        cur.execute(self._sql("DELETE FROM sessions WHERE session_id = ?"), (session_id,))
        return cur.rowcount > 0

    # one-shot localizations --------------------------------------------------------------------
    def put_localization(self, localization_id: str, map_id: str, local: dict) -> None:
        with self._transaction(write=True, durable=False) as cur:
            cur.execute(
                self._sql(
                    "INSERT INTO localizations (localization_id, map_id, created, local) "
                    "VALUES (?, ?, ?, ?)"
                ),
                (localization_id, map_id, time.time(), _pack(local)),
            )

    def localization(self, localization_id: str) -> tuple[str, float, dict] | None:
        """(map id, created, what was kept) of a one-shot localization, or None."""
        with self._transaction() as cur:
            cur.execute(
                self._sql(
                    "SELECT map_id, created, local FROM localizations WHERE localization_id = ?"
                ),
                (localization_id,),
            )
            row = cur.fetchone()
        return None if row is None else (row[0], float(row[1]), _unpack(row[2]))

    def expire_sessions(self, idle_seconds: float) -> list[str]:
        """Delete the sessions idle for longer than `idle_seconds` (and the one-shot
        localizations older than that, and request keys older than `REQUEST_KEY_TTL_S`); the
        sessions' ids."""
        now = time.time()
        cutoff = now - idle_seconds
        with self._transaction(write=True, durable=False) as cur:
            cur.execute(self._sql("DELETE FROM localizations WHERE created < ?"), (cutoff,))
            cur.execute(
                self._sql("DELETE FROM request_keys WHERE created < ?"), (now - REQUEST_KEY_TTL_S,)
            )
            cur.execute(self._sql("SELECT session_id FROM sessions WHERE touched < ?"), (cutoff,))
            gone = [r[0] for r in cur.fetchall()]
            for sid in gone:
                self._delete_session(cur, sid)
        return gone


def session_scope(session_id: str) -> str:
    """The scope of a session's request keys (deleted with the session)."""
    return f"session {session_id}"


class SQLiteStore(Store):
    """The default store: one SQLite file (WAL journal).  Map versions are synced to disk before
    they are acknowledged (they survive a crash of the machine); session updates survive a crash
    of the process.

    Writers of one process take turns on a lock; writers of several processes (`--workers`)
    retry every millisecond while another holds the database's write lock (SQLite's own busy
    handler sleeps up to 100 ms at a time, which would show in every device's latency)."""

    LOCKED_RETRY_S = 0.001
    LOCKED_GIVE_UP_S = 30.0

    def __init__(self, path: str | Path) -> None:
        self.path = str(path)
        self._writing = threading.Lock()
        super().__init__()

    def _connect(self) -> sqlite3.Connection:
        connection = sqlite3.connect(self.path, timeout=0.0, isolation_level=None)
        connection.execute("PRAGMA busy_timeout=0")
        self._retry(lambda: connection.execute("PRAGMA journal_mode=WAL"))
        connection.execute("PRAGMA synchronous=FULL")
        self._local.durable = True
        return connection

    def _has_table(self, cur: Any, name: str) -> bool:
        cur.execute("SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = ?", (name,))
        return cur.fetchone() is not None

    def _retry(self, step: Callable[[], object]) -> None:
        """`step()`, again every millisecond while the database is locked (up to 30 s)."""
        give_up = time.monotonic() + self.LOCKED_GIVE_UP_S
        while True:
            try:
                step()
                return
            except sqlite3.OperationalError as exc:
                if "locked" not in str(exc) or time.monotonic() > give_up:
                    raise
                time.sleep(self.LOCKED_RETRY_S)

    @contextmanager
    def _transaction(self, write: bool = False, durable: bool = True) -> Iterator[sqlite3.Cursor]:
        connection = self._connection()
        if not write:
            with self._begun(connection, "BEGIN") as cur:
                yield cur
            return
        with self._writing:
            if durable != self._local.durable:  # NORMAL: WAL commits without fsync
                connection.execute(f"PRAGMA synchronous={'FULL' if durable else 'NORMAL'}")
                self._local.durable = durable
            # IMMEDIATE takes the write lock at once: a read-then-write cannot be overtaken
            with self._begun(connection, "BEGIN IMMEDIATE") as cur:
                yield cur

    @contextmanager
    def _begun(self, connection: sqlite3.Connection, statement: str) -> Iterator[sqlite3.Cursor]:
        self._retry(lambda: connection.execute(statement))
        cur = connection.cursor()
        try:
            yield cur
        except BaseException:
            connection.rollback()
            raise
        else:
            self._retry(connection.commit)  # (a checkpoint of another process may lock it)
        finally:
            cur.close()


class PostgresStore(Store):
    """The shared store: a PostgreSQL database (`postgresql://user@host:port/db`), for several
    worker processes or machines, through a pool of at most `pool_size` connections per
    process.  Needs `psycopg` and `psycopg_pool` (the `serve` extra)."""

    placeholder = "%s"
    blob = "BYTEA"
    CONNECT_TIMEOUT_S = 10.0
    PING_TIMEOUT_S = 2.0

    def __init__(self, url: str, pool_size: int = 10) -> None:
        import psycopg_pool  # the serve extra; only a PostgreSQL store needs it

        self.url = url
        self._pool = psycopg_pool.ConnectionPool(
            url, min_size=1, max_size=pool_size, open=False, name="semloc",
            timeout=self.CONNECT_TIMEOUT_S, check=psycopg_pool.ConnectionPool.check_connection,
            kwargs={"autocommit": False, "connect_timeout": int(self.CONNECT_TIMEOUT_S)},
        )  # fmt: skip
        try:
            self._pool.open(wait=True, timeout=self.CONNECT_TIMEOUT_S)
        except psycopg_pool.PoolTimeout:
            self._pool.close()
            where = url.split("@")[-1]
            raise StoreError(f"--db {where}: PostgreSQL does not answer (no connection "
                             f"within {self.CONNECT_TIMEOUT_S:g} s)") from None  # fmt: skip
        super().__init__()

    def _has_table(self, cur: Any, name: str) -> bool:
        cur.execute("SELECT to_regclass(%s) IS NOT NULL", (name,))
        return bool(cur.fetchone()[0])

    def _lock_schema(self, cur: Any) -> None:
        cur.execute("SELECT pg_advisory_xact_lock(hashtext('semloc schema'))")

    def _lock_map(self, cur: Any, map_id: str) -> int | None:
        cur.execute("SELECT latest FROM maps WHERE map_id = %s FOR UPDATE", (map_id,))
        row = cur.fetchone()
        if row is not None:
            return int(row[0])
        # a new map: serialise creators of this id on an advisory lock of its hash
        cur.execute("SELECT pg_advisory_xact_lock(hashtext(%s))", (map_id,))
        cur.execute("SELECT latest FROM maps WHERE map_id = %s FOR UPDATE", (map_id,))
        row = cur.fetchone()
        return None if row is None else int(row[0])

    @contextmanager
    def _transaction(self, write: bool = False, durable: bool = True) -> Iterator[Any]:
        with self._pool.connection() as connection, self._transaction_on(connection) as cur:
            if write and not durable:
                cur.execute("SET LOCAL synchronous_commit = off")
            yield cur

    @contextmanager
    def _transaction_on(self, connection: Any) -> Iterator[Any]:
        try:
            with connection.cursor() as cur:
                yield cur
        except BaseException:
            connection.rollback()
            raise
        else:
            connection.commit()

    def ping(self) -> bool:
        """Whether PostgreSQL answers within `PING_TIMEOUT_S` (a pooled connection)."""
        try:
            with self._pool.connection(timeout=self.PING_TIMEOUT_S) as connection:
                return connection.execute("SELECT 1").fetchone()[0] == 1
        except Exception:
            return False

    def close(self) -> None:
        self._pool.close()


def open_store(data_dir: str | Path | None, url: str | None = None, pool_size: int = 10) -> Store:
    """The store of `url` (`postgresql://…`, a pool of `pool_size` connections), or SQLite in
    the folder `data_dir` without one."""
    if url is not None and url.startswith(("postgresql://", "postgres://")):
        return PostgresStore(url, pool_size)
    if url is not None:
        raise ValueError(f"--db takes a postgresql:// URL, got {url[:60]!r}")
    if data_dir is None:
        raise ValueError("a store needs a folder (--data DIR) or a database (--db URL)")
    folder = Path(data_dir)
    folder.mkdir(parents=True, exist_ok=True)
    return SQLiteStore(folder / "semloc.sqlite3")
