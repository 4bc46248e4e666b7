"""The live Foxglove view: a WebSocket server that speaks both names of Foxglove's protocol,
advertises semloc's channels in Foxglove's schemas, gives a viewer that joins at any time the
latest message of every channel, and draws an ambiguous answer's next look.  (Foxglove's own
client library decodes every message in tests/interop.)"""

from __future__ import annotations

import base64
import json
import os
import signal
import struct
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np
import pytest

pytest.importorskip("foxglove", reason="foxglove-sdk (the viz extra) is not installed")
pytest.importorskip("websockets", reason="websockets (the viz extra) is not installed")

import foxglove.messages  # noqa: E402
from websockets.exceptions import InvalidStatus  # noqa: E402
from websockets.sync.client import ClientConnection, connect  # noqa: E402

import semloc  # noqa: E402
from semloc.pictures.foxglove_ws import SUBPROTOCOLS, FoxgloveServer  # noqa: E402
from semloc.pictures.live import TOPICS, FoxgloveView  # noqa: E402
from semloc.pictures.looks import look_arrows  # noqa: E402
from semloc.sim.layouts import layout  # noqa: E402
from semloc.sim.longwalk import LongWalk, WalkConfig  # noqa: E402

WAIT = 20.0
"""Bound (s) of every wait for the server; a healthy run needs far less."""


@pytest.fixture(scope="module")
def run():
    """A walk's answers: failed, ambiguous (with next-look suggestions), then localized."""
    building = layout(60, seed=2)
    localizer = semloc.Localizer(building, local_up=[0, 0, 1])
    answers = []
    for k, frame in enumerate(LongWalk(building, WalkConfig(keyframes=25, points_per_object=0), seed=2)):  # fmt: skip
        result = localizer.update(frame.objects, position=frame.T_odom_robot)
        answers.append((k, result, localizer.local_map, frame.T_odom_robot))
    statuses = {a[1].status for a in answers}
    assert {"ambiguous", "localized"} <= statuses
    assert any(a[1].next_look for a in answers)
    return building, answers


@contextmanager
def opened(port: int, subprotocol: str) -> Iterator[tuple[ClientConnection, dict, dict[int, dict]]]:
    """A client of the view: its connection, the server's info and the advertised channels."""
    with connect(f"ws://127.0.0.1:{port}", subprotocols=[subprotocol], open_timeout=WAIT) as ws:
        info, advertise = json.loads(ws.recv(WAIT)), json.loads(ws.recv(WAIT))
        assert info["op"] == "serverInfo" and advertise["op"] == "advertise"
        yield ws, info, {c["id"]: c for c in advertise["channels"]}


def subscribe_all(ws: ClientConnection, channels: dict[int, dict]) -> dict[int, str]:
    """Subscribe to every channel (subscription id = 100 + channel id); subscription -> topic."""
    subs = [{"id": 100 + cid, "channelId": cid} for cid in channels]
    ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
    return {100 + cid: c["topic"] for cid, c in channels.items()}


def messages(ws: ClientConnection, topics: dict[int, str], count: int) -> list[tuple[str, bytes]]:
    """The next `count` messages (topic, payload)."""
    found = []
    while len(found) < count:
        frame = ws.recv(WAIT)
        assert isinstance(frame, bytes), frame
        opcode, sid, _ = struct.unpack_from("<BIQ", frame)
        assert opcode == 1
        found.append((topics[sid], frame[13:]))
    return found


def test_both_names_of_the_protocol_are_accepted_and_the_channels_advertised(run):
    building, _ = run
    view = FoxgloveView(building, port=0)
    try:
        for subprotocol in SUBPROTOCOLS:
            with opened(view.port, subprotocol) as (ws, info, channels):
                assert ws.subprotocol == subprotocol and info["name"] == "semloc"
                assert {c["topic"]: c["schemaName"] for c in channels.values()} == {
                    topic: f"foxglove.{name}" for topic, name in TOPICS.items()
                }
                for c in channels.values():
                    schema = getattr(foxglove.messages, c["schemaName"].split(".")[1]).get_schema()
                    assert c["encoding"] == c["schemaEncoding"] == "protobuf"
                    assert base64.b64decode(c["schema"]) == schema.data
        with pytest.raises(InvalidStatus) as refused:
            connect(f"ws://127.0.0.1:{view.port}", subprotocols=["another.v1"], open_timeout=WAIT)
        assert refused.value.response.status_code == 400
    finally:
        view.close()


def test_a_viewer_that_joins_after_the_run_gets_the_latest_of_every_channel(run):
    building, answers = run
    view = FoxgloveView(building, port=0)
    try:
        for answer in answers:
            view.update(*answer)
        last = answers[-1][1]
        assert last.status == "localized"
        for subprotocol in SUBPROTOCOLS:
            with opened(view.port, subprotocol) as (ws, _, channels):
                got = dict(messages(ws, subscribe_all(ws, channels), len(TOPICS)))
                assert set(got) == set(TOPICS)
                assert b"localized" in got["/semloc/status"]
                assert b"map" in got["/tf"] and b"odom" in got["/tf"]
                assert got["/semloc/map"].count(b"map/") == len(building)
                assert b"next_look/" not in got["/semloc/hypotheses"]  # the answer is localized
    finally:
        view.close()


