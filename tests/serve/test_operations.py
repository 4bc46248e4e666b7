"""What an operator sees: /metrics (Prometheus text format, loopback or a token with a right on
`*`), /v1/ready (the store answers, or 503), the opt-in access log (a JSON line per request,
a request id, never a token)."""

from __future__ import annotations

import asyncio
import json
import logging
import sqlite3
import time
import urllib.request
from typing import Any

import pytest
from conftest import T_TRUE, view
from test_api import raw

from semloc.client import Client
from semloc.io import map_to_dict
from semloc.serve.access import Access
from semloc.serve.app import create_app
from semloc.serve.service import Service
from semloc.serve.store import open_store

ADMIN, OFFICE = "admin-token-1", "office-token-1"
TOKENS = {"tokens": [{"token": ADMIN, "maps": {"*": ["read"], "office": ["localize", "write"]}},
                     {"token": OFFICE, "maps": {"office": ["read", "localize", "write"]}}]}  # fmt: skip


@pytest.fixture
def secured(serve, tmp_path):
    path = tmp_path / "tokens.json"
    path.write_text(json.dumps(TOKENS))
    return serve(access=Access.from_file(path))


def _text(url: str, path: str, token: str | None = None) -> tuple[int, str, Any]:
    request = urllib.request.Request(url + path)
    if token:
        request.add_header("Authorization", f"Bearer {token}")
    with urllib.request.urlopen(request, timeout=30) as response:
        return response.status, response.read().decode(), response.headers


def test_metrics_count_requests_answers_and_live_sessions(secured, building):
    url = secured.url
    client = Client(url, OFFICE)
    client.put_map("office", building)
    local = view(building, [3, 4, 5, 6, 7, 8, 9], T_TRUE)
    session = client.session("office", up=local.up.tolist())
    assert session.update(list(local))["status"] == "localized"
    client.localize("office", view(building, [0, 1, 2], T_TRUE))
    assert raw(url, "GET", "/v1/maps/nowhere", None, OFFICE)[0] == 404
    status, text, headers = _text(url, "/metrics")  # loopback: no token needed
    assert status == 200 and headers["Content-Type"].startswith("text/plain")
    lines = text.splitlines()
    for expected in (
        'semloc_requests_total{method="PUT",route="/v1/maps/{map_id}",status="201"} 1.0',
        'semloc_requests_total{method="GET",route="/v1/maps/{map_id}",status="404"} 1.0',
        'semloc_requests_total{method="POST",route="/v1/sessions/{session_id}/objects",'
        'status="200"} 1.0',
        'semloc_localize_answers_total{kind="session",status="localized"} 1.0',
        'semloc_localize_answers_total{kind="one-shot",status="ambiguous"} 1.0',
        "semloc_live_sessions 1.0",
        "semloc_store_errors_total 0.0",
    ):
        assert expected in lines, expected
    assert any(line.startswith('semloc_request_seconds_bucket{le="0.1",method="POST",'
                               'route="/v1/maps/{map_id}/localize"}') for line in lines)  # fmt: skip
    assert "nowhere" not in text and session.session_id not in text  # ids are not labels


def _asgi_get(app, path: str, token: str | None, client: str) -> int:
    """The status of a GET sent straight to the ASGI app from `client` (an address that is
    not loopback, which a test cannot open a socket from)."""
    headers = [(b"authorization", f"Bearer {token}".encode())] if token else []
    scope = {"type": "http", "asgi": {"version": "3.0"}, "http_version": "1.1", "method": "GET",
             "scheme": "http", "path": path, "raw_path": path.encode(), "query_string": b"",
             "root_path": "", "headers": headers, "client": (client, 50000),
             "server": ("10.0.0.1", 8765)}  # fmt: skip
    sent: list[dict] = []

    async def receive() -> dict:
        return {"type": "http.request", "body": b"", "more_body": False}

    async def send(message: dict) -> None:
        sent.append(message)

    asyncio.run(app(scope, receive, send))
    return next(m["status"] for m in sent if m["type"] == "http.response.start")


