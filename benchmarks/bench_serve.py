"""The service under load, over time, under faults and under bad input (`semloc serve`).

    PYTHONPATH=src python benchmarks/bench_serve.py [--devices 8 32 128] [--seconds 30]
        [--hz 1] [--workers 2] [--db postgresql://...] [--soak 600] [--faults 50] [--fuzz 2000]
        [--startup-maps 100] [--access] [--markdown TABLE.md]

A `semloc serve` process on a loopback port (`--workers` processes over one store, SQLite in a
temporary folder or `--db`) holds the three real maps (ScanNet scene0000_00, Replica office4,
3RScan scene_1; simulated buildings when the real samples are absent).

1. **Load**: N simulated devices (`--devices`, threads of this process, each with its own
   keep-alive connection), each streaming real-layout views (the views of
   `semloc.eval.variants`: clean and noisy, 3 / 5 / 8 objects with points) through a live
   session, one update (one keyframe's objects) every 1/`--hz` seconds, for `--seconds`.
   Printed: per-update latency p50 / p95 / p99 / max, errors, updates a second, and updates per
   CPU-second of the server (its processes' CPU time over the run: updates a second per core
   it keeps busy).  Every answer is compared with an in-process `Localizer` fed the same
   batches: status, pose (1e-9) and pairs must be identical.  `/metrics` is scraped every 2 s
   during each row, as a Prometheus server would: scrapes, their time, failures, and the
   session updates the metrics counted (summed over the workers) against the devices' count.
2. **Soak** (`--soak S`): 32 devices for S seconds; the server's resident memory sampled every
   10 s (first, last, largest): a leak shows as growth.
3. **Faults** (`--faults K`): uploads and change reports from two threads while the server is
   killed (-9) at a random moment, K times, restarted each time: every acknowledged version
   must be there and whole.  Then the start-up time of a server over `--startup-maps` maps.
4. **Bad input** (`--fuzz R`): R requests of every bad-input class (malformed JSON, wrong
   schema, NaN, oversized bodies, unknown ids, bad tokens, random bytes) mixed with good ones,
   plus slow clients trickling a body: each must get a 4xx with the JSON error shape, never a
   5xx, and good requests keep being answered.
5. **Access** (`--access`): the token matrix (no token, an unknown one, and tokens with read /
   localize / write on one map, on every map, on another map) x each right x two maps: every
   status must be what the token file says (200 / 201, 401, 403, 404).

Every loop is bounded in count and time; everything stays on loopback.
"""

from __future__ import annotations

import argparse
import contextlib
import http.client
import json
import os
import random
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
import urllib.request
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import psutil

from semloc.client import Client, ServerError
from semloc.eval.datasets import real_data_dir
from semloc.eval.variants import make_case, variant_maps
from semloc.io import map_from_dict, map_to_dict
from semloc.localizer import Localizer
from semloc.maps import ObjectMap
from semloc.sim.layouts import layout

TOKEN = "bench-token-0001"
MATRIX_TOKENS = {  # the token matrix's tokens (5. access) and their rights
    "matrix-reader-01": {"office": ["read"]},
    "matrix-localize-1": {"office": ["localize"], "*": ["read"]},
    "matrix-writer-01": {"office": ["read", "write"]},
    "matrix-other-map": {"lab": ["read", "localize", "write"]},
}


