"""What the service does, apart from HTTP: map versions, one-shot localizations, live sessions
and change reports, over a `Store`.

Any worker process can serve any request.  A session keeps in the store its Localizer's state
(`Localizer.state()`: a few kB) and the batches that hold the latest version of an object of
its window or came after that state (older batches go), so what it keeps is bounded by the
window, not by the session's length.  A worker that does not hold the session's `Localizer` in
memory rebuilds it from that state and those objects (`Localizer.restore`) and then applies,
one update each, the batches that came after the state.  The state is kept after every update
while the session tracks a place, where it rebuilds the Localizer exactly, and while it
searches only every `SEARCH_CHECKPOINT` updates: so a rebuilt session's answers equal an
uninterrupted one's exactly, except after a search longer than that, whose rebuilt Localizer
grows its association sets again from the same window objects at once (it may rank the
candidate places differently until the search settles).  Each session is pinned to the map version it was created on.  Parsed maps are kept
per (map, version) in a small cache (a version never changes once written).

Errors are `ServiceError`s carrying the HTTP status the web layer answers with.
"""

from __future__ import annotations

import math
import secrets
import threading
import time
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from semloc.association import CandidateIndex, label_report
from semloc.changes import Changes, answer_changes, apply_changes
from semloc.io import map_from_dict, map_to_dict
from semloc.io.answers import answer_document
from semloc.localizer import Localizer, LocalizerConfig, localize
from semloc.maps import MapError, ObjectMap
from semloc.results import Result
from semloc.serve.store import Conflict, Store
from semloc.transforms import as_pose

MAX_ID_LENGTH = 200


class ServiceError(Exception):
    """A request the service refuses: `status` (HTTP), a short `error` and a `detail`."""

    def __init__(self, status: int, error: str, detail: Any = None) -> None:
        super().__init__(error)
        self.status, self.error, self.detail = status, error, detail


def not_found(what: str) -> ServiceError:
    return ServiceError(404, "not found", what)


def check_id(value: str, what: str) -> str:
    if not value or len(value) > MAX_ID_LENGTH or not value.isprintable() or "/" in value:
        raise ServiceError(422, f"invalid {what}", f"1 to {MAX_ID_LENGTH} printable characters")
    return value


def parse_map(document: Any, what: str = "body") -> ObjectMap:
    """A semloc map sent over HTTP (points inline: a `points_file` would name a server file)."""
    if isinstance(document, dict) and "points_file" in document:
        raise ServiceError(422, "invalid map", f"{what}: points must be inline, not a points_file")
    try:
        return map_from_dict(document)
    except MapError as exc:
        raise ServiceError(422, "invalid map", f"{what}: {exc}") from None


def _objects_map(objects: Any, up: list[float] | None, what: str) -> ObjectMap:
    if not isinstance(objects, list):
        raise ServiceError(422, "invalid objects", f"{what}: 'objects' must be a list")
    document: dict[str, Any] = {"format": "semloc-map", "version": 1, "objects": objects}
    if up is not None:
        document["up"] = up
    return parse_map(document, what)


def _position(value: Any) -> list[float] | None:
    """An update's optional `position`: the device in its own frame, [x, y, z] metres."""
    if value is None:
        return None
    if (
        not isinstance(value, list)
        or len(value) != 3
        or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
        or not all(math.isfinite(v) for v in value)
    ):
        raise ServiceError(422, "invalid update", "'position' must be [x, y, z], finite numbers")
    return [float(v) for v in value]


@dataclass
class _LiveSession:
    """A session's Localizer in this process and the answers not yet read, by batch number."""

    localizer: Localizer
    map_id: str
    map_version: int
    up: list[float] | None
    applied: int = 0
    lock: threading.Lock = field(default_factory=threading.Lock)
    answers: dict[int, Result] = field(default_factory=dict)
    seq_of: dict[str, int] = field(default_factory=dict)  # object id -> batch of its version
    saved: int = 0  # the batch after which the store has its state


