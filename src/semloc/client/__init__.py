"""`semloc.client.Client`: talk to a `semloc serve` server from Python (standard library only).

    from semloc.client import Client
    client = Client("http://127.0.0.1:8765", token="...")
    client.put_map("office", semloc.load_map("office.json"))        # -> version 1
    answer = client.localize("office", semloc.load_map("local.json"))
    with client.session("office", up=[0, 0, 1]) as session:          # a device's live session
        answer = session.update([semloc.SemanticObject("l0", "chair", [1, 0, 0.4])], stamp=0.0)
    client.report_changes("office", answer, local=local_map)       # -> {"version": 2, ...}

Position priors (`semloc.Prior`, or its JSON object): `client.localize(map_id, local,
prior=P)`; `client.session(map_id, prior=P)` opens a session with a prior from its first update
on; `session.update(objects, prior=P)` sets a session's prior from that update on and
`session.update(objects, clear_prior=True)` removes it.  Answers echo the prior in effect as
`"prior"` (null: none).

Answers are the JSON documents of `semloc localize --format json` (dicts) plus `map_version`.
Every refusal of the server raises `ServerError` with its status, error and detail.  One
keep-alive connection per thread; a Client may be shared between threads.  The URL may carry a
base path (`https://hub.example/semloc`: the API is then under `/semloc/v1`).

Retries: a request is sent again (up to `retries` times) when the connection failed or the
server answered 429 or 503 (after its `Retry-After`, at most `max_wait` seconds), but only when
sending it twice cannot do it twice: reads, deletions, one-shot localizations, and the writes
that carry an `Idempotency-Key` (uploads, change reports, session updates: the client sends a
fresh key with each; the server answers a repeat with the first answer and writes once).
Opening a session is not repeated after a lost answer (it would open a second one).
"""

from __future__ import annotations

import http.client
import json
import os
import select
import socket
import threading
import time
import urllib.parse
import uuid
from collections.abc import Iterable, Sequence
from typing import Any

from semloc.coverage import Coverage, checked_coverage
from semloc.io import load_map, map_from_dict, map_to_dict
from semloc.maps import ObjectMap, SemanticObject
from semloc.priors import Prior, checked_prior

__all__ = ["Client", "ServerError", "Session"]

MapLike = ObjectMap | dict[str, Any] | str | os.PathLike[str]


class ServerError(Exception):
    """The server refused a request (`status` 4xx / 5xx) or could not be reached (status 0)."""

    def __init__(self, status: int, error: str, detail: Any = None) -> None:
        super().__init__(f"{status} {error}" + (f": {detail}" if detail else ""))
        self.status, self.error, self.detail = status, error, detail