# the server ---------------------------------------------------------------------------------
class Server:
    """`semloc serve` in a subprocess with a token file; `url`, `kill()`, `stop()`."""

    def __init__(self, data: Path, workers: int = 1, db: str | None = None) -> None:
        tokens = data / "tokens.json"
        tokens.write_text(json.dumps({"tokens": [
            {"token": TOKEN, "maps": {"*": ["read", "localize", "write"]}},
            *({"token": token, "maps": maps} for token, maps in MATRIX_TOKENS.items())]}))  # fmt: skip
        command = [sys.executable, "-m", "semloc", "serve", "--data", str(data), "--port", "0",
                   "--workers", str(workers), "--tokens", str(tokens), "--rate", "0"]  # fmt: skip
        if db:
            command += ["--db", db]
        began = time.monotonic()
        self.process = subprocess.Popen(
            command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True
        )
        line = ""
        for _ in range(5):
            line = self.process.stderr.readline()
            if "listening on" in line or not line:
                break
        if "listening on" not in line:
            raise SystemExit(f"the server did not start: {line}{self.process.stderr.read()}")
        self.url = line.split("listening on ")[1].split()[0]
        threading.Thread(target=self.process.stderr.read, daemon=True).start()  # drain
        client = Client(self.url, TOKEN, timeout=5)
        deadline = time.monotonic() + 60
        while True:
            try:
                client.health()
                break
            except ServerError:
                if time.monotonic() > deadline:
                    raise SystemExit("the server did not answer in 60 s") from None
                time.sleep(0.02)
        self.startup_s = time.monotonic() - began

    def processes(self) -> list[psutil.Process]:
        try:
            parent = psutil.Process(self.process.pid)
            return [parent, *parent.children(recursive=True)]
        except psutil.NoSuchProcess:
            return []

    def cpu_seconds(self) -> float:
        total = 0.0
        for p in self.processes():
            try:
                times = p.cpu_times()
                total += times.user + times.system
            except psutil.NoSuchProcess:
                pass
        return total

    def rss_mb(self) -> float:
        total = 0
        for p in self.processes():
            with contextlib.suppress(psutil.NoSuchProcess):
                total += p.memory_info().rss
        return total / 2**20

    def kill(self) -> None:
        for p in reversed(self.processes()):
            with contextlib.suppress(psutil.NoSuchProcess):
                p.send_signal(signal.SIGKILL)
        self.process.wait(10)

    def stop(self) -> None:
        self.process.send_signal(signal.SIGTERM)
        try:
            self.process.wait(20)
        except subprocess.TimeoutExpired:
            self.kill()


# the views the devices stream ---------------------------------------------------------------
@dataclass
class View:
    """One device's walk: the map, the batches (one per keyframe) and the in-process answers."""

    map_id: str
    up: list[float] | None
    batches: list[list[dict]]
    expected: list[dict] = field(default_factory=list)  # status, pose, pairs per update


def maps_and_views(count: int, seed: int) -> tuple[dict[str, ObjectMap], list[View]]:
    data = real_data_dir()
    if data is not None:
        maps = variant_maps(data)
    else:
        print("real samples not found (set SEMLOC_DATA): simulated buildings instead")
        maps = {"building-a": layout(120, seed=1), "building-b": layout(120, seed=2)}
    maps = {name: map_from_dict(map_to_dict(m)) for name, m in maps.items()}  # as stored
    rng = np.random.default_rng(seed)
    views = []
    names = sorted(maps)
    for i in range(count):
        name = names[i % len(names)]
        case = make_case(maps[name], ("clean", "noisy")[i % 2], (3, 5, 8)[i % 3], rng)
        local = map_from_dict(map_to_dict(case.local))  # as sent
        by_keyframe: dict[int, list] = {}
        for obj in local:
            by_keyframe.setdefault(obj.seen, []).append(obj)
        batches = [
            map_to_dict(ObjectMap(objs))["objects"] for _, objs in sorted(by_keyframe.items())
        ]
        up = None if local.up is None else local.up.tolist()
        views.append(View(name, up, batches))
    for view in views:  # the in-process answers, outside the timed run
        localizer = Localizer(maps[view.map_id], local_up=view.up)
        for batch in view.batches:
            result = localizer.update(list(map_from_dict(
                {"format": "semloc-map", "version": 1, "objects": batch})))  # fmt: skip
            view.expected.append(_key(result.to_dict()))
    return maps, views