class Service:
    """The service over `store`; `config` holds the Localizer settings of every request."""

    MAP_CACHE = 16
    SEARCH_CHECKPOINT = 25
    """While a session searches, its state is kept every this many updates (see above)."""
    LIVE_SESSIONS = 4096
    EXPIRY_EVERY_S = 10.0

    def __init__(
        self, store: Store, config: LocalizerConfig | None = None, session_idle_s: float = 600.0
    ) -> None:
        self.store = store
        self.config = config or LocalizerConfig()
        self.session_idle_s = session_idle_s
        self._maps: OrderedDict[tuple[str, int], ObjectMap] = OrderedDict()
        self._live: OrderedDict[str, _LiveSession] = OrderedDict()
        self._lock = threading.Lock()
        self._next_expiry = 0.0

    # maps -------------------------------------------------------------------------------------
    def put_map(self, map_id: str, document: Any) -> int:
        check_id(map_id, "map id")
        objmap = parse_map(document)
        return self.store.put_map(map_id, map_to_dict(objmap), "upload")

    def map_document(self, map_id: str, version: int | None = None) -> tuple[int, dict]:
        found = self.store.get_map(map_id, version)
        if found is None:
            raise not_found(f"map {map_id!r}" + ("" if version is None else f" version {version}"))
        return found

    def object_map(self, map_id: str, version: int | None = None) -> tuple[int, ObjectMap]:
        """The parsed map (cached per version); its version."""
        if version is None:
            version = self.store.latest_version(map_id)
            if version is None:
                raise not_found(f"map {map_id!r}")
        key = (map_id, version)
        with self._lock:
            cached = self._maps.get(key)
            if cached is not None:
                self._maps.move_to_end(key)
                return version, cached
        _, document = self.map_document(map_id, version)
        objmap = map_from_dict(document)
        with self._lock:
            self._maps[key] = objmap
            while len(self._maps) > self.MAP_CACHE:
                self._maps.popitem(last=False)
        return version, objmap

    # one-shot localization --------------------------------------------------------------------
    def localize(self, map_id: str, document: Any) -> dict[str, Any]:
        """The answer for a local map, with the map version and a `localization_id` under which
        the local map is kept (as long as an idle session) for a change report of the answer."""
        self._expire()
        version, global_map = self.object_map(map_id)
        local = parse_map(document)
        result = localize(global_map, local, self.config)
        labels = label_report(CandidateIndex(global_map, self.config.association), local)
        document = answer_document(result, labels, map_version=version)
        document["localization_id"] = secrets.token_urlsafe(18)
        kept = {"local": map_to_dict(local), "answer": _answer_record(document)}
        self.store.put_localization(document["localization_id"], map_id, kept)
        return document

    # sessions ---------------------------------------------------------------------------------
    def create_session(self, map_id: str, body: Any) -> str:
        self._expire()
        up = None
        if body is not None:
            if not isinstance(body, dict) or set(body) - {"up"}:
                raise ServiceError(
                    422, "invalid session", 'the body is optional: {"up": [x, y, z]}'
                )
            up = body.get("up")
            if up is not None:
                _objects_map([], up, "body")  # validates `up` as a map's
        version, _ = self.object_map(map_id)
        session_id = secrets.token_urlsafe(18)
        self.store.create_session(session_id, map_id, version, up)
        return session_id

    def session_map(self, session_id: str) -> str:
        """The map a live session localizes in (404 for an unknown or expired one)."""
        return self._session_meta(session_id)[0]

    def _session_meta(self, session_id: str) -> tuple[str, int, list[float] | None]:
        """(map id, map version, up) of a session: from memory where it is live here (an
        update still checks in the store that it exists), else from the store."""
        with self._lock:
            live = self._live.get(session_id)
        if live is not None:
            return live.map_id, live.map_version, live.up
        row = self.store.session(session_id)
        if row is None or time.time() - row.touched > self.session_idle_s:
            raise not_found(f"session {session_id!r}")
        return row.map_id, row.map_version, row.up

    def update_session(self, session_id: str, body: Any) -> dict[str, Any]:
        self._expire()
        map_id, version, up = self._session_meta(session_id)
        if not isinstance(body, dict) or "objects" not in body:
            raise ServiceError(422, "invalid update", 'body: {"objects": [...], "stamp": float}')
        stamp = body.get("stamp", 0.0)
        if (
            isinstance(stamp, bool)
            or not isinstance(stamp, (int, float))
            or not math.isfinite(stamp)
        ):
            raise ServiceError(422, "invalid update", "'stamp' must be a finite number")
        position = _position(body.get("position"))
        objects = _objects_map(body["objects"], up, "objects")  # refused before it is stored
        seq = self.store.append_batch(
            session_id, float(stamp), body["objects"], self.session_idle_s, position
        )
        if seq is None:
            with self._lock:
                self._live.pop(session_id, None)
            raise not_found(f"session {session_id!r}")
        live = self._live_session(session_id, map_id, version, up)
        result = self._advance(session_id, live, seq, objects, position)
        document = answer_document(
            result, live.localizer.label_report(), map_version=version, stamp=stamp
        )
        document["session_id"], document["update"] = session_id, seq
        self.store.set_last(session_id, _summary(document))
        return document

    def _live_session(
        self, session_id: str, map_id: str, version: int, up: list[float] | None
    ) -> _LiveSession:
        with self._lock:
            live = self._live.get(session_id)
            if live is not None:
                self._live.move_to_end(session_id)
                return live
        _, global_map = self.object_map(map_id, version)
        fresh = self._rebuilt(session_id, global_map, map_id, version, up)
        with self._lock:
            live = self._live.setdefault(session_id, fresh)
            while len(self._live) > self.LIVE_SESSIONS:
                self._live.popitem(last=False)  # rebuilt from the store if it comes back
        return live

    def _rebuilt(
        self, session_id: str, global_map: ObjectMap, map_id: str, version: int,
        up: list[float] | None,
    ) -> _LiveSession:  # fmt: skip
        """The session from its kept state and window objects (fresh when it has none)."""
        for _ in range(3):  # another worker may let batches go between the two reads
            saved = self.store.session_state(session_id)
            if saved is None:
                return _LiveSession(Localizer(global_map, self.config, local_up=up), map_id,
                                    version, up)  # fmt: skip
            seq, state = saved
            latest: dict[str, tuple[int, dict]] = {}
            for batch in self.store.batches(session_id, 0, seq):
                for raw in batch.objects:
                    latest[str(raw["id"])] = (batch.seq, raw)
            order = [str(i) for i in state["window"]["order"]]
            if all(i in latest for i in order):
                objects = _objects_map([latest[i][1] for i in order], up, "session state")
                localizer = Localizer.restore(global_map, state, objects, self.config, up)
                live = _LiveSession(localizer, map_id, version, up, applied=seq, saved=seq)
                live.seq_of = {i: latest[i][0] for i in order}
                return live
        raise ServiceError(503, "session busy", "its state changed while it was read; retry")

    def _advance(
        self,
        session_id: str,
        live: _LiveSession,
        seq: int,
        objects: ObjectMap,
        position: list[float] | None,
    ) -> Result:
        """Apply the batches up to `seq` (whose objects are `objects`) not yet applied here, in
        order (those of other workers read from the store); the answer after `seq`.  The state
        after them is kept in the store, with the batches its window needs."""
        with live.lock:
            if seq > live.applied:
                if seq == live.applied + 1:
                    pending = [(seq, objects, position)]
                else:
                    pending = self._pending(session_id, live, seq)
                for number, batch, at in pending:
                    result = live.localizer.update(list(batch), position=at)
                    assert result is not None
                    live.applied = number
                    live.answers[number] = result
                    live.seq_of.update((o.id, number) for o in batch)
                self._keep_state(session_id, live)
            result = live.answers.pop(seq, None)
            for old in [s for s in live.answers if s < seq - 64]:  # answers nobody came for
                del live.answers[old]
        if result is None:
            raise ServiceError(409, "update superseded", f"update {seq} was answered already")
        return result

    def _pending(self, session_id: str, live: _LiveSession, seq: int) -> list[tuple]:
        """The batches after `live.applied` up to `seq`, parsed.  When another worker let
        some of them go (its state is newer than this Localizer), the session is rebuilt
        here from that state first."""
        wanted = list(range(live.applied + 1, seq + 1))
        batches = self.store.batches(session_id, live.applied, seq)
        if [b.seq for b in batches] != wanted:
            _, global_map = self.object_map(live.map_id, live.map_version)
            fresh = self._rebuilt(session_id, global_map, live.map_id, live.map_version, live.up)
            live.localizer, live.applied, live.saved = fresh.localizer, fresh.applied, fresh.saved
            live.seq_of = fresh.seq_of
            batches = self.store.batches(session_id, live.applied, seq)
        return [(b.seq, _objects_map(b.objects, live.up, f"batch {b.seq}"), b.position)
                for b in batches]  # fmt: skip

    def _keep_state(self, session_id: str, live: _LiveSession) -> None:
        """Store the Localizer's state and let go of the batches its window no longer needs:
        after every update while the session tracks a place (a state then rebuilds it exactly),
        and every `SEARCH_CHECKPOINT` updates while it searches (the batches since the last
        state are replayed, which keeps a rebuild exact until then)."""
        if not live.localizer.tracking and live.applied - live.saved < self.SEARCH_CHECKPOINT:
            return
        window = live.localizer.window
        live.seq_of = {i: n for i, n in live.seq_of.items() if i in window}
        state = live.localizer.state()
        self.store.save_state(session_id, live.applied, state, set(live.seq_of.values()))
        live.saved = live.applied

    def delete_session(self, session_id: str) -> None:
        with self._lock:
            self._live.pop(session_id, None)
        if not self.store.delete_session(session_id):
            raise not_found(f"session {session_id!r}")

    def sessions(self, map_id: str) -> list[dict[str, Any]]:
        """The live sessions of a map with their latest answer (for the page)."""
        if self.store.latest_version(map_id) is None:
            raise not_found(f"map {map_id!r}")
        now = time.time()
        return [
            {"session_id": s.session_id, "map_version": s.map_version, "up": s.up,
             "idle_s": round(now - s.touched, 3), "last": s.last}
            for s in self.store.sessions_of(map_id)
            if now - s.touched <= self.session_idle_s
        ]  # fmt: skip

    def _expire(self) -> None:
        now = time.monotonic()
        if now < self._next_expiry:
            return
        self._next_expiry = now + self.EXPIRY_EVERY_S
        gone = self.store.expire_sessions(self.session_idle_s)
        with self._lock:
            for session_id in gone:
                self._live.pop(session_id, None)

    def session_objects(self, session_id: str) -> ObjectMap:
        """The objects a session keeps (the latest version of each, the current window's among
        them), in its frame."""
        row = self.store.session(session_id)
        if row is None:
            raise not_found(f"session {session_id!r}")
        latest: dict[str, Any] = {}
        for batch in self.store.batches(session_id):
            for raw in batch.objects:
                latest[str(raw["id"])] = raw
        return _objects_map(list(latest.values()), row.up, f"session {session_id}")

    # change reports ---------------------------------------------------------------------------
    def report_changes(self, map_id: str, body: Any) -> tuple[int, bool]:
        """Apply a localization result's changes as a new version: (version, written).  Nothing
        is written when the report changes nothing; `Conflict` (409) when the map moved on."""
        if not isinstance(body, dict):
            raise ServiceError(422, "invalid change report", "the body must be a result object")
        if self.store.latest_version(map_id) is None:
            raise not_found(f"map {map_id!r}")
        local, kept = self._reported_local(map_id, body)
        reported = {**body, **kept}  # the server's own record of the answer wins
        base_version = reported.get("map_version")
        if isinstance(base_version, bool) or not isinstance(base_version, int):
            raise ServiceError(422, "invalid change report", "'map_version' must be an integer")
        found = self.store.get_map(map_id, base_version)
        if found is None:
            raise ServiceError(422, "invalid change report", f"no version {base_version}")
        base = map_from_dict(found[1])
        pose, pairs = _reported_answer(reported)
        changes = answer_changes(
            base, local, pose, pairs, self.config.association, self.config.changes
        )  # the report's own `changes` are not trusted: they are recomputed here
        if not (changes.moved or changes.new or changes.missing or _flagged(base, changes)):
            return self.store.latest_version(map_id) or base_version, False

        def build(latest: int | None, document: dict | None) -> dict:
            assert latest is not None and document is not None
            current = map_from_dict(document)
            if latest != base_version:
                _check_still_applies(base, current, local, pose, changes)
            return map_to_dict(apply_changes(current, local, pose, changes))

        try:
            version = self.store.derive_map(map_id, build, f"changes (from version {base_version})")
        except Conflict as exc:
            raise ServiceError(409, "conflict", str(exc)) from None
        except KeyError:
            raise not_found(f"map {map_id!r}") from None
        return version, True

    def _reported_local(self, map_id: str, body: dict) -> tuple[ObjectMap, dict[str, Any]]:
        """The local objects of a report, and the server's own record of the answer when it
        kept one: the objects sent along (`local`: the body's answer is taken as it is), or
        those of the answer's one-shot localization (`localization_id`) or session
        (`session_id`, its latest answer)."""
        if "local" in body:
            return parse_map(body["local"], "local"), {}
        if isinstance(body.get("localization_id"), str):
            found = self.store.localization(body["localization_id"])
            if found is None or found[0] != map_id:
                raise ServiceError(422, "invalid change report",
                                   "unknown or expired localization_id: send 'local'")  # fmt: skip
            return map_from_dict(found[2]["local"]), found[2]["answer"]
        if isinstance(body.get("session_id"), str):
            row = self.store.session(body["session_id"])
            if row is None or row.map_id != map_id or row.last is None:
                raise ServiceError(422, "invalid change report",
                                   "unknown or expired session_id: send 'local'")  # fmt: skip
            kept = {key: row.last[key] for key in ANSWER_KEYS if key in row.last}
            return self.session_objects(body["session_id"]), kept
        raise ServiceError(
            422,
            "invalid change report",
            "the local objects are needed: 'local' (a semloc map), or the answer's "
            "'localization_id' or 'session_id'",
        )


