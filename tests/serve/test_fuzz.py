"""Property-based bad input against a live server: any JSON value or bytes on any route gets
a 2xx or a 4xx with the error shape, never a 5xx, and the server keeps answering."""

from __future__ import annotations

import json

import pytest
from conftest import LiveServer
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_api import raw

from semloc.client import Client
from semloc.io import map_to_dict
from semloc.maps import ObjectMap, SemanticObject
from semloc.serve.service import Service
from semloc.serve.store import open_store

pytestmark = pytest.mark.usefixtures("compiled")

JSON = st.recursive(
    st.none() | st.booleans() | st.integers(-(2**70), 2**70) | st.floats(allow_nan=False)
    | st.text(max_size=12),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner, max_size=4),
    max_leaves=20,
)  # fmt: skip
OBJECT = st.fixed_dictionaries(
    {"id": st.one_of(st.text(max_size=5), st.integers()), "label": st.text(max_size=6),
     "position": st.lists(st.floats(allow_nan=False), min_size=0, max_size=4)},
    optional={"size": JSON, "rotation": JSON, "points": st.lists(st.lists(st.floats(-5, 5),
              min_size=3, max_size=3), max_size=5), "seen": JSON},
)  # fmt: skip
MAPS = st.fixed_dictionaries(
    {"format": st.sampled_from(["semloc-map", "x"]), "version": st.sampled_from([1, 2, "1"]),
     "objects": st.lists(OBJECT, max_size=4)},
    optional={"up": JSON, "name": JSON},
)  # fmt: skip


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    running = LiveServer(Service(open_store(tmp_path_factory.mktemp("fuzz"))), rate=0)
    objects = [SemanticObject(str(i), "chair", [i, 0.3 * i, 0.4]) for i in range(6)]
    Client(running.url).put_map("m", map_to_dict(ObjectMap(objects, up=[0, 0, 1])))
    running.session_id = Client(running.url).session("m").session_id
    yield running
    running.stop()


def routes(server) -> list[tuple[str, str]]:
    return [("PUT", "/v1/maps/f"), ("POST", "/v1/maps/m/localize"), ("POST", "/v1/maps/m/changes"),
            ("POST", f"/v1/sessions/{server.session_id}/objects"), ("POST", "/v1/maps/m/sessions")]  # fmt: skip


def check(server, body: bytes) -> None:
    for method, path in routes(server):
        status, answer = raw(server.url, method, path, body)
        assert status < 500, (method, path, body[:200], answer)
        if status >= 400:
            assert isinstance(answer, dict) and set(answer) == {"error", "detail"}, answer


SETTINGS = settings(max_examples=40, suppress_health_check=[HealthCheck.too_slow])


@SETTINGS
@given(value=JSON)
def test_any_json_value(server, value):
    check(server, json.dumps(value).encode())


@SETTINGS
@given(document=MAPS)
def test_map_like_documents(server, document):
    check(server, json.dumps(document).encode())
    check(server, json.dumps({"objects": document["objects"], "stamp": 1.0}).encode())
    report = {"status": "localized", "map_version": 1, "pose": [[1, 0, 0, 0], [0, 1, 0, 0],
              [0, 0, 1, 0], [0, 0, 0, 1]], "local": document}  # fmt: skip
    check(server, json.dumps(report).encode())


@SETTINGS
@given(body=st.binary(max_size=200))
def test_any_bytes(server, body):
    check(server, body)


def test_the_server_still_answers(server):
    assert Client(server.url).health()["status"] == "ok"