def _key(answer: dict) -> dict:
    return {"status": answer["status"], "pose": answer["pose"],
            "pairs": [[(p["global"], p["local"]) for p in h["pairs"]] for h in answer["hypotheses"]]}  # fmt: skip


def identical(answer: dict, expected: dict) -> bool:
    if answer["status"] != expected["status"] or _key(answer)["pairs"] != expected["pairs"]:
        return False
    if (answer["pose"] is None) != (expected["pose"] is None):
        return False
    return answer["pose"] is None or np.allclose(
        answer["pose"], expected["pose"], atol=1e-9, rtol=0
    )


# 1. load ------------------------------------------------------------------------------------
@dataclass
class LoadResult:
    devices: int
    latencies_ms: list[float]
    errors: int
    mismatches: int
    seconds: float
    server_cpu_s: float
    scrapes: list[float] = field(default_factory=list)  # ms each
    scrape_failures: int = 0
    counted_updates: float = float("nan")  # by the server's /metrics over the row

    def metrics_line(self) -> str:
        p99 = np.percentile(self.scrapes, 99) if self.scrapes else np.nan
        return (f"metrics ({self.devices} devices): {len(self.scrapes)} scrapes, p99 {p99:.1f} ms, "
                f"{self.scrape_failures} failed; session updates counted by /metrics "
                f"{self.counted_updates:.0f}, by the devices {len(self.latencies_ms)}")  # fmt: skip

    def row(self) -> list[str]:
        q = np.percentile(self.latencies_ms, [50, 95, 99]) if self.latencies_ms else [np.nan] * 3
        n = len(self.latencies_ms)
        return [str(self.devices), f"{n}", f"{q[0]:.1f}", f"{q[1]:.1f}", f"{q[2]:.1f}",
                f"{max(self.latencies_ms, default=np.nan):.1f}", str(self.errors),
                str(self.mismatches), f"{n / self.seconds:.1f}",
                f"{n / self.server_cpu_s:.1f}" if self.server_cpu_s else "-"]  # fmt: skip


def load(server: Server, views: list[View], devices: int, seconds: float, hz: float,
         seed: int) -> LoadResult:  # fmt: skip
    latencies: list[float] = []
    counters = {"errors": 0, "mismatches": 0}
    lock = threading.Lock()
    stop_at = time.monotonic() + seconds

    def device(index: int) -> None:
        rng = random.Random(seed * 1000 + index)
        client = Client(server.url, TOKEN, timeout=60)
        next_send = time.monotonic() + rng.uniform(0, 1 / hz)  # devices start out of step
        while time.monotonic() < stop_at:
            view = views[rng.randrange(len(views))]
            try:
                session = client.session(view.map_id, up=view.up)
            except ServerError:
                with lock:
                    counters["errors"] += 1
                continue
            for batch, expected in zip(view.batches, view.expected):
                time.sleep(max(0.0, next_send - time.monotonic()))
                next_send = max(next_send + 1 / hz, time.monotonic())
                if time.monotonic() >= stop_at:
                    break
                began = time.perf_counter()
                try:
                    answer = session.update(batch, stamp=time.time())
                except ServerError:
                    with lock:
                        counters["errors"] += 1
                    break
                took = (time.perf_counter() - began) * 1e3
                with lock:
                    latencies.append(took)
                    counters["mismatches"] += not identical(answer, expected)
            with contextlib.suppress(ServerError):
                session.close()

    threads = [threading.Thread(target=device, args=(i,), daemon=True) for i in range(devices)]
    scraper = Scraper(server.url)
    counted_before = scraper.updates()
    cpu_before, began = server.cpu_seconds(), time.monotonic()
    for thread in [*threads, scraper]:
        thread.start()
    for thread in threads:
        thread.join(seconds + 120)
    elapsed = time.monotonic() - began
    cpu = server.cpu_seconds() - cpu_before
    scraper.done.set()
    scraper.join(30)
    result = LoadResult(devices, latencies, counters["errors"], counters["mismatches"], elapsed,
                        cpu, scraper.took_ms, scraper.failures)  # fmt: skip
    result.counted_updates = scraper.updates() - counted_before
    return result


