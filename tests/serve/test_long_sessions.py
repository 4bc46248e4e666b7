"""Long sessions: bounded answers and store, positions, and a rebuild on another worker that
answers as the uninterrupted session."""

from __future__ import annotations

import sqlite3

import pytest
from test_api import raw, same_answer

import semloc
from semloc.client import Client
from semloc.io import map_from_dict, map_to_dict
from semloc.maps import ObjectMap
from semloc.serve.store import open_store
from semloc.sim.layouts import layout
from semloc.sim.longwalk import LongWalk, WalkConfig


@pytest.fixture(scope="module")
def walk():
    building = layout(160, seed=5)
    frames = list(LongWalk(building, WalkConfig(keyframes=70, points_per_object=0), seed=3))
    return building, frames


def batches_kept(folder, session_id: str) -> int:
    with sqlite3.connect(folder / "semloc.sqlite3") as db:
        query = "SELECT COUNT(*) FROM session_batches WHERE session_id = ?"
        return db.execute(query, (session_id,)).fetchone()[0]


def test_a_long_session_is_rebuilt_by_another_worker_as_it_was(serve, walk, tmp_path):
    building, frames = walk
    store = tmp_path / "shared"
    first, second = serve(store=open_store(store)), serve(store=open_store(store))
    Client(first.url).put_map("building", building)
    session = Client(first.url).session("building", up=[0, 0, 1])
    served_map = map_from_dict(map_to_dict(building))  # the map as the server reads it
    reference = semloc.Localizer(served_map, local_up=[0, 0, 1])
    clients = [Client(first.url), Client(second.url)]
    sizes, statuses = [], []
    for k, frame in enumerate(frames):
        if k >= 30:
            session.client = clients[(k // 3) % 2]  # 3 updates on one worker, 3 on the other
        at = frame.T_odom_robot[:3, 3]
        served = session.update(frame.objects, stamp=k, position=at)
        sent = list(map_from_dict(map_to_dict(ObjectMap(frame.objects))))  # as the server reads
        same_answer(served, reference.update(sent, position=at))
        assert len(served["steps"]) <= 10
        sizes.append(len(served["steps"]))
        statuses.append(served["status"])
    assert statuses.count("localized") > 40 and reference.tracking
    kept = batches_kept(store, session.session_id)
    assert kept < len(frames) / 2 and kept <= len(reference.local_map) + 1, kept


def test_a_position_must_be_three_finite_numbers(serve, walk):
    building, _ = walk
    client = Client(serve().url)
    client.put_map("building", building)
    session = client.session("building")
    path = f"/v1/sessions/{session.session_id}/objects"
    for position in (b"[1, 2]", b'"here"', b"[1, 2, true]"):
        status, _ = raw(client.url, "POST", path, b'{"objects": [], "position": ' + position + b"}")
        assert status == 422
    answer = session.update([], position=[1.0, 2.0, 0.0])
    assert answer["status"] == "failed" and answer["support"] is None
