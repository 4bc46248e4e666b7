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
candidate places differently until the search settles).  A session's position prior is set by
an update that carries `"prior"` (null clears it) and holds from then on: the batch keeps the
change (a rebuild replays it in order) and the kept state the prior in effect; a prior given
when the session opens is the kept state after batch 0 (a fresh Localizer with that prior).  Each session is pinned to the map version it was created on.  Parsed maps are kept
per (map, version) in a small cache (a version never changes once written).

A session belongs to its owner, the token that opened it: to any other caller it is as good as
absent (its id is a capability, never shown to another), except that a caller allowed to end
any session of its map may end it.  Writes that a device retries after losing the answer (an
upload, a change report, a session update) take a request key: the same key with the same body
gets the answer of the first request and writes nothing more; with another body it is refused.

Refusals are `ServiceError`s, one class per kind (`Invalid`, `NotFound`, `Conflict`,
`PreconditionFailed`); the web layer maps each kind to its HTTP status.
"""

from __future__ import annotations

import hashlib
import math
import re
import secrets
import threading
import time
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from pydantic import TypeAdapter, ValidationError

from semloc import schema
from semloc.changes import (
    Changes,
    ReportConflict,
    answer_changes,
    apply_changes,
    check_still_applies,
    flags_to_clear,
)
from semloc.coverage import Coverage
from semloc.io import map_from_dict, map_to_dict
from semloc.localizer import Localizer, LocalizerConfig, localize
from semloc.maps import MapError, ObjectMap
from semloc.priors import Prior
from semloc.results import Result
from semloc.serve.store import Batch, KeyTaken, Remembered, RequestKey, Store, session_scope
from semloc.transforms import as_pose

MAX_ID_LENGTH = 200


class ServiceError(Exception):
    """A request the service refuses: a short `error` and a `detail`; the class says which
    kind of refusal it is."""

    def __init__(self, error: str, detail: Any = None) -> None:
        super().__init__(error)
        self.error, self.detail = error, detail


class Invalid(ServiceError):
    """The request's content is not what the operation takes."""


class NotFound(ServiceError):
    """An unknown (or expired, or another owner's) map, version or session."""


class Conflict(ServiceError):
    """The write no longer applies: the map moved on, or the update was answered already."""


class PreconditionFailed(ServiceError):
    """The caller's condition on the map's latest version does not hold."""


def not_found(what: str) -> NotFound:
    return NotFound("not found", what)


ID = re.compile(rf"[^\x00-\x1f\x7f-\x9f/]{{1,{MAX_ID_LENGTH}}}")
"""A map id: 1 to 200 characters, none of them a control character or '/'."""


def check_id(value: str, what: str) -> str:
    if not ID.fullmatch(value):
        raise Invalid(f"invalid {what}", f"1 to {MAX_ID_LENGTH} characters, no control "
                      "character and no '/'")  # fmt: skip
    return value


Expected = list[int] | Literal["*"]
"""The versions a conditional upload expects to be the latest (`*`: any existing one)."""


@dataclass(frozen=True)
class Idempotency:
    """A write's Idempotency-Key and the digest of its body as it was sent (the same key with
    the same bytes is the same request)."""

    key: str
    digest: str

    @classmethod
    def of(cls, key: str | None, body: bytes) -> Idempotency | None:
        return None if key is None else cls(key, hashlib.sha256(body).hexdigest())


def request_key(scope: str, idempotency: Idempotency | None) -> RequestKey | None:
    """A write's request key under `scope` (whose, and what it writes: a session's keys are
    deleted with it); None without one."""
    if idempotency is None:
        return None
    key = idempotency.key
    if not key or len(key) > MAX_ID_LENGTH or not key.isprintable():
        raise Invalid("invalid Idempotency-Key", f"1 to {MAX_ID_LENGTH} printable characters")
    return RequestKey(scope, key, idempotency.digest)


def _same_body(key: RequestKey, remembered: Remembered) -> Remembered:
    if remembered.digest != key.digest:
        raise Invalid(
            "idempotency key reused",
            "this Idempotency-Key was used with another body: use a new key for a new request",
        )
    return remembered


