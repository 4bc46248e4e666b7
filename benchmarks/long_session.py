"""A long service session: 10,000 updates of a robot's walk through `semloc serve`.

    PYTHONPATH=src python benchmarks/long_session.py [--updates 10000] [--rebuilds 5] [--seed 0]

Two `semloc serve` processes over one store (SQLite in a temporary folder, loopback ports)
hold a generated building of 600 objects (points on the box faces).  One device streams a walk
(`semloc.sim.longwalk.LongWalk`: 0.5 m per update, drifting odometry, new objects with their
visible points plus two re-detections per update, the odometry position with each update)
through a session on the first server.  At `--rebuilds` moments spread over the run one
update goes to the second server instead, which does not hold the session and rebuilds it
from the store (the first server then rebuilds it again at its next update).  Every answer
is compared with an in-process `Localizer` fed the same batches: status, pose (1e-9), pairs.

Printed: median latency and answer size of the first and last 100 updates, the rebuilds'
latencies (the update that rebuilt the session), the answers that differ, and the batches the
store keeps for the session at the end.
"""

from __future__ import annotations

import argparse
import json
import sqlite3
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_serve import TOKEN, Server, _key, identical  # noqa: E402

from semloc.client import Client  # noqa: E402
from semloc.io import map_from_dict, map_to_dict  # noqa: E402
from semloc.localizer import Localizer  # noqa: E402
from semloc.maps import ObjectMap  # noqa: E402
from semloc.sim.layouts import layout  # noqa: E402
from semloc.sim.longwalk import LongWalk, WalkConfig  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--updates", type=int, default=10_000)
    parser.add_argument("--rebuilds", type=int, default=5)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    building = layout(600, seed=args.seed, points_per_object=120)
    walk = LongWalk(building, WalkConfig(keyframes=args.updates, points_per_object=60), args.seed)
    rebuild_at = set(np.linspace(args.updates * 0.2, args.updates - 50, args.rebuilds).astype(int))
    with tempfile.TemporaryDirectory() as folder:
        data = Path(folder)
        first, second = Server(data), Server(data)
        try:
            rows = run(first, second, building, walk, rebuild_at)
            kept = _kept_batches(data)
        finally:
            first.stop()
            second.stop()
    latency, size, differ, rebuilds = rows
    print(f"| updates | latency ms, first 100 / last 100 (median) | answer kB, first 100 / last 100 "
          f"| rebuilds on the other worker, ms | answers differing from in-process | batches kept |\n"
          f"|---:|---|---|---|---:|---:|\n"
          f"| {len(latency)} | {np.median(latency[:100]):.1f} / {np.median(latency[-100:]):.1f} | "
          f"{np.median(size[:100]) / 1e3:.1f} / {np.median(size[-100:]) / 1e3:.1f} | "
          f"{', '.join(f'{ms:.0f}' for ms in rebuilds)} | {differ} | {kept} |")  # fmt: skip
    return 0


def run(first: Server, second: Server, building: ObjectMap, walk: LongWalk, rebuild_at: set[int]):
    clients = Client(first.url, TOKEN, timeout=60), Client(second.url, TOKEN, timeout=60)
    clients[0].put_map("building", building)
    reference = Localizer(map_from_dict(map_to_dict(building)), local_up=[0, 0, 1])
    session = clients[0].session("building", up=[0, 0, 1])
    latency, size, rebuilds, differ = [], [], [], 0
    for k, frame in enumerate(walk):
        session.client = clients[1] if k in rebuild_at else clients[0]
        at = frame.T_odom_robot[:3, 3].tolist()
        documents = map_to_dict(ObjectMap(frame.objects))["objects"]
        start = time.perf_counter()
        served = session.update(documents, stamp=float(k), position=at)
        ms = (time.perf_counter() - start) * 1e3
        latency.append(ms)
        size.append(len(json.dumps(served)))
        if k in rebuild_at:
            rebuilds.append(ms)
        sent = list(map_from_dict({"format": "semloc-map", "version": 1, "objects": documents}))
        expected = reference.update(sent, position=at)
        differ += not identical(served, _key(expected.to_dict()))
        if k % 1000 == 999:
            print(f"{k + 1} updates, {np.median(latency[-100:]):.1f} ms", file=sys.stderr)
    return latency, size, differ, rebuilds


def _kept_batches(data: Path) -> int:
    with sqlite3.connect(data / "semloc.sqlite3") as db:
        return int(db.execute("SELECT COUNT(*) FROM session_batches").fetchone()[0])


if __name__ == "__main__":
    raise SystemExit(main())
