"""Position priors through `semloc serve`: the localize body's and session updates' `"prior"`
(answers equal in-process `semloc.localize(..., prior=)` and a Localizer with `set_prior`),
422 for an invalid prior, a session's prior (from its opening or an update) across a rebuild on
another worker, the client's `prior=` and `semloc localize --server --near --radius`."""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers import room
from test_api import raw, same_answer

import semloc
from semloc import Localizer, ObjectMap, Prior
from semloc.cli import main
from semloc.client import Client
from semloc.io import map_from_dict, map_to_dict, save_map
from semloc.priors import OUTSIDE_PRIOR
from semloc.serve.store import open_store
from semloc.transforms import yaw_pose

SHIFT = np.array([30.0, 0.0, 0.0])
TRUE_POSE = yaw_pose(0.7, [0.5, 0.5, 0.0])  # the local origin in copy A
IN_A = Prior(position=[1.3, 0.0, 0.2], radius=1.5)
IN_B = Prior(position=[34.0, 4.0, 0.5], radius=2.0)  # the other copy: not the origin's place


@pytest.fixture(scope="module")
def two_rooms() -> tuple[ObjectMap, ObjectMap]:
    """Two identical copies of one room 30 m apart, and a view of copy A (as the server reads
    them: JSON rounds to 1e-6)."""
    a = room(10)
    b = [o.replace(id=o.id.replace("a", "b"), position=o.position + SHIFT) for o in a]
    world = ObjectMap([*a, *b], up=[0, 0, 1], name="two rooms")
    inverse = np.linalg.inv(TRUE_POSE)
    seen = [a[i].transformed(inverse).replace(id=f"l{k}", seen=k) for k, i in enumerate(range(7))]
    view = ObjectMap(seen, up=[0, 0, 1], name="view of A")
    return map_from_dict(map_to_dict(world)), map_from_dict(map_to_dict(view))


@pytest.fixture
def client(serve, two_rooms) -> Client:
    client = Client(serve().url)
    client.put_map("rooms", two_rooms[0])
    return client


@pytest.mark.parametrize("prior", [None, IN_A, IN_B, Prior([0.5, 0.5, 0], 1, heading=40)])
def test_a_served_localization_with_a_prior_equals_the_in_process_one(client, two_rooms, prior):
    world, view = two_rooms
    served = client.localize("rooms", view, prior=prior)
    expected = semloc.localize(world, view, prior=prior)
    same_answer(served, expected)
    assert served["reason"] == expected.reason
    assert served["prior"] == (None if prior is None else prior.to_dict())  # echoed
    assert [h.get("outside_prior") for h in served["hypotheses"]] == [
        h.outside_prior for h in expected.hypotheses
    ]


def test_a_prior_decides_between_two_copies_and_says_when_the_best_lies_outside(client, two_rooms):
    view = two_rooms[1]
    assert client.localize("rooms", view)["status"] == "ambiguous"
    inside = client.localize("rooms", view, prior=IN_A.to_dict())  # its JSON object does too
    assert inside["status"] == "localized"
    np.testing.assert_allclose(inside["pose"], TRUE_POSE, atol=1e-6)
    outside = client.localize("rooms", view, prior=IN_B)
    assert outside["status"] == "ambiguous" and outside["reason"].startswith(OUTSIDE_PRIOR)
    assert outside["hypotheses"][0]["outside_prior"] is True


@pytest.mark.parametrize(
    ("prior", "named"),
    [
        ({"position": [1, 2], "radius": 1}, "position"),
        ({"position": [1, 2, 3], "radius": 0}, "radius"),
        ({"position": [1, 2, 3], "radius": -2}, "radius"),
        ({"position": [1, 2, 3]}, "radius"),
        ({"position": [1, 2, 3], "radius": "2"}, "radius"),
        ({"position": [1, 2, 3], "radius": 1, "floor": [2, 1]}, "z_min <= z_max"),
        ({"position": [1, 2, 3], "radius": 1, "heading_tolerance": 10}, "needs a heading"),
        ({"position": [1, 2, 3], "radius": 1, "heading": 0, "heading_tolerance": 200}, "heading_tolerance"),
        ({"position": [1, 2, 3], "radius": 1, "colour": "red"}, "colour"),
        ([1, 2, 3], "prior"),
    ],
)  # fmt: skip
def test_an_invalid_prior_is_refused_with_422_naming_the_problem(client, two_rooms, prior, named):
    world, view = two_rooms
    local = json.dumps({**map_to_dict(view), "prior": prior}).encode()
    session = client.session("rooms")
    update = json.dumps({"objects": [], "prior": prior}).encode()
    opening = json.dumps({"up": [0, 0, 1], "prior": prior}).encode()
    for path, body in (
        ("/v1/maps/rooms/localize", local),
        (f"/v1/sessions/{session.session_id}/objects", update),
        ("/v1/maps/rooms/sessions", opening),
    ):
        status, answer = raw(client.url, "POST", path, body)
        assert status == 422, answer
        assert set(answer) == {"error", "detail"} and answer["error"].startswith("invalid")
        assert named in json.dumps(answer["detail"]), answer
    assert session.update([])["update"] == 1  # nothing of the refused updates was applied
    assert [s["mine"] for s in client.request("GET", "/v1/maps/rooms/sessions")] == [True]


