"""The API as `/openapi.json` describes it, tested from outside: every route declares its body,
its answers and its errors; schemathesis (every check, every phase) finds nothing against a
live server on loopback."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import LiveServer
from test_api import raw

from semloc.client import Client
from semloc.io import map_to_dict
from semloc.maps import ObjectMap, SemanticObject
from semloc.serve.access import Access
from semloc.serve.service import Service
from semloc.serve.store import open_store

pytestmark = pytest.mark.usefixtures("compiled")
TOKEN = "openapi-token-1"
HERE = Path(__file__).parent


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    folder = tmp_path_factory.mktemp("openapi")
    tokens = folder / "tokens.json"
    tokens.write_text(
        json.dumps({"tokens": [{"token": TOKEN, "maps": {"*": ["read", "localize", "write"]}}]})
    )
    running = LiveServer(Service(open_store(folder / "data")), Access.from_file(tokens), rate=0)
    objects = [SemanticObject(str(i), "chair", [i, 0.3 * i, 0.4], size=[0.5, 0.5, 0.9])
               for i in range(6)]  # fmt: skip
    Client(running.url, TOKEN).put_map("m", map_to_dict(ObjectMap(objects, up=[0, 0, 1])))
    yield running
    running.stop()


def test_every_route_declares_its_body_answers_errors_and_security(server):
    status, spec = raw(server.url, "GET", "/openapi.json")
    assert status == 200
    assert spec["components"]["securitySchemes"] == {
        "HTTPBearer": {
            "type": "http",
            "scheme": "bearer",
            "description": "A token of the server's token file.",
        }
    }
    schemas = spec["components"]["schemas"]
    assert schemas["Error"]["required"] == ["error"] and set(schemas["Error"]["properties"]) == {
        "error",
        "detail",
    }
    assert "HTTPValidationError" not in schemas
    bodies = {("put", "/v1/maps/{map_id}"): "SemlocMap", ("post", "/v1/maps/{map_id}/localize"): "LocalizeRequest",
              ("post", "/v1/maps/{map_id}/sessions"): "SessionCreate",
              ("post", "/v1/sessions/{session_id}/objects"): "SessionUpdate",
              ("post", "/v1/maps/{map_id}/changes"): "ChangeReport"}  # fmt: skip
    for model in ("LocalizeRequest", "SessionCreate", "SessionUpdate"):  # a position prior
        declared = schemas[model]["properties"]["prior"]["anyOf"]
        assert {"$ref": "#/components/schemas/PriorBody"} in declared, model
    operations = [(m, p, o) for p, ops in spec["paths"].items() for m, o in ops.items()]
    assert len(operations) == 14  # DELETE /v1/maps/{map_id} included
    for method, path, operation in operations:
        body = operation.get("requestBody")
        if (method, path) in bodies:
            assert body["content"]["application/json"]["schema"]["$ref"].endswith(
                bodies[method, path]
            )
        else:
            assert body is None, (method, path)
        for code, answer in operation["responses"].items():
            if code == "204":
                continue
            media = "text/plain" if path == "/metrics" and code == "200" else "application/json"
            schema = answer["content"][media]["schema"]
            assert schema != {}, (method, path, code)
            if int(code) >= 400:
                assert schema == {"$ref": "#/components/schemas/Error"}, (method, path, code)
        if path not in ("/v1/health", "/v1/ready"):
            optional = [{}] if path == "/metrics" else []  # loopback: no token needed
            assert operation["security"] == [*optional, {"HTTPBearer": []}], (method, path)
            needed = {"401", "403"} if path == "/metrics" else {"401", "429"}  # no rate there
            assert needed <= set(operation["responses"]), (method, path)


@pytest.mark.slow  # up to 300 s
def test_schemathesis_finds_nothing(server, tmp_path):
    """Every check and every phase, bounded (examples per operation, seconds), seeded; the
    rules JSON Schema cannot state are schemathesis_hooks.py's.  Any finding fails the test
    with schemathesis's report."""
    pytest.importorskip("schemathesis", reason="schemathesis (the test extra) is not installed")
    command = [
        sys.executable, "-m", "schemathesis.cli", "--config-file", str(HERE / "schemathesis.toml"),
        "run", f"{server.url}/openapi.json",
        "--checks", "all", "--phases", "examples,coverage,fuzzing,stateful",
        "--max-examples", "25", "--max-time", "40", "--seed", "53", "--workers", "1",
        "--suppress-health-check", "too_slow",
        "--request-timeout", "30", "--no-color",
    ]  # fmt: skip
    environment = {
        **os.environ,
        "SCHEMATHESIS_HOOKS": "schemathesis_hooks",
        "SEMLOC_OPENAPI_TOKEN": TOKEN,
        "PYTHONPATH": os.pathsep.join([str(HERE), os.environ.get("PYTHONPATH", "")]),
    }
    done = subprocess.run(
        command, capture_output=True, text=True, timeout=300, env=environment, cwd=tmp_path
    )
    (tmp_path / "schemathesis.txt").write_text(done.stdout + done.stderr)
    report = done.stdout[-6000:] + done.stderr[-2000:]
    assert done.returncode == 0, f"{tmp_path / 'schemathesis.txt'}\n{report}"
    assert "No issues found" in done.stdout or "passed" in done.stdout, report