def parse_map(document: Any, what: str = "body") -> ObjectMap:
    """A semloc map sent over HTTP (points inline: a `points_file` would name a server file)."""
    if isinstance(document, dict) and "points_file" in document:
        raise Invalid("invalid map", f"{what}: points must be inline, not a points_file")
    try:
        return map_from_dict(document)
    except MapError as exc:
        raise Invalid("invalid map", f"{what}: {exc}") from None


def _objects_map(objects: Any, up: list[float] | None, what: str) -> ObjectMap:
    if not isinstance(objects, list):
        raise Invalid("invalid objects", f"{what}: 'objects' must be a list")
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
        raise Invalid("invalid update", "'position' must be [x, y, z], finite numbers")
    return [float(v) for v in value]


def _prior(value: Any) -> Prior | None:
    """A body's `prior`: `Prior.to_dict`'s object (None: none); `Invalid` naming the problem."""
    if value is None:
        return None
    try:
        return Prior.from_dict(value)
    except (TypeError, ValueError) as exc:
        raise Invalid("invalid prior", str(exc)) from None


def _coverage(value: Any) -> Coverage | None:
    """An update's optional `coverage` (`Coverage.to_dict`'s object); `Invalid` naming the
    problem."""
    if value is None:
        return None
    try:
        return Coverage.from_dict(value)
    except (TypeError, ValueError) as exc:
        raise Invalid("invalid coverage", str(exc)) from None


def _prior_json(prior: Prior | None) -> dict[str, Any] | None:
    return None if prior is None else prior.to_dict()


@dataclass(frozen=True)
class _Update:
    """One batch of a session as its Localizer takes it: the objects, the device's position
    and, when the batch set one (`sets_prior`), the prior from then on (None: no prior)."""

    seq: int
    objects: ObjectMap
    position: list[float] | None = None
    sets_prior: bool = False
    prior: Prior | None = None
    coverage: Coverage | None = None

    @classmethod
    def of(cls, batch: Batch, up: list[float] | None) -> _Update:
        objects = _objects_map(batch.objects, up, f"batch {batch.seq}")
        prior = Prior.from_dict(batch.prior) if batch.prior is not None else None
        coverage = None if batch.coverage is None else Coverage.from_dict(batch.coverage)
        return cls(batch.seq, objects, batch.position, batch.sets_prior, prior, coverage)

    def apply(self, localizer: Localizer) -> Result:
        """The Localizer's answer after this batch (its prior set first, when it sets one)."""
        if self.sets_prior:
            localizer.set_prior(self.prior)
        result = localizer.update(
            list(self.objects), position=self.position, coverage=self.coverage
        )
        assert result is not None
        return result


@dataclass(frozen=True)
class SessionMeta:
    """What a session is: its map and version, its device frame's up, its owner."""

    session_id: str
    map_id: str
    map_version: int
    up: list[float] | None
    owner: str