def test_the_client_checks_a_prior_before_sending_it(client, two_rooms):
    with pytest.raises(ValueError, match="radius must be > 0"):
        client.localize("rooms", two_rooms[1], prior={"position": [0, 0, 0], "radius": 0})
    with pytest.raises(TypeError, match="semloc.Prior"):
        client.localize("rooms", two_rooms[1], prior=[0, 0, 0])  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="contradict"):
        client.session("rooms").update([], prior=IN_A, clear_prior=True)
    with pytest.raises(ValueError, match="radius must be > 0"):
        client.session("rooms", prior={"position": [0, 0, 0], "radius": -1})
    with pytest.raises(TypeError, match="semloc.Prior"):
        client.session("rooms", prior=(0, 0, 0))  # type: ignore[arg-type]


def test_a_session_prior_holds_from_its_update_until_cleared(client, two_rooms):
    world, view = two_rooms
    objects = list(view)
    session = client.session("rooms", up=[0, 0, 1])
    reference = Localizer(world, local_up=[0, 0, 1])
    first = session.update(objects[:3])
    same_answer(first, reference.update(objects[:3]))
    assert first["prior"] is None
    reference.set_prior(IN_A)
    second = session.update(objects[3:5], prior=IN_A)
    same_answer(second, reference.update(objects[3:5]))
    assert second["status"] == "localized" and second["prior"] == IN_A.to_dict()
    third = session.update(objects[5:6])  # no "prior": it stays
    same_answer(third, reference.update(objects[5:6]))
    assert third["prior"] == IN_A.to_dict()
    reference.set_prior(None)
    cleared = session.update(objects[6:], clear_prior=True)  # "prior": null
    same_answer(cleared, reference.update(objects[6:]))
    assert cleared["prior"] is None  # (the tracked place is kept: it is within "no prior")


def test_a_session_opened_with_a_prior_has_it_from_its_first_update(client, two_rooms):
    world, view = two_rooms
    objects = list(view)
    session = client.session("rooms", up=[0, 0, 1], prior=IN_A)
    reference = Localizer(world, local_up=[0, 0, 1], prior=IN_A)
    for batch in (objects[:4], objects[4:]):
        served = session.update(batch)
        same_answer(served, reference.update(batch))
        assert served["prior"] == IN_A.to_dict()
    assert served["status"] == "localized"
    np.testing.assert_allclose(served["pose"], TRUE_POSE, atol=1e-6)
    cleared = session.update([], clear_prior=True)  # an update changes it as before
    reference.set_prior(None)
    same_answer(cleared, reference.update([]))
    assert cleared["prior"] is None
    unset = client.session("rooms", up=[0, 0, 1], prior=None)  # null: no prior
    assert unset.update(objects)["prior"] is None


@pytest.mark.parametrize("changes", [False, True])
def test_a_session_opened_with_a_prior_keeps_it_across_rebuilds(serve, two_rooms, tmp_path,
                                                                 changes):  # fmt: skip
    """Opened on one worker, every update on the other in turn: the opening prior holds on
    either (on the second from its very first update, with no state saved by an update),
    and an update's change replaces it there too."""
    world, view = two_rooms
    store = tmp_path / "shared"
    first, second = serve(store=open_store(store)), serve(store=open_store(store))
    Client(first.url).put_map("rooms", world)
    session = Client(first.url).session("rooms", up=[0, 0, 1], prior=IN_B)
    clients = [Client(second.url), Client(first.url)]  # the first update on the other one
    reference = Localizer(world, local_up=[0, 0, 1], prior=IN_B)
    objects = list(view)
    steps = [(objects[:3], None), (objects[3:5], None), (objects[5:], None), ([], None)]
    if changes:
        steps[2] = (objects[5:], IN_A)
    statuses = []
    for k, (batch, change) in enumerate(steps):
        session.client = clients[k % 2]
        served = session.update(batch, stamp=k, prior=change)
        if change is not None:
            reference.set_prior(change)
        same_answer(served, reference.update(batch))
        assert served["prior"] == reference.prior.to_dict()
        statuses.append(served["status"])
    if changes:
        assert statuses == ["ambiguous", "ambiguous", "localized", "localized"]
    else:  # the view is of copy A, the prior says B: never localized
        assert statuses == ["ambiguous"] * 4


