"""`semloc.client.Client`: talk to a `semloc serve` server from Python (standard library only).

    from semloc.client import Client
    client = Client("http://127.0.0.1:8765", token="...")
    client.put_map("office", semloc.load_map("office.json"))        # -> version 1
    answer = client.localize("office", semloc.load_map("local.json"))
    with client.session("office", up=[0, 0, 1]) as session:          # a device's live session
        answer = session.update([semloc.SemanticObject("l0", "chair", [1, 0, 0.4])], stamp=0.0)
    client.report_changes("office", answer, local=local_map)       # -> {"version": 2, ...}

Answers are the JSON documents of `semloc localize --format json` (dicts) plus `map_version`.
Every refusal of the server raises `ServerError` with its status, error and detail.  One
keep-alive connection per thread; a Client may be shared between threads.
"""

from __future__ import annotations

import http.client
import json
import os
import socket
import threading
import urllib.parse
from collections.abc import Iterable, Sequence
from typing import Any

from semloc.io import load_map, map_from_dict, map_to_dict
from semloc.maps import ObjectMap, SemanticObject

__all__ = ["Client", "ServerError", "Session"]

MapLike = ObjectMap | dict[str, Any] | str | os.PathLike[str]


class ServerError(Exception):
    """The server refused a request (`status` 4xx / 5xx) or could not be reached (status 0)."""

    def __init__(self, status: int, error: str, detail: Any = None) -> None:
        super().__init__(f"{status} {error}" + (f": {detail}" if detail else ""))
        self.status, self.error, self.detail = status, error, detail


class Client:
    """A connection to a semloc server at `url` (http://host:port) with a `token` (or none)."""

    def __init__(self, url: str, token: str | None = None, timeout: float = 60.0) -> None:
        parts = urllib.parse.urlsplit(url)
        if parts.scheme not in ("http", "https") or not parts.hostname:
            raise ValueError(f"server URL must be http(s)://host[:port], got {url!r}")
        self.url, self.token, self.timeout = url.rstrip("/"), token, timeout
        self._parts = parts
        self._local = threading.local()

    # maps -------------------------------------------------------------------------------------
    def health(self) -> dict[str, Any]:
        return self.request("GET", "/v1/health")

    def maps(self) -> list[dict[str, Any]]:
        """The maps this token may read, with their latest version."""
        return self.request("GET", "/v1/maps")

    def put_map(self, map_id: str, objmap: MapLike) -> int:
        """Upload a map (a new version if it exists); its version."""
        return self.request("PUT", f"/v1/maps/{_quote(map_id)}", _map_document(objmap))["version"]

    def get_map(self, map_id: str, version: int | None = None) -> ObjectMap:
        query = "" if version is None else f"?version={int(version)}"
        return map_from_dict(self.request("GET", f"/v1/maps/{_quote(map_id)}{query}"))

    def versions(self, map_id: str) -> list[dict[str, Any]]:
        return self.request("GET", f"/v1/maps/{_quote(map_id)}/versions")

    # localization -----------------------------------------------------------------------------
    def localize(self, map_id: str, local: MapLike) -> dict[str, Any]:
        """Localize a local map (replayed by `seen`) in the latest version of `map_id`."""
        return self.request("POST", f"/v1/maps/{_quote(map_id)}/localize", _map_document(local))

    def session(self, map_id: str, up: Iterable[float] | None = None) -> Session:
        """A live session on `map_id`: stream objects with `Session.update`."""
        body = None if up is None else {"up": [float(v) for v in up]}
        created = self.request("POST", f"/v1/maps/{_quote(map_id)}/sessions", body)
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
        return self.request("POST", f"/v1/maps/{_quote(map_id)}/changes", body)

    # HTTP -------------------------------------------------------------------------------------
    def request(self, method: str, path: str, body: Any = None) -> Any:
        """One request; the decoded JSON answer (None for 204), or ServerError."""
        payload = None if body is None else json.dumps(body, allow_nan=False).encode()
        headers = {"Accept": "application/json"}
        if payload is not None:
            headers["Content-Type"] = "application/json"
        if self.token:
            headers["Authorization"] = f"Bearer {self.token}"
        for attempt in (0, 1):  # a kept-alive connection the server closed: one retry
            try:
                connection = self._connection()
                connection.request(method, path, payload, headers)
                response = connection.getresponse()
                data = response.read()
                break
            except (ConnectionError, http.client.HTTPException, TimeoutError, OSError) as exc:
                self.close()
                if attempt:
                    raise ServerError(0, "unreachable", f"{self.url}: {exc}") from None
        if response.status == 204 or not data:
            _raise_for(response.status, None)
            return None
        try:
            document = json.loads(data)
        except ValueError:
            document = {"error": data[:200].decode(errors="replace")}
        _raise_for(response.status, document)
        return document

    def _connection(self) -> http.client.HTTPConnection:
        connection = getattr(self._local, "connection", None)
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
    ) -> dict[str, Any]:
        """The answer after these objects, with `stamp` echoed (the device adds its own motion
        since `stamp` to the pose).  `position`: the device in its own frame, [x, y, z] (it
        measures the travel that bounds the session's window)."""
        body: dict[str, Any] = {"objects": _object_documents(objects), "stamp": float(stamp)}
        if position is not None:
            body["position"] = [float(v) for v in position]
        return self.client.request("POST", f"/v1/sessions/{_quote(self.session_id)}/objects", body)

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