@dataclass
class _LiveSession:
    """A session's Localizer in this process and the answers not yet read, by batch number."""

    localizer: Localizer
    meta: SessionMeta
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
    def put_map(
        self,
        map_id: str,
        document: Any,
        expected: Expected | None = None,
        idempotency: Idempotency | None = None,
        owner: str = "",
    ) -> int:
        """Store an upload by `owner` as the next version of `map_id`; its number.  With
        `expected`, only while the latest version is one of them (`PreconditionFailed`
        otherwise); with an `idempotency` key, once."""
        check_id(map_id, "map id")
        objmap = parse_map(document)
        key = request_key(f"upload {owner} {map_id}", idempotency)

        def check(latest: int | None) -> None:
            if expected is None:
                return
            if latest is None or (expected != "*" and latest not in expected):
                now = "no version" if latest is None else f"version {latest}"
                raise PreconditionFailed("precondition failed", f"the map {map_id!r} has {now}")

        if key is not None and (found := self.store.recall(key)) is not None:
            return _same_body(key, found).ref
        try:
            return self.store.put_map(
                map_id, map_to_dict(objmap), "upload", check, key,
                lambda version: {"map_id": map_id, "version": version},
            )  # fmt: skip
        except KeyTaken as taken:
            assert key is not None
            return _same_body(key, taken.remembered).ref

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
        """The answer for a local map (with its optional `prior`, echoed), with the map version
        and a `localization_id` under which the local map is kept (as long as an idle session)
        for a change report of the answer."""
        self._expire()
        prior = _prior(document.get("prior")) if isinstance(document, dict) else None
        version, global_map = self.object_map(map_id)
        local = parse_map(document)
        result = localize(global_map, local, self.config, prior=prior)
        document = result.to_dict(schema.LocalizeAnswer, map_version=version,
                                  localization_id=new_id())  # fmt: skip
        kept = {"local": map_to_dict(local), "answer": _answer_record(document)}
        self.store.put_localization(document["localization_id"], map_id, kept)
        return document

    # sessions ---------------------------------------------------------------------------------
    def create_session(self, map_id: str, body: Any, owner: str = "") -> str:
        """A new session on the latest version of `map_id`, owned by `owner`; its id.  A
        body's `prior` holds from the first update on: the session starts from the kept state
        of a fresh Localizer with that prior (batch 0), so a rebuild anywhere has it."""
        self._expire()
        up, prior = None, None
        if body is not None:
            if not isinstance(body, dict) or set(body) - {"up", "prior"}:
                raise Invalid(
                    "invalid session", 'the body is optional: {"up": [x, y, z], "prior": {...}}'
                )
            up = body.get("up")
            if up is not None:
                _objects_map([], up, "body")  # validates `up` as a map's
            prior = _prior(body.get("prior"))
        version, global_map = self.object_map(map_id)
        session_id = new_id()
        localizer, state = None, None
        if prior is not None:
            localizer = Localizer(global_map, self.config, local_up=up, prior=prior)
            state = {**localizer.state(), "prior": _prior_json(prior)}
        self.store.create_session(session_id, map_id, version, up, owner, state)
        if localizer is not None:  # this worker holds it: the first update here builds nothing
            meta = SessionMeta(session_id, map_id, version, up, owner)
            self._hold(_LiveSession(localizer, meta))
        return session_id

    def session_of(self, session_id: str, owner: str, ends_any: bool = False) -> SessionMeta:
        """The live session `owner` may use (`NotFound` for an unknown or expired one, and for
        another owner's: its id is a capability).  `ends_any`: the caller may end any
        session, a check the caller makes once it knows the session's map."""
        meta = self._session_meta(session_id)
        if meta.owner != owner and not ends_any:
            raise not_found(f"session {session_id!r}")
        return meta

    def session_map(self, session_id: str) -> str:
        """The map of a live session, whoever owns it (`NotFound` if unknown or expired)."""
        return self._session_meta(session_id).map_id

    def _session_meta(self, session_id: str) -> SessionMeta:
        """What a session is: from memory where it is live here (an update still checks in the
        store that it exists), else from the store."""
        with self._lock:
            live = self._live.get(session_id)
        if live is not None:
            return live.meta
        row = self.store.session(session_id)
        if row is None or time.time() - row.touched > self.session_idle_s:
            raise not_found(f"session {session_id!r}")
        return SessionMeta(session_id, row.map_id, row.map_version, row.up, row.owner)

    def update_session(
        self, session_id: str, body: Any, idempotency: Idempotency | None = None
    ) -> dict[str, Any]:
        """The answer after one more batch of a session's objects (the caller checked that it
        owns the session).  A batch sent again with its `idempotency` key is answered as the
        first time and not applied again."""
        self._expire()
        meta = self._session_meta(session_id)
        key = request_key(session_scope(session_id), idempotency)
        if not isinstance(body, dict) or "objects" not in body:
            raise Invalid("invalid update", 'body: {"objects": [...], "stamp": float}')
        stamp = body.get("stamp", 0.0)
        if (
            isinstance(stamp, bool)
            or not isinstance(stamp, (int, float))
            or not math.isfinite(stamp)
        ):
            raise Invalid("invalid update", "'stamp' must be a finite number")
        position = _position(body.get("position"))
        sets_prior, prior = "prior" in body, _prior(body.get("prior"))
        coverage = _coverage(body.get("coverage"))
        objects = _objects_map(body["objects"], meta.up, "objects")  # refused before it is stored
        try:  # a key used before is found under the session's lock: nothing appended
            seq = self.store.append_batch(
                session_id, float(stamp), body["objects"], self.session_idle_s, key, position,
                sets_prior, _prior_json(prior), None if coverage is None else coverage.to_dict(),
            )  # fmt: skip
        except KeyTaken as taken:
            assert key is not None
            return self._answered(meta, _same_body(key, taken.remembered))
        if seq is None:
            with self._lock:
                self._live.pop(session_id, None)
            raise not_found(f"session {session_id!r}")
        live = self._live_session(meta)
        update = _Update(seq, objects, position, sets_prior, prior, coverage)
        result = self._advance(session_id, live, update)
        document = self._session_answer(result, meta, stamp, seq)
        self.store.set_last(session_id, _summary(document), key, document)
        return document

    @staticmethod
    def _session_answer(
        result: Result, meta: SessionMeta, stamp: float, seq: int
    ) -> dict[str, Any]:
        return result.to_dict(schema.SessionAnswer, map_version=meta.map_version, stamp=stamp,
                              session_id=meta.session_id, update=seq)  # fmt: skip

    def _answered(self, meta: SessionMeta, remembered: Remembered) -> dict[str, Any]:
        """The answer to a session update sent again: the stored one, or (when the first
        request has not stored it yet, or died before) the session rebuilt from its kept state
        and the batches after it, up to that update (409 when the kept state is already past
        it: the answer is lost, the next update answers)."""
        if remembered.answer is not None:
            return remembered.answer
        live = self._rebuilt(meta)
        if live.applied >= remembered.ref:
            raise Conflict("update superseded", f"update {remembered.ref} was answered already")
        result, stamp = None, 0.0
        for batch in self.store.batches(meta.session_id, live.applied, remembered.ref):
            result = _Update.of(batch, meta.up).apply(live.localizer)
            stamp = batch.stamp
        if result is None:
            raise not_found(f"session {meta.session_id!r}")
        return self._session_answer(result, meta, float(stamp), remembered.ref)

    def _live_session(self, meta: SessionMeta) -> _LiveSession:
        session_id = meta.session_id
        with self._lock:
            live = self._live.get(session_id)
            if live is not None:
                self._live.move_to_end(session_id)
                return live
        return self._hold(self._rebuilt(meta))

    def _hold(self, fresh: _LiveSession) -> _LiveSession:
        """Keep a session's Localizer in this process (the one held already, if another
        thread was first); the least recently used go beyond `LIVE_SESSIONS`."""
        with self._lock:
            live = self._live.setdefault(fresh.meta.session_id, fresh)
            while len(self._live) > self.LIVE_SESSIONS:
                self._live.popitem(last=False)  # rebuilt from the store if it comes back
        return live

    def _rebuilt(self, meta: SessionMeta) -> _LiveSession:
        """The session from its kept state and window objects (fresh when it has none)."""
        session_id, up = meta.session_id, meta.up
        _, global_map = self.object_map(meta.map_id, meta.map_version)
        for _ in range(3):  # another worker may let batches go between the two reads
            saved = self.store.session_state(session_id)
            if saved is None:
                return _LiveSession(Localizer(global_map, self.config, local_up=up), meta)
            seq, state = saved
            latest: dict[str, tuple[int, dict]] = {}
            for batch in self.store.batches(session_id, 0, seq):
                for raw in batch.objects:
                    latest[str(raw["id"])] = (batch.seq, raw)
            order = [str(i) for i in state["window"]["order"]]
            if all(i in latest for i in order):
                objects = _objects_map([latest[i][1] for i in order], up, "session state")
                prior = None if state.get("prior") is None else Prior.from_dict(state["prior"])
                localizer = Localizer.restore(global_map, state, objects, self.config, up, prior)
                live = _LiveSession(localizer, meta, applied=seq, saved=seq)
                live.seq_of = {i: latest[i][0] for i in order}
                return live
        raise Conflict("session busy", "its kept state changed while it was read; retry")

    def _advance(self, session_id: str, live: _LiveSession, update: _Update) -> Result:
        """Apply the batches up to `update` not yet applied here, in order (those of other
        workers read from the store); the answer after `update`.  The
        state after them is kept in the store, with the batches its window needs."""
        seq = update.seq
        with live.lock:
            if seq > live.applied:
                if seq == live.applied + 1:
                    pending = [update]
                else:
                    pending = self._pending(session_id, live, seq)
                for batch in pending:
                    result = batch.apply(live.localizer)
                    live.applied = batch.seq
                    live.answers[batch.seq] = result
                    live.seq_of.update((o.id, batch.seq) for o in batch.objects)
                self._keep_state(session_id, live)
            answer = live.answers.pop(seq, None)
            for old in [s for s in live.answers if s < seq - 64]:  # answers nobody came for
                del live.answers[old]
        if answer is None:
            raise Conflict("update superseded", f"update {seq} was answered already")
        return answer

    def _pending(self, session_id: str, live: _LiveSession, seq: int) -> list[_Update]:
        """The batches after `live.applied` up to `seq`, parsed.  When another worker let
        some of them go (its state is newer than this Localizer), the session is rebuilt
        here from that state first."""
        wanted = list(range(live.applied + 1, seq + 1))
        batches = self.store.batches(session_id, live.applied, seq)
        if [b.seq for b in batches] != wanted:
            fresh = self._rebuilt(live.meta)
            live.localizer, live.applied, live.saved = fresh.localizer, fresh.applied, fresh.saved
            live.seq_of = fresh.seq_of
            batches = self.store.batches(session_id, live.applied, seq)
        return [_Update.of(b, live.meta.up) for b in batches]

    def _keep_state(self, session_id: str, live: _LiveSession) -> None:
        """Store the Localizer's state and let go of the batches its window no longer needs:
        after every update while the session tracks a place (a state then rebuilds it exactly),
        and every `SEARCH_CHECKPOINT` updates while it searches (the batches since the last
        state are replayed, which keeps a rebuild exact until then)."""
        if not live.localizer.tracking and live.applied - live.saved < self.SEARCH_CHECKPOINT:
            return
        window = live.localizer.window
        live.seq_of = {i: n for i, n in live.seq_of.items() if i in window}
        state = {**live.localizer.state(), "prior": _prior_json(live.localizer.prior)}
        self.store.save_state(session_id, live.applied, state, set(live.seq_of.values()))
        live.saved = live.applied

    def delete_map(self, map_id: str) -> None:
        """Delete a map with every version and its sessions (`NotFound` if it is not there)."""
        if not self.store.delete_map(map_id):
            raise not_found(f"map {map_id!r}")
        with self._lock:
            for key in [k for k in self._maps if k[0] == map_id]:
                del self._maps[key]
            for session_id in [s for s, live in self._live.items() if live.meta.map_id == map_id]:
                del self._live[session_id]

    def delete_session(self, session_id: str) -> None:
        with self._lock:
            self._live.pop(session_id, None)
        if not self.store.delete_session(session_id):
            raise not_found(f"session {session_id!r}")

    def sessions(self, map_id: str, owner: str = "") -> list[dict[str, Any]]:
        """The live sessions of a map with their latest answer (for the page); the ids of
        `owner`'s own sessions only (an id is a capability)."""
        if self.store.latest_version(map_id) is None:
            raise not_found(f"map {map_id!r}")
        now = time.time()
        return [
            {"session_id": s.session_id if s.owner == owner else None,
             "mine": s.owner == owner, "map_version": s.map_version, "up": s.up,
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
    def report_changes(
        self, map_id: str, body: Any, idempotency: Idempotency | None = None, owner: str = ""
    ) -> dict[str, Any]:
        """Apply a localization result's changes as a new version: `{"version", "changed"}`.
        Nothing is written when the report changes nothing; `Conflict` when the map moved on
        and the report no longer applies.  A report sent again by `owner` with its
        `idempotency` key gets the first answer.

        The changes are never the body's own: they are recomputed from the local objects, the
        pose and the pairs (`answer_changes`), except for a session (`session_id`) whose latest
        answer tracks its place: then they are the run's report that the server itself
        accumulated over the walk (`Result.changes` while tracked: moved and new objects seen
        at least twice, missing ones looked at twice and not seen), which is what a robot's
        day found, with the evidence a single view lacks (a phantom is seen once), together
        with the moves the latest view shows of objects the run does not name (a single
        view's move needs its old place seen empty: evidence of its own); that view's new and
        missing objects are not taken.  Moved objects go where the session's latest detection
        of them puts them under the answer's pose; map objects the latest view sees in place
        clear their `missing` flag."""
        if not isinstance(body, dict):
            raise Invalid("invalid change report", "the body must be a result object")
        key = request_key(f"changes {owner} {map_id}", idempotency)
        if self.store.latest_version(map_id) is None:
            raise not_found(f"map {map_id!r}")
        if key is not None and (found := self.store.recall(key)) is not None:
            return _same_body(key, found).answer or {"version": found.ref, "changed": True}
        try:
            return self._report_changes(map_id, body, key)
        except KeyTaken as taken:
            assert key is not None
            found = _same_body(key, taken.remembered)
            return found.answer or {"version": found.ref, "changed": True}

    def _report_changes(self, map_id: str, body: dict, key: RequestKey | None) -> dict[str, Any]:
        local, kept = self._reported_local(map_id, body)
        reported = {**body, **kept}  # the server's own record of the answer wins
        base_version = reported.get("map_version")
        if isinstance(base_version, bool) or not isinstance(base_version, int):
            raise Invalid("invalid change report", "'map_version' must be an integer")
        found = None if abs(base_version) > 2**62 else self.store.get_map(map_id, base_version)
        if found is None:
            raise not_found(f"map {map_id!r} has no version {base_version}")
        base = map_from_dict(found[1])
        try:
            pose, pairs = _reported_answer(reported)
        except Invalid as exc:
            if not kept:
                raise
            # the body is well formed; the server's own record of its answer is not appliable
            raise Conflict("answer not appliable", f"the kept answer: {exc.detail}") from None
        changes = answer_changes(
            base, local, pose, pairs, self.config.association, self.config.changes
        )  # the report's own `changes` are not trusted: they are recomputed here
        if isinstance(kept.get(RUN_CHANGES), dict):  # the server's own record of the run
            changes = _run_report(changes, Changes.from_dict(kept[RUN_CHANGES]), local)
        if not (changes.moved or changes.new or changes.missing or flags_to_clear(base, changes)):
            latest = self.store.latest_version(map_id) or base_version
            unchanged = {"version": latest, "changed": False}
            if key is not None and (taken := self.store.remember(key, latest, unchanged)):
                raise KeyTaken(taken)
            return unchanged

        def build(latest: int | None, document: dict | None) -> dict:
            assert latest is not None and document is not None
            current = map_from_dict(document)
            if latest != base_version:
                check_still_applies(base, current, local, pose, changes)
            try:
                return map_to_dict(apply_changes(current, local, pose, changes))
            except MapError as exc:  # e.g. a new object's embedding of another length
                raise ReportConflict(f"the map cannot take these changes: {exc}") from None

        try:
            version = self.store.derive_map(
                map_id, build, f"changes (from version {base_version})", key=key,
                answer=lambda version: {"version": version, "changed": True},
            )  # fmt: skip
        except ReportConflict as exc:
            raise Conflict("conflict", str(exc)) from None
        except KeyError:
            raise not_found(f"map {map_id!r}") from None
        return {"version": version, "changed": True}

    def _reported_local(self, map_id: str, body: dict) -> tuple[ObjectMap, dict[str, Any]]:
        """The local objects of a report, and the server's own record of the answer when it
        kept one: the objects sent along (`local`: the body's answer is taken as it is), or
        those of the answer's one-shot localization (`localization_id`) or session
        (`session_id`, its latest answer)."""
        if body.get("local") is not None:
            return parse_map(body["local"], "local"), {}
        if isinstance(body.get("localization_id"), str):
            found = self.store.localization(body["localization_id"])
            if found is None or found[0] != map_id:
                raise not_found("unknown or expired localization_id: send 'local'")
            return map_from_dict(found[2]["local"]), found[2]["answer"]
        if isinstance(body.get("session_id"), str):
            row = self.store.session(body["session_id"])
            if row is None or row.map_id != map_id or row.last is None:
                raise not_found("unknown or expired session_id: send 'local'")
            kept = {key: row.last[key] for key in ANSWER_KEYS if key in row.last}
            return self.session_objects(body["session_id"]), kept
        raise Invalid(
            "invalid change report",
            "the local objects are needed: 'local' (a semloc map), or the answer's "
            "'localization_id' or 'session_id'",
        )


def _reported_answer(body: dict) -> tuple[np.ndarray, list[tuple[str, str]]]:
    if body.get("status") != "localized" and not body.get("accept_ambiguous"):
        raise Invalid(
            "not localized", f"status {body.get('status')!r}: only a localized answer's "
            "changes are applied (or set accept_ambiguous)",
        )  # fmt: skip
    if body.get("pose") is None:
        raise Invalid("no pose", "the answer found no pose: there is nothing to apply")
    try:
        pose = as_pose(body.get("pose"), "pose")
    except (ValueError, TypeError) as exc:
        raise Invalid("invalid change report", str(exc)) from None
    hypotheses = body.get("hypotheses") or []
    best = hypotheses[0] if isinstance(hypotheses, list) and hypotheses else {}
    try:
        pairs = _PAIRS.validate_python((best.get("pairs") or []) if isinstance(best, dict) else [])
    except ValidationError as exc:
        detail = schema.field_error(exc, "hypotheses[0].pairs")
        raise Invalid("invalid change report", detail) from None
    return pose, [(p.global_, p.local) for p in pairs]


_PAIRS = TypeAdapter(list[schema.Pair])
"""A reported answer's pairs (`schema.Pair`: ids, integers taken as their strings)."""


RUN_CHANGES = "run_changes"
"""The key of a session's summary that holds its tracked answer's run report."""
ANSWER_KEYS = ("status", "pose", "hypotheses", "map_version", RUN_CHANGES)
"""What the server keeps of an answer to check a change report of it."""


def _run_report(latest: Changes, run: Changes, local: ObjectMap) -> Changes:
    """A session's run report as the changes to apply: its moved, new and missing objects
    (those whose local objects the session holds); the moves the latest view shows of objects
    the run does not name (a single view's move has evidence of its own: the old place seen
    empty, with points); and the map objects the latest view matched in place (which clear a
    `missing` flag).  The latest view's new and missing objects are left out: once is not
    enough (a phantom, a miss)."""
    held = set(local.ids.tolist())
    moved = [m for m in run.moved if m.local_id in held]
    named = {m.global_id for m in moved} | set(run.missing)
    named_local = {m.local_id for m in moved} | set(run.new)
    moved += [m for m in latest.moved
              if m.global_id not in named and m.local_id not in named_local]  # fmt: skip
    changed = {m.global_id for m in moved} | set(run.missing)
    matched = [g for g in latest.matched if g not in changed]
    return Changes(moved, [i for i in run.new if i in held], list(run.missing), matched,
                   evidence=run.evidence)  # fmt: skip


def _answer_record(document: dict[str, Any]) -> dict[str, Any]:
    """An answer's status, pose, map version and its best hypothesis' pairs."""
    best = document["hypotheses"][:1]
    return {"status": document["status"], "pose": document["pose"],
            "map_version": document["map_version"],
            "hypotheses": [{"pairs": h["pairs"]} for h in best]}  # fmt: skip


def _summary(document: dict[str, Any]) -> dict[str, Any]:
    """What the page shows of a session's latest answer (and a change report checks)."""
    shown = {key: document.get(key) for key in ("confidence", "stamp", "update")}
    summary = {**shown, **_answer_record(document)}
    if (document.get("support") or {}).get("tracked") and document.get("changes"):
        summary[RUN_CHANGES] = document["changes"]  # the run's report (see report_changes)
    return summary


def new_id() -> str:
    """A new random id (a session's, a localization's): 24 URL-safe characters, never
    starting with "-" (a command line would read it as an option: `semloc sessions show
    MAP -x...`)."""
    while (found := secrets.token_urlsafe(18)).startswith("-"):
        pass
    return found