def _reported_answer(body: dict) -> tuple[np.ndarray, list[tuple[str, str]]]:
    if body.get("status") != "localized" and not body.get("accept_ambiguous"):
        raise ServiceError(
            422, "not localized", f"status {body.get('status')!r}: only a localized answer's "
            "changes are applied (or set accept_ambiguous)",
        )  # fmt: skip
    try:
        pose = as_pose(body.get("pose"), "pose")
    except (ValueError, TypeError) as exc:
        raise ServiceError(422, "invalid change report", str(exc)) from None
    hypotheses = body.get("hypotheses") or []
    pairs: list[tuple[str, str]] = []
    if isinstance(hypotheses, list) and hypotheses and isinstance(hypotheses[0], dict):
        for pair in hypotheses[0].get("pairs") or []:
            if isinstance(pair, dict) and isinstance(pair.get("global"), (str, int)):
                pairs.append((str(pair["global"]), str(pair.get("local"))))
    return pose, pairs


def _flagged(base: ObjectMap, changes: Changes) -> bool:
    """Whether a matched object carries a `missing` flag the report would clear."""
    matched = set(changes.matched)
    return any(o.id in matched and "missing" in o.extra for o in base)


def _check_still_applies(base: ObjectMap, current: ObjectMap, local, pose, changes) -> None:
    """Raise `Conflict` when the versions written since `base` touched what the report changes
    or relies on: an object it moves, flags missing or matched was changed or removed, or an
    object added since lies where the report adds one (two devices reporting one new chair)."""
    before = {o.id: o for o in base}
    after = {o.id: o for o in current}
    touched = {
        i for i, o in before.items()
        if i not in after or not _same(o, after[i])
    }  # fmt: skip
    relied = {m.global_id for m in changes.moved} | set(changes.missing) | set(changes.matched)
    clash = sorted(relied & touched)
    if clash:
        raise Conflict(f"objects changed since the report's version: {', '.join(clash[:10])}")
    added = [o for i, o in after.items() if i not in before]
    if added and changes.new:
        R, t = pose[:3, :3], pose[:3, 3]
        placed = {o.id: R @ o.position + t for o in local}
        for local_id in changes.new:
            for other in added:
                if np.linalg.norm(other.position - placed[local_id]) < 1.0:
                    raise Conflict(
                        f"new object {local_id} lies where object {other.id} was added since"
                    )


def _same(a, b) -> bool:
    return (
        a.label == b.label
        and np.allclose(a.position, b.position, atol=1e-6)
        and (a.extra.get("missing") == b.extra.get("missing"))
    )


ANSWER_KEYS = ("status", "pose", "hypotheses", "map_version")
"""What the server keeps of an answer to check a change report of it."""


def _answer_record(document: dict[str, Any]) -> dict[str, Any]:
    """An answer's status, pose, map version and its best hypothesis' pairs."""
    best = document["hypotheses"][:1]
    return {"status": document["status"], "pose": document["pose"],
            "map_version": document["map_version"],
            "hypotheses": [{"pairs": h["pairs"]} for h in best]}  # fmt: skip


def _summary(document: dict[str, Any]) -> dict[str, Any]:
    """What the page shows of a session's latest answer (and a change report checks)."""
    shown = {key: document.get(key) for key in ("confidence", "stamp", "update")}
    return {**shown, **_answer_record(document)}