UPDATES = (
    'semloc_requests_total{method="POST",route="/v1/sessions/{session_id}/objects",status="200"}'
)


class Scraper(threading.Thread):
    """Scrapes `/metrics` every `every` seconds until `done` (a loopback client: no token)."""

    def __init__(self, url: str, every: float = 2.0) -> None:
        super().__init__(daemon=True)
        self.url, self.every = url, every
        self.done = threading.Event()
        self.took_ms: list[float] = []
        self.failures = 0

    def run(self) -> None:
        while not self.done.wait(self.every):
            began = time.perf_counter()
            try:
                self.scrape()
            except OSError:
                self.failures += 1
                continue
            self.took_ms.append((time.perf_counter() - began) * 1e3)

    def scrape(self) -> dict[str, float]:
        with urllib.request.urlopen(self.url + "/metrics", timeout=10) as response:
            text = response.read().decode()
        lines = [line.rsplit(" ", 1) for line in text.splitlines() if line and line[0] != "#"]
        return {name: float(value) for name, value in lines}

    def updates(self) -> float:
        """Successful session updates the server counted so far."""
        return self.scrape().get(UPDATES, 0.0)


# 2. soak ------------------------------------------------------------------------------------
def soak(server: Server, views: list[View], seconds: float, hz: float) -> list[float]:
    samples: list[float] = []
    done = threading.Event()

    def sample() -> None:
        while not done.wait(10.0):
            samples.append(server.rss_mb())

    sampler = threading.Thread(target=sample, daemon=True)
    samples.append(server.rss_mb())
    sampler.start()
    result = load(server, views, 32, seconds, hz, seed=99)
    done.set()
    samples.append(server.rss_mb())
    print(f"soak: {len(result.latencies_ms)} updates, {result.errors} errors, "
          f"{result.mismatches} answers differing from in-process")  # fmt: skip
    return samples


# 3. faults ----------------------------------------------------------------------------------
def faults(folder: Path, maps: dict[str, ObjectMap], kills: int, seed: int, db: str | None,
           startup_maps: int) -> None:  # fmt: skip
    rng = random.Random(seed)
    documents = [map_to_dict(m) for m in maps.values()]
    for i, document in enumerate(documents):
        document["name"] = f"doc{i}"
    acknowledged: dict[tuple[str, int], str] = {}
    reports = 0
    for _ in range(kills):
        server = Server(folder, db=db)
        stop = threading.Event()

        def upload(worker: int, server: Server = server, stop: threading.Event = stop) -> None:
            nonlocal reports
            client = Client(server.url, TOKEN, timeout=10)
            while not stop.is_set():
                document = documents[rng.randrange(len(documents))]
                try:
                    if worker == 0:
                        version, what = client.put_map("m0", document), document["name"]
                    else:  # change reports of a moved object
                        version, what = _report_changes(client, document, rng), "report"
                        reports += version is not None
                except ServerError:
                    return
                if version is not None:
                    acknowledged[(f"m{worker}", version)] = what

        threads = [threading.Thread(target=upload, args=(w,)) for w in range(2)]
        for thread in threads:
            thread.start()
        time.sleep(rng.uniform(0.1, 1.0))
        server.kill()
        stop.set()
        for thread in threads:
            thread.join(20)
    server = Server(folder, db=db)
    client = Client(server.url, TOKEN)
    names = {d["name"]: d for d in documents}
    lost = half = 0
    for (map_id, version), name in acknowledged.items():
        try:
            stored = client.request("GET", f"/v1/maps/{map_id}?version={version}")
        except ServerError:
            lost += 1
            continue
        if name != "report" and (stored.get("name") != name or
                                 len(stored["objects"]) != len(names[name]["objects"])):  # fmt: skip
            half += 1
    for map_id in ("m0", "m1"):
        try:
            versions = [v["version"] for v in client.versions(map_id)]
        except ServerError:
            continue
        if versions != list(range(1, len(versions) + 1)):
            half += 1
    print(f"faults: {kills} kills (-9), {len(acknowledged)} acknowledged writes "
          f"({reports} change reports): {lost} lost, {half} not whole")  # fmt: skip
    for i in range(startup_maps):
        client.put_map(f"startup-{i:03d}", documents[i % len(documents)])
    server.kill()  # a crash, then a start over the store with every map
    restarted = Server(folder, db=db)
    print(
        f"start-up after a crash with {len(Client(restarted.url, TOKEN).maps())} maps: {restarted.startup_s:.2f} s "
        "(process start to the first answer)"
    )
    restarted.stop()