class Client:
    """A connection to a semloc server at `url` (http://host:port) with a `token` (or none)."""

    def __init__(
        self,
        url: str,
        token: str | None = None,
        timeout: float = 60.0,
        retries: int = 2,
        max_wait: float = 30.0,
    ) -> None:
        parts = urllib.parse.urlsplit(url)
        if parts.scheme not in ("http", "https") or not parts.hostname or parts.query:
            raise ValueError(f"server URL must be http(s)://host[:port][/base], got {url!r}")
        self.url, self.token, self.timeout = url.rstrip("/"), token, timeout
        self.retries, self.max_wait = retries, max_wait
        self._parts = parts
        self._base = parts.path.rstrip("/")
        self._local = threading.local()

    # maps -------------------------------------------------------------------------------------
    def health(self) -> dict[str, Any]:
        return self.request("GET", "/v1/health")

    def maps(self) -> list[dict[str, Any]]:
        """The maps this token may read, with their latest version."""
        return self.request("GET", "/v1/maps")

    def put_map(self, map_id: str, objmap: MapLike, if_match: int | None = None) -> int:
        """Upload a map (a new version if it exists); its version.  With `if_match`, only if
        the map's latest version is still that one (ServerError 412 otherwise)."""
        headers = {} if if_match is None else {"If-Match": f'"{int(if_match)}"'}
        return self.request(
            "PUT", f"/v1/maps/{_quote(map_id)}", _map_document(objmap), headers, key=True
        )["version"]

    def get_map(self, map_id: str, version: int | None = None) -> ObjectMap:
        query = "" if version is None else f"?version={int(version)}"
        return map_from_dict(self.request("GET", f"/v1/maps/{_quote(map_id)}{query}"))

    def delete_map(self, map_id: str) -> None:
        """Delete a map with every version and its sessions (needs `write`)."""
        self.request("DELETE", f"/v1/maps/{_quote(map_id)}")

    def versions(self, map_id: str) -> list[dict[str, Any]]:
        return self.request("GET", f"/v1/maps/{_quote(map_id)}/versions")

    # localization -----------------------------------------------------------------------------
    def localize(
        self, map_id: str, local: MapLike, prior: Prior | dict[str, Any] | None = None
    ) -> dict[str, Any]:
        """Localize a local map (replayed by `seen`) in the latest version of `map_id`, within
        the position `prior` when one is given (checked here: `ValueError`, `TypeError`)."""
        body = _map_document(local)
        checked = checked_prior(prior)
        if checked is not None:
            body["prior"] = checked.to_dict()
        return self.request("POST", f"/v1/maps/{_quote(map_id)}/localize", body)

    def session(
        self,
        map_id: str,
        up: Iterable[float] | None = None,
        prior: Prior | dict[str, Any] | None = None,
    ) -> Session:
        """A live session on `map_id`: stream objects with `Session.update`.  `prior`: its
        position prior from the first update on (checked here: `ValueError`, `TypeError`)."""
        body: dict[str, Any] = {}
        if up is not None:
            body["up"] = [float(v) for v in up]
        checked = checked_prior(prior)
        if checked is not None:
            body["prior"] = checked.to_dict()
        created = self.request("POST", f"/v1/maps/{_quote(map_id)}/sessions", body or None)
        return Session(self, created["session_id"])

    def report_changes(
        self,
        map_id: str,
        answer: dict[str, Any],
        local: MapLike | None = None,
        session_id: str | None = None,
    ) -> dict[str, Any]:
        """Apply what `answer` (a localization of that map, with its `map_version`) found
        changed, as a new version: `{"version", "changed"}`; ServerError 409 when the map moved
        on and the changes no longer apply.  The local objects are `local` when given, else the
        server's copy of them (the answer's `localization_id` or `session_id`)."""
        body = dict(answer)
        if local is not None:
            body["local"] = _map_document(local)
        elif session_id is not None or "session_id" in answer:
            body["session_id"] = session_id or answer["session_id"]
        return self.request("POST", f"/v1/maps/{_quote(map_id)}/changes", body, key=True)

    # sessions, maps (administration) ----------------------------------------------------------
    def sessions(self, map_id: str) -> list[dict[str, Any]]:
        """The live sessions of `map_id`: `session_id` (of this token's own only, else None),
        `mine`, `map_version`, `up`, `idle_s` and `last` (status, pose, stamp)."""
        return self.request("GET", f"/v1/maps/{_quote(map_id)}/sessions")

    def end_session(self, session_id: str) -> None:
        """End a session: this token's own, or any session of a map it may write."""
        self.request("DELETE", f"/v1/sessions/{_quote(session_id)}")

    # HTTP -------------------------------------------------------------------------------------
    def request(
        self,
        method: str,
        path: str,
        body: Any = None,
        headers: dict[str, str] | None = None,
        key: bool = False,
    ) -> Any:
        """One request to `path` (below the URL's base path); the decoded JSON answer (None for
        204), or ServerError.  `key`: send an Idempotency-Key, which makes a write safe to
        retry.  Retried as the module says."""
        payload = None if body is None else json.dumps(body, allow_nan=False).encode()
        sent = {"Accept": "application/json", **(headers or {})}
        if payload is not None:
            sent["Content-Type"] = "application/json"
        if self.token:
            sent["Authorization"] = f"Bearer {self.token}"
        if key:
            sent["Idempotency-Key"] = uuid.uuid4().hex
        safe = key or method in ("GET", "HEAD", "DELETE") or path.endswith("/localize")
        for attempt in range(self.retries + 1):
            last = attempt == self.retries
            try:
                status, retry_after, data = self._send(method, self._base + path, payload, sent)
            except (ConnectionError, http.client.HTTPException, TimeoutError, OSError) as exc:
                self.close()
                if last or not safe:
                    raise ServerError(0, "unreachable", f"{self.url}: {exc}") from None
                time.sleep(min(self.max_wait, 0.1 * 2**attempt))
                continue
            if status in (429, 503) and not last and (safe or status == 429):
                time.sleep(min(self.max_wait, retry_after))  # 429: nothing was done
                continue
            break
        if method == "DELETE" and status == 404 and attempt > 0:
            return None  # the first attempt did it; its answer was lost
        return _decoded(status, data)

    def _send(
        self, method: str, path: str, payload: bytes | None, headers: dict[str, str]
    ) -> tuple[int, float, bytes]:
        """(status, Retry-After in seconds, body) of one exchange."""
        connection = self._connection()
        connection.request(method, path, payload, headers)
        response = connection.getresponse()
        data = response.read()
        return response.status, _seconds(response.getheader("Retry-After")), data

    def _connection(self) -> http.client.HTTPConnection:
        connection = getattr(self._local, "connection", None)
        if connection is not None and _dropped(connection):
            connection.close()  # the server closed the kept-alive connection meanwhile
            connection = self._local.connection = None
        if connection is None:
            kind = (
                http.client.HTTPSConnection
                if self._parts.scheme == "https"
                else http.client.HTTPConnection
            )
            connection = kind(self._parts.hostname, self._parts.port, timeout=self.timeout)
            connection.connect()
            # small requests go out at once (no 40 ms wait for a delayed acknowledgement)
            connection.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._local.connection = connection
        return connection

    def close(self) -> None:
        connection = getattr(self._local, "connection", None)
        if connection is not None:
            connection.close()
            self._local.connection = None


