"""`semloc serve` as a process: one-line refusals of bad settings, a clean stop, and no
acknowledged write lost when the process is killed (-9) at random moments."""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from semloc.client import Client, ServerError
from semloc.io import map_to_dict
from semloc.maps import ObjectMap, SemanticObject

SEMLOC = [sys.executable, "-m", "semloc"]
HANG_SECONDS = 300
"""A server that has not answered its health check by then is hung (slow machines included)."""
pytestmark = [
    pytest.mark.usefixtures("compiled"),  # the servers load compiled code, not compile
    pytest.mark.slow,  # a server process per test, started, killed, restarted: 5-30 s each
]


def start(data: Path, *options: str) -> tuple[subprocess.Popen, str]:
    """`semloc serve --data DATA --port 0 ...`; the process and the URL it printed."""
    process = subprocess.Popen(
        [*SEMLOC, "serve", "--data", str(data), "--port", "0", *options],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    lines = [process.stderr.readline() for _ in range(1)]
    while "listening on" not in lines[-1] and lines[-1] and len(lines) < 5:
        lines.append(process.stderr.readline())  # "compiling…" first on a cold cache
    line = lines[-1]
    assert "listening on http://127.0.0.1:" in line, lines
    url = line.split("listening on ")[1].split()[0]
    deadline = time.monotonic() + HANG_SECONDS  # a guard against a hang, not a timing
    while True:
        try:
            Client(url, timeout=30).health()
            return process, url
        except ServerError:
            assert time.monotonic() < deadline, f"the server did not answer in {HANG_SECONDS} s"
            time.sleep(0.05)


def refused(*arguments: str) -> str:
    done = subprocess.run([*SEMLOC, "serve", *arguments], capture_output=True, text=True,
                          timeout=60)  # fmt: skip
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("semloc: error: "), done.stderr
    return lines[0]


def test_bad_settings_are_one_line_and_status_2(tmp_path):
    tokens = tmp_path / "tokens.json"
    tokens.write_text('{"tokens": [{"token": "short", "maps": {"*": ["read"]}}]}')
    assert "at least 8 characters" in refused("--data", str(tmp_path), "--tokens", str(tokens))
    assert "loopback" in refused("--data", str(tmp_path), "--host", "0.0.0.0")
    (tmp_path / "file").write_text("")
    assert "is a file" in refused("--data", str(tmp_path / "file"))
    assert "postgresql://" in refused("--data", str(tmp_path), "--db", "mysql://x")
    assert "workers" in refused("--data", str(tmp_path), "--workers", "0")
    bad_config = tmp_path / "config.json"
    bad_config.write_text('{"gamma": 7}')
    assert "gamma" in refused("--data", str(tmp_path), "--config", str(bad_config))


def test_a_busy_port_is_one_line(tmp_path):
    process, url = start(tmp_path / "a")
    try:
        port = url.rsplit(":", 1)[1]
        assert "cannot serve on" in refused("--data", str(tmp_path / "b"), "--port", port)
    finally:
        process.terminate()
        process.wait(120)


def test_sigterm_stops_it_cleanly_and_the_store_survives(tmp_path):
    process, url = start(tmp_path)
    objmap = ObjectMap([SemanticObject("1", "chair", [1.0, 2.0, 0.5])])
    assert Client(url).put_map("m", objmap) == 1
    process.send_signal(signal.SIGTERM)
    _, stderr = process.communicate(timeout=120)
    assert "Traceback" not in stderr
    assert process.returncode == 143 and stderr.strip().splitlines() == ["semloc: interrupted"]
    process, url = start(tmp_path)
    try:
        assert Client(url).get_map("m").get("1").label == "chair"
    finally:
        process.terminate()
        process.wait(120)


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_several_workers_stop_with_the_status_of_the_signal(tmp_path, signum):
    """With worker processes (uvicorn's supervisor) as with one: 128 + the signal number."""
    process, _ = start(tmp_path, "--workers", "2")
    process.send_signal(signum)
    _, stderr = process.communicate(timeout=120)
    assert process.returncode == 128 + signum, stderr
    assert stderr.strip().splitlines() == ["semloc: interrupted"]


def _documents(rng: random.Random, n: int) -> list[dict]:
    """n maps of 20-200 objects with points (large enough that a write takes a while)."""
    out = []
    for k in range(n):
        count = rng.randint(20, 200)
        generator = np.random.default_rng(k)
        objects = [SemanticObject(f"o{i}", "chair", generator.uniform(-50, 50, 3),
                                  points=generator.uniform(-1, 1, (50, 3)))
                   for i in range(count)]  # fmt: skip
        out.append(map_to_dict(ObjectMap(objects, name=f"doc{k}")))
    return out


def test_no_acknowledged_write_is_lost_when_killed(tmp_path):
    """Uploads from two threads while the server is killed (-9) at random moments, 6 times:
    after each restart every acknowledged version holds exactly what was sent, and every
    stored version is whole.  (benchmarks/bench_serve.py --faults runs 50 kills.)"""
    rng = random.Random(7)
    documents = _documents(rng, 6)
    acknowledged: dict[tuple[str, int], str] = {}  # (map, version) -> the document's name
    for _ in range(6):
        process, url = start(tmp_path)
        stop = threading.Event()

        def upload(worker: int, url: str = url, stop: threading.Event = stop) -> None:
            client = Client(url, timeout=5)
            while not stop.is_set():
                document = documents[rng.randrange(len(documents))]
                map_id = f"m{worker}"
                try:
                    version = client.put_map(map_id, document)
                except ServerError:
                    return  # killed
                acknowledged[(map_id, version)] = document["name"]

        threads = [threading.Thread(target=upload, args=(w,)) for w in range(2)]
        for thread in threads:
            thread.start()
        time.sleep(rng.uniform(0.2, 0.8))
        os.kill(process.pid, signal.SIGKILL)
        process.wait(10)
        stop.set()
        for thread in threads:
            thread.join(10)
        assert acknowledged, "nothing was acknowledged before the kill"
    process, url = start(tmp_path)  # restarts (how fast: benchmarks/bench_serve.py)
    try:
        client = Client(url)
        names = {d["name"]: d for d in documents}
        for (map_id, version), name in acknowledged.items():
            stored = client.request("GET", f"/v1/maps/{map_id}?version={version}")
            assert stored["name"] == name and len(stored["objects"]) == len(names[name]["objects"])
        for map_id in ("m0", "m1"):
            versions = [v["version"] for v in client.versions(map_id)]
            assert versions == list(range(1, len(versions) + 1))
            for version in versions:  # every stored version is whole
                stored = client.request("GET", f"/v1/maps/{map_id}?version={version}")
                assert stored["name"] in names
                assert json.dumps(stored["objects"]) == json.dumps(names[stored["name"]]["objects"])
    finally:
        process.terminate()
        process.wait(120)


def test_without_the_serve_extra_it_names_the_extra(tmp_path, monkeypatch, capsys):
    pytest.importorskip("fastapi")
    from semloc.cli import extras

    monkeypatch.setattr(extras, "missing", lambda module: module == "fastapi")
    from semloc.cli import main

    assert main(["serve", "--data", str(tmp_path)]) == 2
    assert "needs the 'serve' extra (fastapi is not installed)" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []  # no store was made


def test_the_loopback_rule_and_the_store_are_the_settings_own(tmp_path):
    """Whoever starts the server (`run`, `serving`, the command): no open API on a network
    address, and a store is needed (a folder or a database, not both required)."""
    from pydantic import ValidationError

    from semloc.serve.server import ServeSettings, serving

    for host in ("0.0.0.0", "192.168.1.10", "::"):
        with pytest.raises(ValidationError, match="loopback address only"):
            ServeSettings(data=tmp_path, host=host)
    tokens = tmp_path / "tokens.json"
    tokens.write_text('{"tokens": [{"token": "a-long-token", "maps": {"*": ["read"]}}]}')
    assert ServeSettings(data=tmp_path, host="0.0.0.0", tokens=tokens).host == "0.0.0.0"
    assert ServeSettings(data=tmp_path, host="::1").host == "::1"
    with pytest.raises(ValidationError, match="a store is needed"):
        ServeSettings()
    with (
        pytest.raises(ValidationError, match="loopback address only"),
        serving(tmp_path, host="0.0.0.0"),
    ):
        pass
    assert "a store is needed" in refused("--port", "0")


def test_with_db_no_data_folder_is_needed(postgres_url, building):
    from semloc.serve.server import serving
    from semloc.serve.store import open_store

    try:
        with serving(None, db=postgres_url, db_pool=2) as url:
            assert Client(url).put_map("m", building) >= 1
            assert Client(url).get_map("m").get(building[0].id).label == building[0].label
    finally:
        store = open_store(None, postgres_url)
        with store._transaction(write=True) as cur:
            cur.execute("DROP TABLE maps, map_versions, sessions, session_batches, "
                        "localizations, schema_version")  # fmt: skip
        store.close()
