"""What an operator sees of `semloc serve`: Prometheus metrics, request ids, the access log.

`Observer` holds one app's metrics in its own registry (prometheus-client): requests by route,
method and status, their latency (histogram), localization answers by kind and status, live
sessions (counted in the store when scraped) and store errors.  `ObserveMiddleware` (ASGI)
counts and times every request under its route's template (never the raw path: a map or
session id is not a label), gives each request an id (the caller's `X-Request-ID` when it is a
short visible-ASCII string, else a fresh one; echoed in the answer), and with `access_log`
writes one JSON line per request to the `semloc.serve.access` logger: time, request id,
method, route, path, status, milliseconds, client address and the caller's non-secret name
(the first digits of its token's digest), never a token.

With several worker processes (`PROMETHEUS_MULTIPROC_DIR` set by the server), a scrape sums
the counters and histograms of every worker (prometheus-client's multiprocess mode).
"""

from __future__ import annotations

import json
import logging
import os
import sys
import time
import uuid
from collections.abc import Awaitable, Callable, MutableMapping
from typing import Any

from prometheus_client import (
    CONTENT_TYPE_LATEST,
    CollectorRegistry,
    Counter,
    Histogram,
    generate_latest,
    multiprocess,
)
from prometheus_client.core import GaugeMetricFamily

ACCESS = logging.getLogger("semloc.serve.access")
LATENCY_BUCKETS = (0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0)
Scope = MutableMapping[str, Any]
ASGI = Callable[
    [Scope, Callable[[], Awaitable[Any]], Callable[[Any], Awaitable[None]]], Awaitable[None]
]


class Observer:
    """One app's metrics; `live_sessions()` counts the live sessions when scraped."""

    def __init__(self, live_sessions: Callable[[], int]) -> None:
        self.registry = CollectorRegistry(auto_describe=True)
        self._multiprocess = bool(os.environ.get("PROMETHEUS_MULTIPROC_DIR"))
        registry = None if self._multiprocess else self.registry
        self.requests = Counter("semloc_requests", "HTTP requests by route, method and status.",
                                ["route", "method", "status"], registry=registry)  # fmt: skip
        self.latency = Histogram("semloc_request_seconds", "Time to answer, by route and method.",
                                 ["route", "method"], buckets=LATENCY_BUCKETS,
                                 registry=registry)  # fmt: skip
        self.answers = Counter("semloc_localize_answers", "Localization answers by kind "
                               "(one-shot, session) and status.", ["kind", "status"],
                               registry=registry)  # fmt: skip
        self.store_errors = Counter("semloc_store_errors", "Store operations that failed.",
                                    registry=registry)  # fmt: skip
        self.registry.register(_LiveSessions(live_sessions))

    def exposition(self) -> tuple[bytes, str]:
        """The metrics in the Prometheus text format, and its content type."""
        if not self._multiprocess:
            return generate_latest(self.registry), CONTENT_TYPE_LATEST
        registry = CollectorRegistry()
        multiprocess.MultiProcessCollector(registry)
        live = generate_latest(self.registry)  # counted here, at the scrape
        return generate_latest(registry) + live, CONTENT_TYPE_LATEST


class _LiveSessions:
    """The live sessions, counted in the store at each scrape (NaN when the store fails)."""

    def __init__(self, count: Callable[[], int]) -> None:
        self.count = count

    def collect(self) -> Any:
        try:
            value = float(self.count())
        except Exception:  # a dead store: the scrape still answers
            value = float("nan")
        yield GaugeMetricFamily(
            "semloc_live_sessions", "Sessions not idle for longer than the idle time.", value
        )


class ObserveMiddleware:
    """Counts, times and (with `access_log`) logs every HTTP request; sets its request id."""

    def __init__(self, app: ASGI, observer: Observer, access_log: bool = False) -> None:
        self.app, self.observer, self.access_log = app, observer, access_log
        if access_log and not ACCESS.handlers:
            handler = logging.StreamHandler(sys.stderr)
            handler.setFormatter(logging.Formatter("%(message)s"))
            ACCESS.addHandler(handler)
            ACCESS.setLevel(logging.INFO)
            ACCESS.propagate = False

    async def __call__(self, scope: Scope, receive: Any, send: Any) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        started = time.perf_counter()
        request_id = _request_id(scope)
        scope.setdefault("state", {})["request_id"] = request_id
        status = 500

        async def sending(message: MutableMapping[str, Any]) -> None:
            nonlocal status
            if message["type"] == "http.response.start":
                status = message["status"]
                message.setdefault("headers", [])
                message["headers"] = [*message["headers"], (b"x-request-id", request_id.encode())]
            await send(message)

        try:
            await self.app(scope, receive, sending)
        finally:
            self._record(scope, request_id, status, time.perf_counter() - started)

    def _record(self, scope: Scope, request_id: str, status: int, seconds: float) -> None:
        route = scope.get("route")
        template = getattr(route, "path", None) or "unmatched"
        method = scope["method"]
        self.observer.requests.labels(template, method, str(status)).inc()
        self.observer.latency.labels(template, method).observe(seconds)
        if self.access_log:
            client = scope.get("client")
            ACCESS.info(json.dumps({
                "time": round(time.time(), 3), "request_id": request_id, "method": method,
                "route": template, "path": scope.get("path", ""), "status": status,
                "ms": round(seconds * 1000, 2), "client": client[0] if client else None,
                "caller": scope.get("state", {}).get("caller"),
            }))  # fmt: skip


def _request_id(scope: Scope) -> str:
    for name, value in scope.get("headers", ()):
        if name == b"x-request-id" and 0 < len(value) <= 64 and all(33 <= c <= 126 for c in value):
            return value.decode()
    return uuid.uuid4().hex