class Session:
    """A live session: each `update` adds new or changed local objects and returns the answer."""

    def __init__(self, client: Client, session_id: str) -> None:
        self.client, self.session_id = client, session_id

    def update(
        self,
        objects: Iterable[SemanticObject | dict[str, Any]],
        stamp: float = 0.0,
        position: Sequence[float] | None = None,
        prior: Prior | dict[str, Any] | None = None,
        clear_prior: bool = False,
        coverage: Coverage | dict[str, Any] | None = None,
    ) -> dict[str, Any]:
        """The answer after these objects, with `stamp` echoed (the device adds its own motion
        since `stamp` to the pose).  `position`: the device in its own frame, [x, y, z] (it
        measures the travel that bounds the session's window).  `prior`: the session's
        position prior from this update on; `clear_prior`: none from this update on (without
        either the prior stays as it was).  `coverage`: what the sensor covered at this
        update (`semloc.Coverage`; the objects are every detection of that look)."""
        body: dict[str, Any] = {"objects": _object_documents(objects), "stamp": float(stamp)}
        if position is not None:
            body["position"] = [float(v) for v in position]
        checked = checked_prior(prior)
        if checked is not None and clear_prior:
            raise ValueError("prior and clear_prior=True contradict each other")
        if checked is not None or clear_prior:
            body["prior"] = None if checked is None else checked.to_dict()
        look = checked_coverage(coverage)
        if look is not None:
            body["coverage"] = look.to_dict()
        path = f"/v1/sessions/{_quote(self.session_id)}/objects"
        return self.client.request("POST", path, body, key=True)

    def close(self) -> None:
        self.client.request("DELETE", f"/v1/sessions/{_quote(self.session_id)}")

    def __enter__(self) -> Session:
        return self

    def __exit__(self, *exc: object) -> None:
        try:
            self.close()
        except ServerError as error:
            if error.status != 404:  # expired already
                raise


def _decoded(status: int, data: bytes) -> Any:
    """The JSON of an answer, or ServerError for a refusal."""
    if status == 204 or not data:
        _raise_for(status, None)
        return None
    try:
        document = json.loads(data)
    except ValueError:
        document = {"error": data[:200].decode(errors="replace")}
    _raise_for(status, document)
    return document


def _seconds(retry_after: str | None) -> float:
    """A Retry-After header's delay (seconds; 1 when absent or an HTTP date)."""
    try:
        return max(0.0, float(retry_after)) if retry_after else 1.0
    except ValueError:
        return 1.0


def _dropped(connection: http.client.HTTPConnection) -> bool:
    """Whether a kept-alive connection was closed by the server (readable while idle: EOF)."""
    sock = connection.sock
    if sock is None:
        return True
    try:
        return bool(select.select([sock], [], [], 0)[0])
    except (OSError, ValueError):
        return True


def _raise_for(status: int, document: Any) -> None:
    if status < 400:
        return
    if isinstance(document, dict):
        raise ServerError(status, str(document.get("error", "")), document.get("detail"))
    raise ServerError(status, "error", document)


def _quote(value: str) -> str:
    return urllib.parse.quote(value, safe="")


def _map_document(objmap: MapLike) -> dict[str, Any]:
    if isinstance(objmap, ObjectMap):
        return map_to_dict(objmap)
    if isinstance(objmap, dict):
        return objmap
    return map_to_dict(load_map(objmap))  # a file: its points_file read here, sent inline


def _object_documents(objects: Iterable[SemanticObject | dict[str, Any]]) -> list[dict]:
    items = list(objects)
    if all(isinstance(o, dict) for o in items):
        return items
    as_objects = [o for o in items if isinstance(o, SemanticObject)]
    if len(as_objects) != len(items):
        raise TypeError("update() takes SemanticObjects or object dicts")
    return map_to_dict(ObjectMap(as_objects))["objects"]