def _report_changes(client: Client, document: dict, rng: random.Random) -> int | None:
    """Move one object of m1's latest version by 1 m and report it as a localization would."""
    try:
        current = client.request("GET", "/v1/maps/m1")
    except ServerError as exc:
        if exc.status == 404:
            return client.put_map("m1", document)
        raise
    versions = client.versions("m1")
    objects = current["objects"]
    moved = dict(objects[rng.randrange(len(objects))])
    moved["position"] = [moved["position"][0] + 1.0, *moved["position"][1:]]
    local = {"format": "semloc-map", "version": 1,
             "objects": [dict(o) for o in objects if o["id"] != moved["id"]] + [moved]}  # fmt: skip
    pose = np.eye(4).tolist()
    pairs = [{"global": o["id"], "local": o["id"]} for o in objects[:3] if o["id"] != moved["id"]]
    answer = {"status": "localized", "pose": pose, "map_version": versions[-1]["version"],
              "hypotheses": [{"pairs": pairs}]}  # fmt: skip
    try:
        return client.report_changes("m1", answer, local=local)["version"]
    except ServerError as exc:
        if exc.status in (409, 422):
            return None
        raise


# 4. bad input -------------------------------------------------------------------------------
def fuzz(server: Server, maps: dict[str, ObjectMap], requests: int, seed: int) -> None:
    rng = random.Random(seed)
    good_map = map_to_dict(next(iter(maps.values())))
    good = json.dumps(good_map).encode()
    client = Client(server.url, TOKEN)
    client.put_map("fuzz", good_map)
    session = client.session("fuzz")
    host, port = server.url.removeprefix("http://").rsplit(":", 1)
    statuses: dict[int, int] = {}
    shapes_wrong = 0

    def mutate() -> tuple[str, str, bytes, str | None]:
        kind = rng.randrange(10)
        body = good
        if kind == 0:
            body = good[: rng.randrange(len(good))]
        elif kind == 1:
            body = bytes(rng.randrange(256) for _ in range(rng.randrange(1, 400)))
        elif kind == 2:
            body = good.replace(b"0.", b"NaN", 1)
        elif kind == 3:
            body = json.dumps(
                {**good_map, "objects": rng.choice([7, "x", [1], [{}], None])}
            ).encode()
        elif kind == 4:
            obj = dict(good_map["objects"][0])
            obj[rng.choice(["position", "id", "label", "size", "points"])] = rng.choice(
                [None, [], "x", [1e308, 0, 0], [[1, 2]], -1, {"a": 1}])  # fmt: skip
            body = json.dumps({**good_map, "objects": [obj]}).encode()
        elif kind == 5:
            body = b"[" * rng.randrange(1000, 50_000)
        target = rng.choice([
            ("PUT", "/v1/maps/fuzz"), ("POST", "/v1/maps/fuzz/localize"),
            ("POST", f"/v1/sessions/{session.session_id}/objects"), ("POST", "/v1/maps/fuzz/changes"),
            ("POST", "/v1/maps/unknown/localize"), ("POST", "/v1/sessions/unknown/objects"),
        ])  # fmt: skip
        token = rng.choice([TOKEN, TOKEN, TOKEN, None, "wrong-token-123"]) if kind >= 6 else TOKEN
        if kind == 6:
            body = json.dumps({"objects": [good_map["objects"][0]], "stamp": rng.choice(
                [1.0, "x", None, 1e400])}).encode() if rng.random() < 0.5 else good  # fmt: skip
        return target[0], target[1], body, token

    def slow_client() -> None:  # trickles a body, one byte at a time, then gives up
        with socket.create_connection((host, int(port)), timeout=10) as sock:
            sock.sendall(b"PUT /v1/maps/slow HTTP/1.1\r\nHost: x\r\nContent-Length: 100000\r\n"
                         + f"Authorization: Bearer {TOKEN}\r\n\r\n".encode())  # fmt: skip
            for _ in range(20):
                sock.sendall(b" ")
                time.sleep(0.1)

    slow = [threading.Thread(target=slow_client, daemon=True) for _ in range(8)]
    for thread in slow:
        thread.start()
    began = time.monotonic()
    for _ in range(requests):
        method, path, body, token = mutate()
        try:
            answer = Client(server.url, token, timeout=30).request(method, path, json.loads(body))
            status = 200 if answer is not None else 204
        except (ValueError, RecursionError, UnicodeDecodeError):
            status, ok = _raw(server.url, method, path, body, token)
            shapes_wrong += not ok
        except ServerError as exc:
            status = exc.status
            shapes_wrong += not exc.error
        statuses[status] = statuses.get(status, 0) + 1
        if time.monotonic() - began > 600:
            break
    for thread in slow:
        thread.join(5)
    five = sum(n for s, n in statuses.items() if s >= 500)
    print(f"bad input: {sum(statuses.values())} requests, statuses "
          f"{dict(sorted(statuses.items()))}; 5xx: {five}; 4xx without the error shape: "
          f"{shapes_wrong}; health after: {client.health()['status']}")  # fmt: skip