def test_metrics_off_loopback_need_a_token_with_a_right_on_every_map(tmp_path):
    path = tmp_path / "tokens.json"
    path.write_text(json.dumps(TOKENS))
    app = create_app(Service(open_store(tmp_path / "data")), Access.from_file(path))
    assert _asgi_get(app, "/metrics", None, "10.0.0.7") == 401
    assert _asgi_get(app, "/metrics", OFFICE, "10.0.0.7") == 403  # office only
    assert _asgi_get(app, "/metrics", ADMIN, "10.0.0.7") == 200  # read on *
    assert _asgi_get(app, "/metrics", None, "127.0.0.1") == 200
    assert _asgi_get(app, "/metrics", None, "::1") == 200
    assert _asgi_get(app, "/v1/ready", None, "10.0.0.7") == 200  # no token needed


def test_ready_says_whether_the_store_answers(secured, monkeypatch):
    url = secured.url
    assert raw(url, "GET", "/v1/ready") == (200, {"status": "ready"})
    store = secured.service.store

    def broken(*args, **kwargs):
        raise sqlite3.OperationalError("disk I/O error")

    monkeypatch.setattr(store, "_transaction", broken)
    status, error = raw(url, "GET", "/v1/ready")
    assert status == 503 and error == {
        "error": "not ready", "detail": "the store does not answer (OperationalError)"}  # fmt: skip
    assert raw(url, "GET", "/v1/health")[0] == 200  # the process itself answers
    status, text, _ = _text(url, "/metrics")
    assert "semloc_store_errors_total 1.0" in text.splitlines()
    assert "semloc_live_sessions NaN" in text.splitlines()  # counted in the store: unknown
    monkeypatch.undo()
    assert raw(url, "GET", "/v1/ready")[0] == 200


def test_the_access_log_is_one_json_line_per_request_without_the_token(serve, tmp_path,
                                                                      building, caplog):  # fmt: skip
    path = tmp_path / "tokens.json"
    path.write_text(json.dumps(TOKENS))
    server = serve(access=Access.from_file(path), access_log=True)
    logger = logging.getLogger("semloc.serve.access")
    logger.addHandler(caplog.handler)
    try:
        document = json.dumps(map_to_dict(building)).encode()
        assert raw(server.url, "PUT", "/v1/maps/office", document, OFFICE,
                   headers={"X-Request-ID": "upload-17"})[0] == 201  # fmt: skip
        assert raw(server.url, "GET", "/v1/maps/office/versions", None, "wrong-token-9")[0] == 401
        request = urllib.request.Request(server.url + "/v1/health")
        with urllib.request.urlopen(request, timeout=30) as response:
            generated = response.headers["X-Request-ID"]
        deadline = (
            time.monotonic() + 120
        )  # a line is written once its answer has gone out (a hang guard)
        while len(caplog.records) < 3 and time.monotonic() < deadline:
            time.sleep(0.01)
    finally:
        logger.removeHandler(caplog.handler)
    lines = [json.loads(r.getMessage()) for r in caplog.records if r.name == logger.name]
    assert [(l["method"], l["route"], l["status"]) for l in lines] == [
        ("PUT", "/v1/maps/{map_id}", 201), ("GET", "/v1/maps/{map_id}/versions", 401),
        ("GET", "/v1/health", 200)]  # fmt: skip
    assert lines[0]["request_id"] == "upload-17" and lines[0]["caller"] == Access.from_file(
        path).grant(OFFICE).name  # fmt: skip
    assert lines[2]["request_id"] == generated and len(generated) == 32
    assert lines[0]["path"] == "/v1/maps/office" and lines[0]["client"] == "127.0.0.1"
    text = "\n".join(r.getMessage() for r in caplog.records)
    assert OFFICE not in text and "wrong-token-9" not in text
