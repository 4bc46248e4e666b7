"""The live view with Foxglove's own client library, `@foxglove/ws-protocol` (npm, run by
Node.js; `make interop-deps` installs it into tests/interop/node): both names of the protocol
accepted, every channel decoded with the schema it advertises, and a viewer that joins late
gets the latest message of every channel, contents included.

A viewer joins after the answers were published (a late joiner) and prints what it decodes
(`node/client.js`, `foxglove_viewer.py`); the assertions compare it with what the answers
say.  `live_view.py` draws docs/img/live_view.png from the same decoded messages."""

from __future__ import annotations

import shutil

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

pytest.importorskip("foxglove", reason="foxglove-sdk (the viz extra) is not installed")
pytest.importorskip("websockets", reason="websockets (the viz extra) is not installed")

from foxglove_viewer import LIBRARY, viewer, walk_answers  # noqa: E402

from semloc.pictures.foxglove_ws import SUBPROTOCOLS  # noqa: E402
from semloc.pictures.live import TOPICS, FoxgloveView  # noqa: E402
from semloc.pictures.looks import look_arrows  # noqa: E402

if shutil.which("node") is None:
    pytest.skip("Node.js is not installed (make system-deps)", allow_module_level=True)
if not LIBRARY.is_dir():
    pytest.skip(
        "@foxglove/ws-protocol is not installed (make interop-deps)", allow_module_level=True
    )


@pytest.fixture(scope="module")
def run():
    """A walk's answers: ambiguous ones with next-look suggestions, then localized ones."""
    return walk_answers()


def xyz(vector: dict) -> list[float]:
    return [vector["x"], vector["y"], vector["z"]]


@pytest.mark.parametrize("subprotocol", SUBPROTOCOLS)
def test_a_late_foxglove_client_decodes_the_latest_of_every_channel(run, subprotocol):
    building, answers = run
    view = FoxgloveView(building, port=0)
    try:
        for answer in answers:
            view.update(*answer)
        _, result, local, T_odom_sensor = answers[-1]
        assert result.status == "localized"
        opened, channels, got = viewer(view.port, subprotocol, list(TOPICS))
    finally:
        view.close()
    assert opened == subprotocol
    assert {t: c["schemaName"] for t, c in channels.items()} == {
        t: f"foxglove.{name}" for t, name in TOPICS.items()
    }
    assert {t: m["schemaName"] for t, m in got.items()} == {
        t: c["schemaName"] for t, c in channels.items()
    }
    msg = {topic: line["message"] for topic, line in got.items()}
    entities = msg["/semloc/map"]["entities"]
    assert sorted(e["id"] for e in entities) == sorted(f"map/{o.id}" for o in building)
    assert {e["texts"][0]["text"] for e in entities} == set(building.labels)
    by_id = {e["id"]: e for e in msg["/semloc/local"]["entities"]}
    assert set(by_id) == {"local", "missing"}  # (missing: none without coverage)
    placed = by_id["local"]
    assert not by_id["missing"].get("cubes")
    assert len(placed["spheres"]) == len(local) and placed["frame_id"] == "map"
    ranks = [e["id"] for e in msg["/semloc/hypotheses"]["entities"]]
    assert ranks[0] == "hypothesis/1" and not [r for r in ranks if r.startswith("next_look")]
    tf = msg["/tf"]
    assert (tf["parent_frame_id"], tf["child_frame_id"]) == ("map", "odom")
    assert np.allclose(xyz(tf["translation"]), result.pose[:3, 3])
    pose = msg["/semloc/pose"]
    assert pose["frame_id"] == "map"
    assert np.allclose(xyz(pose["pose"]["position"]), (result.pose @ T_odom_sensor)[:3, 3])
    assert msg["/semloc/status"]["level"] == "INFO"
    assert msg["/semloc/status"]["message"].startswith("localized")


def test_a_late_foxglove_client_sees_where_to_look_next(run, tmp_path):
    building, answers = run
    ambiguous = [a for a in answers if a[1].next_look]
    view = FoxgloveView(building, port=0)
    try:
        for answer in answers[: answers.index(ambiguous[-1]) + 1]:
            view.update(*answer)
        _, result, _, T_odom_sensor = ambiguous[-1]
        topics = ["/semloc/map", "/semloc/local", "/semloc/hypotheses", "/semloc/status"]
        _, _, got = viewer(view.port, "foxglove.websocket.v1", topics)
    finally:
        view.close()
    arrows = look_arrows(result, T_odom_sensor)
    assert arrows
    drawn = {e["id"]: e for e in got["/semloc/hypotheses"]["message"]["entities"]}
    for order in range(1, len(result.next_look) + 1):
        entity = drawn[f"next_look/{order}"]
        mine = [a for a in arrows if a.order == order]
        assert entity["frame_id"] == "map"
        assert [t["text"] for t in entity["texts"]] == [a.text for a in mine]
        assert len(entity["arrows"]) == len(mine)
        for shaft, arrow in zip(entity["arrows"], mine, strict=True):
            assert np.allclose(xyz(shaft["pose"]["position"]), arrow.start)
            q = shaft["pose"]["orientation"]  # Foxglove's arrows point along their pose's +x
            along = Rotation.from_quat([q["x"], q["y"], q["z"], q["w"]]).apply([1.0, 0.0, 0.0])
            length = shaft["shaft_length"] + shaft["head_length"]
            assert np.allclose(arrow.start + length * along, arrow.end, atol=1e-5)
    status = got["/semloc/status"]["message"]
    assert status["level"] == "WARNING" and status["message"].startswith("ambiguous")
    assert (
        f"look at {result.next_look[0].label} {result.next_look[0].global_id}" in status["message"]
    )
    # the picture of docs/img/live_view.png draws the same decoded messages
    pytest.importorskip("matplotlib", reason="matplotlib (the viz extra) is not installed")
    from live_view import render

    render([("ambiguous", got)], tmp_path / "view.png")
    assert (tmp_path / "view.png").read_bytes().startswith(b"\x89PNG")