def test_a_session_prior_survives_a_rebuild_on_another_worker(serve, two_rooms, tmp_path):
    """Two servers over one store taking turns; the prior is set, changed and cleared on
    either: every answer equals an uninterrupted Localizer's with the same set_prior calls."""
    world, view = two_rooms
    store = tmp_path / "shared"
    first, second = serve(store=open_store(store)), serve(store=open_store(store))
    Client(first.url).put_map("rooms", world)
    session = Client(first.url).session("rooms", up=[0, 0, 1])
    clients = [Client(first.url), Client(second.url)]
    reference = Localizer(world, local_up=[0, 0, 1])
    objects = list(view)
    steps = [  # (objects, prior change: absent, a Prior, or "clear")
        (objects[:2], IN_A), (objects[2:3], None), (objects[3:4], None), (objects[4:5], IN_B),
        (objects[5:6], None), (objects[6:], IN_A), ([], None), ([], "clear"), ([], None),
        ([], IN_A), ([], None),
    ]  # fmt: skip
    statuses = []
    for k, (batch, change) in enumerate(steps):
        session.client = clients[k % 2]  # every update on the other worker: always rebuilt
        if change == "clear":
            served = session.update(batch, stamp=k, clear_prior=True)
            reference.set_prior(None)
        else:
            served = session.update(batch, stamp=k, prior=change)
            if change is not None:
                reference.set_prior(change)
        same_answer(served, reference.update(batch))
        prior = reference.prior
        assert served["prior"] == (None if prior is None else prior.to_dict())
        statuses.append(served["status"])
    assert statuses == [  # the prior decides; B's prior ends A's claim; clearing keeps it
        "ambiguous", "ambiguous", "localized", "ambiguous", "ambiguous", *["localized"] * 6
    ]  # fmt: skip


def test_localize_on_a_server_sends_near_and_radius(client, two_rooms, tmp_path, capsys):
    local = tmp_path / "view.json"
    save_map(two_rooms[1], local)
    args = ["localize", "rooms", str(local), "--server", client.url, "--format", "json"]
    assert main([*args, "--near", "1.3", "0", "0.2", "--radius", "1.5"]) == 0
    answer = json.loads(capsys.readouterr().out)
    assert answer["status"] == "localized" and answer["prior"] == IN_A.to_dict()
    np.testing.assert_allclose(answer["pose"], TRUE_POSE, atol=1e-6)
    assert main([*args, "--near", "1", "2", "3", "--radius", "0"]) == 2
    assert "radius must be > 0" in capsys.readouterr().err


def test_the_node_s_remote_localizer_sends_a_prior_change_once(client, two_rooms):
    """`semloc ros2 node --server`: set_prior reaches the session with the next update."""
    from semloc.ros2.remote import RemoteLocalizer

    world, view = two_rooms
    objects = list(view)
    remote = RemoteLocalizer(client.session("rooms", up=[0, 0, 1]), world)
    reference = Localizer(world, local_up=[0, 0, 1])
    remote.set_prior(IN_A)
    reference.set_prior(IN_A)
    for batch in (objects[:4], objects[4:]):
        got, expected = remote.update(batch), reference.update(batch)
        assert got.status == expected.status == "localized"
        np.testing.assert_allclose(got.pose, expected.pose, atol=1e-9)
    assert remote.prior == IN_A  # the session's echo
    remote.set_prior(None)
    assert remote.prior is None  # pending: the prior from the next update on
    answer = remote.session.update([])  # not through the RemoteLocalizer: no change sent
    assert answer["prior"] == IN_A.to_dict()
    remote.update([])
    assert remote.session.update([])["prior"] is None and remote.prior is None
    opened = RemoteLocalizer(client.session("rooms", up=[0, 0, 1], prior=IN_B), world)
    assert opened.prior is None  # nothing answered yet: not known here
    opened.update(objects[:2])
    assert opened.prior == IN_B  # the session's opening prior, as its answer echoes it


def test_the_node_s_remote_localizer_sends_the_coverage(client, two_rooms):
    """`semloc ros2 node --server --camera-info`: each look goes with its session update, so
    the served answers weigh it as an in-process Localizer does (and without one, neither)."""
    from semloc.ros2.remote import RemoteLocalizer

    world, view = two_rooms
    objects = list(view)
    look = semloc.Coverage(pose=np.eye(4), range_m=6.0, fov_deg=None)
    remote = RemoteLocalizer(client.session("rooms", up=[0, 0, 1]), world)
    reference = Localizer(world, local_up=[0, 0, 1])
    for batch, coverage in ((objects[:4], None), (objects[4:], look), ([], look)):
        got = remote.update(batch, coverage=coverage)
        expected = reference.update(batch, coverage=coverage)
        assert got.status == expected.status
        assert got.support == expected.support
        assert [(h.n_missing, h.n_expected) for h in got.hypotheses] == [
            (h.n_missing, h.n_expected) for h in expected.hypotheses
        ]
    assert expected.hypotheses[0].n_expected is not None