def test_a_subscriber_gets_each_new_answer_and_none_after_unsubscribing(run):
    building, answers = run
    view = FoxgloveView(building, port=0)
    try:
        with opened(view.port, "foxglove.websocket.v1") as (ws, _, channels):
            status = next(cid for cid, c in channels.items() if c["topic"] == "/semloc/status")
            topics = subscribe_all(ws, {status: channels[status]})
            ambiguous = next(a for a in answers if a[1].next_look)
            view.update(*ambiguous)
            ((topic, payload),) = messages(ws, topics, 1)
            assert topic == "/semloc/status" and b"ambiguous" in payload
            assert f"look at {ambiguous[1].next_look[0].label}".encode() in payload
            ws.send(json.dumps({"op": "unsubscribe", "subscriptionIds": [100 + status]}))
            ws.send(json.dumps({"op": "fetchAsset", "uri": "x", "requestId": 1}))
            reply = json.loads(ws.recv(WAIT))  # in order: the unsubscribe was taken before it
            assert reply["op"] == "status" and "fetchAsset" in reply["message"]
            view.update(*answers[-1])  # no subscriber of /semloc/status now
            subs = [{"id": 7, "channelId": status}]
            ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
            ((topic, payload),) = messages(ws, {7: "/semloc/status"}, 1)  # not subscription 100+
            assert b"localized" in payload
    finally:
        view.close()


def test_a_channel_added_later_is_advertised_to_connected_clients():
    server = FoxgloveServer(port=0)
    try:
        with connect(f"ws://127.0.0.1:{server.port}", subprotocols=["foxglove.sdk.v1"]) as ws:
            assert json.loads(ws.recv(WAIT))["op"] == "serverInfo"
            assert json.loads(ws.recv(WAIT))["channels"] == []
            cid = server.add_channel("/later", "Later", b'{"type": "object"}', encoding="json",
                                     schema_encoding="jsonschema")  # fmt: skip
            (channel,) = json.loads(ws.recv(WAIT))["channels"]
        assert channel == {"id": cid, "topic": "/later", "encoding": "json", "schemaName": "Later",
                           "schema": '{"type": "object"}', "schemaEncoding": "jsonschema"}  # fmt: skip
    finally:
        server.close()


def test_the_next_look_is_drawn_for_each_rank_it_separates(run):
    from semloc.ros.answers import AnswerTopics, Frames

    building, answers = run
    k, result, local, T_odom_sensor = next(a for a in answers if a[1].next_look)
    arrows = look_arrows(result, T_odom_sensor)
    assert len(arrows) == sum(len(look.separates) for look in result.next_look)
    best = result.best.pose
    where = {o.id: o.position for o in building}
    for arrow in arrows:
        look = result.next_look[arrow.order - 1]
        # from the sensor as the best hypothesis places it, to where rank r puts the object
        assert np.allclose(arrow.start, best[:3, :3] @ T_odom_sensor[:3, 3] + best[:3, 3])
        spot = best[:3, :3] @ look.where[arrow.rank] + best[:3, 3]
        assert np.allclose(arrow.end, spot)
        assert arrow.text == f"look {arrow.order}: {look.label} {look.global_id} if #{arrow.rank}"
        if arrow.rank == result.best.rank:  # the best hypothesis's spot is the object itself
            assert np.allclose(arrow.end, where[look.global_id], atol=1e-6)
    markers = AnswerTopics(None, building, Frames()).match_markers(k, result, local, T_odom_sensor)
    drawn = [mk for mk in markers.markers if mk.ns == "next look"]
    assert [mk.type for mk in drawn] == [0, 9] * len(arrows)  # an arrow and its label
    assert [mk.text for mk in drawn[1::2]] == [a.text for a in arrows]
    assert len({mk.id for mk in drawn}) == len(drawn)
    assert np.allclose([[p.x, p.y, p.z] for p in drawn[0].points], [arrows[0].start, arrows[0].end])
    localized = AnswerTopics(None, building, Frames()).match_markers(*answers[-1])
    assert not [mk for mk in localized.markers if mk.ns == "next look"]


def test_the_demo_streams_to_foxglove_and_stays_up_until_ctrl_c(tmp_path):
    pytest.importorskip("open3d", reason="the sim extra is not installed")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path), "COLUMNS": "200"}
    demo = subprocess.Popen(
        [sys.executable, "-m", "semloc", "demo", "--size", "tiny", "--keyframes", "8",
         "--resolution", "120x90", "--out", str(tmp_path / "out"), "--foxglove", "0"],
        env=env, text=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
    )  # fmt: skip
    try:
        port = None
        for line in demo.stdout:
            if "stays up at ws://localhost:" in line:
                port = int(line.split("ws://localhost:")[1].split(":")[0].split()[0])
                break
        assert port is not None, demo.stderr.read()
        assert (tmp_path / "out" / "result.json").is_file()
        for subprotocol in SUBPROTOCOLS:  # after the run: every channel that had a message
            with opened(port, subprotocol) as (ws, _, channels):
                topics, got = subscribe_all(ws, channels), {}
                while "/semloc/status" not in got:  # the last channel: its message comes last
                    got.update(messages(ws, topics, 1))
                assert {"/semloc/map", "/semloc/local", "/semloc/hypotheses"} <= set(got)
    finally:
        demo.send_signal(signal.SIGINT)
        _, err = demo.communicate(timeout=30)
    assert demo.returncode == 130, err
    assert "semloc: interrupted" in err.splitlines() and "Traceback" not in err