def _raw(url: str, method: str, path: str, body: bytes, token: str | None) -> tuple[int, bool]:
    """(status, whether the answer has the error shape) of a request the client cannot encode;
    a server that answers before reading the whole body (401, 413) is read all the same."""
    host, port = url.removeprefix("http://").rsplit(":", 1)
    connection = http.client.HTTPConnection(host, int(port), timeout=30)
    headers = {"Content-Type": "application/json"}
    if token:
        headers["Authorization"] = f"Bearer {token}"
    try:
        # answered early and closed: its answer may still be read
        with contextlib.suppress(BrokenPipeError, ConnectionResetError):
            connection.request(method, path, body, headers)
        response = connection.getresponse()
        data = response.read()
    except (ConnectionError, http.client.HTTPException):
        return 0, False
    finally:
        connection.close()
    if response.status < 400:
        return response.status, True
    try:
        return response.status, set(json.loads(data)) == {"error", "detail"}
    except ValueError:
        return response.status, False


# 5. access ---------------------------------------------------------------------------------
def access_matrix(server: Server, maps: dict[str, ObjectMap]) -> None:
    """Every token (none, unknown, each of MATRIX_TOKENS) x every right x a map it may and may
    not see: the status each gets, against what the token file says it must be."""
    document = map_to_dict(next(iter(maps.values())))
    admin = Client(server.url, TOKEN)
    for map_id in ("office", "lab"):
        admin.put_map(map_id, document)
    body = json.dumps(document).encode()
    requests = {"read": ("GET", "/v1/maps/{m}", None), "versions": ("GET", "/v1/maps/{m}/versions", None),
                "localize": ("POST", "/v1/maps/{m}/localize", body),
                "session": ("POST", "/v1/maps/{m}/sessions", None),
                "write": ("PUT", "/v1/maps/{m}", body)}  # fmt: skip
    right_of = {"read": "read", "versions": "read", "localize": "localize",
                "session": "localize", "write": "write"}  # fmt: skip
    success = {"read": 200, "versions": 200, "localize": 200, "session": 201, "write": 201}
    checked = wrong = 0
    tokens = [None, "not-a-known-token", *MATRIX_TOKENS]
    for token in tokens:
        for map_id in ("office", "lab"):
            rights = set()
            if token in MATRIX_TOKENS:
                grants = MATRIX_TOKENS[token]
                rights = set(grants.get(map_id, [])) | set(grants.get("*", []))
            for what, (method, path, payload) in requests.items():
                if token not in MATRIX_TOKENS:
                    expected = 401
                elif not rights:
                    expected = 404
                else:
                    expected = success[what] if right_of[what] in rights else 403
                got, shaped = _raw(server.url, method, path.format(m=map_id), payload or b"", token)
                checked += 1
                wrong += got != expected or (got >= 400 and not shaped)
    print(
        f"access: {checked} requests ({len(tokens)} tokens x 2 maps x 5 requests), {wrong} with a status "
        "other than the token file's or without the error shape"
    )


