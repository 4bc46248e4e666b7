"""The storage layer on SQLite and on a real PostgreSQL server: versions, derived versions and
conflicts, concurrent writers, sessions and their batches, expiry."""

from __future__ import annotations

import threading
import time
from types import SimpleNamespace

import pytest

import semloc.serve.store as store_module
from semloc.serve.store import (
    Conflict,
    KeyTaken,
    Remembered,
    RequestKey,
    Store,
    open_store,
    session_scope,
)

DOC = {"format": "semloc-map", "version": 1, "objects": []}


@pytest.fixture(params=["sqlite", "postgresql"])
def store(request, tmp_path) -> Store:
    if request.param == "sqlite":
        return open_store(tmp_path)
    return request.getfixturevalue("postgres_store")


def test_versions_count_from_one_and_keep_every_document(store):
    assert store.get_map("m") is None and store.latest_version("m") is None
    for n in range(1, 4):
        assert store.put_map("m", {**DOC, "name": f"v{n}"}, "upload") == n
    assert store.get_map("m") == (3, {**DOC, "name": "v3"})
    assert store.get_map("m", 1) == (1, {**DOC, "name": "v1"})
    assert store.get_map("m", 4) is None
    assert [(v.version, v.source) for v in store.versions("m")] == [
        (n, "upload") for n in (1, 2, 3)
    ]
    assert store.map_ids() == [("m", 3)]


def test_a_conflicting_derivation_writes_nothing(store):
    store.put_map("m", DOC, "upload")

    def refuse(latest, document):
        raise Conflict("moved on")

    with pytest.raises(Conflict):
        store.derive_map("m", refuse, "changes")
    with pytest.raises(KeyError):
        store.derive_map("unknown", lambda latest, document: DOC, "changes")
    assert store.latest_version("m") == 1 and store.map_ids() == [("m", 1)]
    seen = []
    assert store.derive_map("m", lambda v, d: seen.append((v, d)) or {**d, "name": "x"}, "c") == 2
    assert seen == [(1, DOC)]


