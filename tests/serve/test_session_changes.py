"""A session's run report posted as a map version proposal: `POST /v1/maps/{id}/changes` with
the `session_id` of a session that tracks its place applies the report the server accumulated
over the walk (a moved object seen twice is moved), not a one-shot recomputation (which, from
centres only, would read the moved object as new); a single sighting changes nothing."""

from __future__ import annotations

import numpy as np
import pytest

from semloc.client import Client
from semloc.io import map_from_dict, map_to_dict
from semloc.maps import ObjectMap, SemanticObject

LABELS = ["chair", "table", "lamp", "sofa", "shelf", "plant", "bin", "desk", "tv", "bed"]
MOVE = np.array([2.0, 0.0, 0.0])


@pytest.fixture
def room() -> ObjectMap:
    """Ten objects of ten labels on a 6 x 4 m floor (as the server stores them)."""
    rng = np.random.default_rng(4)
    xy = rng.uniform([0, 0], [6, 4], (10, 2))
    objects = [SemanticObject(f"a{i}", LABELS[i], [xy[i, 0], xy[i, 1], 0.5], size=[0.5, 0.5, 1.0])
               for i in range(10)]  # fmt: skip
    return map_from_dict(map_to_dict(ObjectMap(objects, up=[0, 0, 1])))


def walked(client: Client, room: ObjectMap, sightings: int):
    """A session that claims the room (the local frame is the map's) on its objects but the
    lamp, then sees the lamp 2 m from its place `sightings` times: the session and its latest
    answer.  (A lamp seen at its place as well would be a second lamp, not a moved one.)"""
    session = client.session("room", up=[0, 0, 1])
    local = [o.replace(id=f"l{o.id}", size=None) for o in room if o.id != "a2"]
    session.update(local[:5])
    assert session.update(local[5:])["status"] == "localized"
    lamp = room.get("a2")
    moved = SemanticObject("moved-lamp", "lamp", lamp.position + MOVE)
    answer = None
    for _ in range(sightings):
        answer = session.update([moved])
    assert answer is not None and answer["status"] == "localized"
    assert answer["support"]["tracked"]
    return session, answer


def test_a_tracking_session_s_run_report_moves_the_object_seen_moved_twice(serve, room):
    client = Client(serve().url)
    client.put_map("room", room)
    session, answer = walked(client, room, sightings=2)
    assert [(m["global"], m["local"], m["evidence"]) for m in answer["changes"]["moved"]] == [
        ("a2", "moved-lamp", 2)
    ]
    done = client.report_changes("room", answer, session_id=session.session_id)
    assert done == {"version": 2, "changed": True}
    after = client.get_map("room")
    np.testing.assert_allclose(after.get("a2").position, room.get("a2").position + MOVE, atol=1e-6)
    assert after.get("a2").extra["moved_m"] == pytest.approx(2.0, abs=0.05)
    assert len(after) == len(room)  # moved, not added as a new object
    others = [o for o in room if o.id != "a2"]
    np.testing.assert_allclose([after.get(o.id).position for o in others],
                               [o.position for o in others], atol=1e-6)  # fmt: skip
    assert client.versions("room")[-1]["source"] == "changes (from version 1)"


def test_a_single_sighting_is_no_change_of_the_run(serve, room):
    client = Client(serve().url)
    client.put_map("room", room)
    session, answer = walked(client, room, sightings=1)
    assert answer["changes"]["moved"] == [] and answer["changes"]["new"] == []
    done = client.report_changes("room", answer, session_id=session.session_id)
    assert done == {"version": 1, "changed": False}
    np.testing.assert_allclose(client.get_map("room").get("a2").position, room.get("a2").position)


def test_the_body_cannot_stand_in_for_the_server_s_run_report(serve, room):
    """A report's own `changes` (or a `run_changes` key) are not trusted: the server's record
    of the session's answer is what applies."""
    client = Client(serve().url)
    client.put_map("room", room)
    session, answer = walked(client, room, sightings=1)
    forged = {"moved": [{"global": "a5", "local": "moved-lamp", "offset_m": 3.0}], "new": [],
              "missing": []}  # fmt: skip
    body = {**answer, "changes": forged, "run_changes": forged}
    done = client.report_changes("room", body, session_id=session.session_id)
    assert done == {"version": 1, "changed": False}