# the report ---------------------------------------------------------------------------------
HEADER = ["devices", "updates", "p50 ms", "p95 ms", "p99 ms", "max ms", "errors",
          "differing answers", "updates/s", "updates per server CPU-s"]  # fmt: skip


def table(rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(HEADER) + " |", "|" + "---|" * len(HEADER)]
    return "\n".join(lines + ["| " + " | ".join(r) + " |" for r in rows])


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--devices", type=int, nargs="+", default=[8, 32, 128])
    parser.add_argument("--seconds", type=float, default=30.0)
    parser.add_argument("--hz", type=float, default=1.0, help="updates a second per device")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--db", default=None, help="a postgresql:// store instead of SQLite")
    parser.add_argument("--views", type=int, default=60)
    parser.add_argument("--soak", type=float, default=0.0, help="seconds (0: no soak)")
    parser.add_argument("--faults", type=int, default=0, help="kills (0: none)")
    parser.add_argument("--fuzz", type=int, default=0, help="bad requests (0: none)")
    parser.add_argument("--access", action="store_true", help="the token matrix")
    parser.add_argument("--startup-maps", type=int, default=100)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--markdown", type=Path, default=None)
    args = parser.parse_args(argv)
    maps, views = maps_and_views(args.views, args.seed)
    print(f"{len(views)} views over {', '.join(maps)}; {os.cpu_count()} cores; "
          f"server: {args.workers} worker(s), {'PostgreSQL' if args.db else 'SQLite'}")  # fmt: skip
    with tempfile.TemporaryDirectory(prefix="semloc-bench-serve-") as folder:
        server = Server(Path(folder), args.workers, args.db)
        client = Client(server.url, TOKEN)
        for name, objmap in maps.items():
            client.put_map(name, objmap)
        rows = []
        for devices in args.devices:
            result = load(server, views, devices, args.seconds, args.hz, args.seed)
            rows.append(result.row())
            print(table(rows[-1:]).splitlines()[-1], flush=True)
            print(result.metrics_line(), flush=True)
        text = table(rows)
        print(f"\nLoad: {args.hz:g} update/s per device, {args.seconds:g} s per row\n\n{text}")
        if args.markdown:
            args.markdown.write_text(text + "\n")
        if args.soak:
            samples = soak(server, views, args.soak, args.hz)
            print(
                f"soak memory (MB, all server processes): first {samples[0]:.0f}, last "
                f"{samples[-1]:.0f}, largest {max(samples):.0f} ({len(samples)} samples)"
            )
        if args.fuzz:
            fuzz(server, maps, args.fuzz, args.seed)
        if args.access:
            access_matrix(server, maps)
        server.stop()
    if args.faults:
        with tempfile.TemporaryDirectory(prefix="semloc-bench-faults-") as folder:
            faults(Path(folder), maps, args.faults, args.seed, args.db, args.startup_maps)


if __name__ == "__main__":
    main()