def test_concurrent_writers_are_serialised(store):
    """Eight threads append to one map, and eight create maps of one new id: every version
    number is given once, and each derivation saw the version before its own."""
    store.put_map("m", {**DOC, "n": 0}, "upload")
    errors = []

    def bump(latest, document):
        assert document["n"] == latest - 1
        return {**document, "n": latest}

    def work() -> None:
        try:
            for _ in range(4):
                store.derive_map("m", bump, "changes")
                store.put_map("fresh", DOC, "upload")
        except Exception as exc:  # noqa: BLE001 - reported below
            errors.append(exc)

    threads = [threading.Thread(target=work) for _ in range(8)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert errors == []
    assert [v.version for v in store.versions("m")] == list(range(1, 34))
    assert store.get_map("m")[1]["n"] == 32
    assert [v.version for v in store.versions("fresh")] == list(range(1, 33))


def test_sessions_keep_their_batches_in_order(store):
    store.put_map("m", DOC, "upload")
    store.create_session("s1", "m", 1, [0.0, 0.0, 1.0])
    assert store.append_batch("s1", 0.5, [{"id": "a"}], 60) == 1
    assert store.append_batch("s1", 1.5, [{"id": "b"}, {"id": "c"}], 60) == 2
    assert store.append_batch("nope", 0.0, [], 60) is None
    assert [(b.seq, b.stamp, b.objects) for b in store.batches("s1")] == [
        (1, 0.5, [{"id": "a"}]), (2, 1.5, [{"id": "b"}, {"id": "c"}])
    ]  # fmt: skip
    assert [b.seq for b in store.batches("s1", after=1)] == [2]
    assert [b.seq for b in store.batches("s1", after=0, upto=1)] == [1]
    row = store.session("s1")
    assert (row.map_id, row.map_version, row.up, row.last) == ("m", 1, [0.0, 0.0, 1.0], None)
    store.set_last("s1", {"status": "failed"})
    assert store.session("s1").last == {"status": "failed"}
    assert [s.session_id for s in store.sessions_of("m")] == ["s1"]
    assert store.delete_session("s1") and not store.delete_session("s1")
    assert store.session("s1") is None and store.batches("s1") == []


def test_idle_sessions_expire(store, monkeypatch):
    """On the store's own clock (a stand-in here: no wall-clock window to fit in)."""
    now = [1.0e9]
    clock = SimpleNamespace(time=lambda: now[0], monotonic=time.monotonic, sleep=time.sleep)
    monkeypatch.setattr(store_module, "time", clock)
    store.put_map("m", DOC, "upload")
    store.create_session("old", "m", 1, None)
    now[0] += 0.3
    store.create_session("new", "m", 1, None)
    assert store.append_batch("old", 0.0, [], 0.2) is None  # too long idle: not touched
    assert store.expire_sessions(0.2) == ["old"]
    assert store.session("old") is None and store.session("new") is not None


def test_an_unknown_database_url_is_refused(tmp_path):
    with pytest.raises(ValueError, match="postgresql://"):
        open_store(tmp_path, "mysql://x")


def test_request_keys_are_written_with_their_write_and_once(store):
    """A version or a batch written with a request key stores the key in its transaction; the
    same key again writes nothing (KeyTaken, with what the key wrote and answered)."""
    key = RequestKey("upload owner m", "k1", "digest-1")
    answer = lambda version: {"map_id": "m", "version": version}  # noqa: E731
    assert store.put_map("m", DOC, "upload", key=key, answer=answer) == 1
    with pytest.raises(KeyTaken) as taken:
        store.put_map("m", {**DOC, "name": "again"}, "upload", key=key, answer=answer)
    assert taken.value.remembered == Remembered("digest-1", 1, {"map_id": "m", "version": 1})
    assert store.latest_version("m") == 1 and store.recall(key).ref == 1
    assert store.recall(RequestKey("upload other m", "k1", "digest-1")) is None  # scoped

    store.create_session("s1", "m", 1, None, owner="device-a")
    assert store.session("s1").owner == "device-a"
    batch = RequestKey(session_scope("s1"), "b1", "digest-b")
    assert store.append_batch("s1", 1.0, [], 600.0, batch) == 1
    assert store.recall(batch) == Remembered("digest-b", 1, None)  # answered later
    store.set_last("s1", {"status": "failed"}, batch, {"update": 1})
    with pytest.raises(KeyTaken) as taken:
        store.append_batch("s1", 2.0, [], 600.0, batch)
    assert taken.value.remembered == Remembered("digest-b", 1, {"update": 1})
    assert [b.seq for b in store.batches("s1")] == [1]
    assert store.remember(RequestKey("changes o m", "c", "d"), 1, {"changed": False}) is None
    assert store.remember(RequestKey("changes o m", "c", "d"), 1, {"changed": True}).answer == {
        "changed": False
    }
    assert store.live_sessions(600.0) == 1
    assert store.ping()
    assert store.delete_session("s1")
    assert store.session("s1") is None and store.recall(batch) is None  # gone with it
    assert store.live_sessions(600.0) == 0


def test_a_deleted_map_is_gone_with_its_sessions_and_its_numbers_go_on(store):
    for n in (1, 2):
        store.put_map("m", {**DOC, "name": f"v{n}"}, "upload")
    store.put_map("other", DOC, "upload")
    store.create_session("s1", "m", 2, None, owner="a")
    store.put_localization("l1", "m", {"objects": []})
    assert store.delete_map("m") and not store.delete_map("m") and not store.delete_map("none")
    assert store.get_map("m") is None and store.latest_version("m") is None
    assert store.versions("m") == [] and store.map_ids() == [("other", 1)]
    assert store.session("s1") is None and store.localization("l1") is None
    with pytest.raises(KeyError):
        store.derive_map("m", lambda latest, old: DOC, "derived")  # no map to derive from
    assert store.put_map("m", {**DOC, "name": "again"}, "upload") == 3
    assert store.get_map("m") == (3, {**DOC, "name": "again"})
    assert [v.version for v in store.versions("m")] == [3]
    assert store.map_ids() == [("m", 3), ("other", 1)]
