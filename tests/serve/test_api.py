"""The HTTP API of `semloc serve` against a live server: each endpoint and status code, answers
equal to in-process calls, sessions rebuilt by another worker, change reports and conflicts."""

from __future__ import annotations

import json
import threading
import time
import urllib.request
from types import SimpleNamespace

import numpy as np
import pytest
from conftest import T_TRUE, view
from proxy import DroppingProxy

import semloc
import semloc.client as client_module
import semloc.serve.service as service_module
import semloc.serve.store as store_module
from semloc.client import Client, ServerError
from semloc.io import map_from_dict, map_to_dict
from semloc.maps import ObjectMap
from semloc.serve.service import Service
from semloc.serve.store import open_store
from semloc.transforms import pose_error, yaw_pose

TABLE = [3, 4, 5, 6, 7, 8, 9]  # a table and its chairs, a cabinet beside them


def raw(url: str, method: str, path: str, body: bytes | None = None, token: str | None = None,
        headers: dict | None = None) -> tuple[int, object]:  # fmt: skip
    """One request without the client: (status, decoded JSON or None)."""
    request = urllib.request.Request(url + path, data=body, method=method)
    request.add_header("Content-Type", "application/json")
    if token:
        request.add_header("Authorization", f"Bearer {token}")
    for key, value in (headers or {}).items():
        request.add_header(key, value)
    try:
        with urllib.request.urlopen(request, timeout=120) as response:
            data = response.read()
            return response.status, json.loads(data) if data else None
    except urllib.error.HTTPError as exc:
        data = exc.read()
        return exc.code, json.loads(data) if data else None


def same_answer(served: dict, result: semloc.Result) -> None:
    """Status, pose (1e-9) and pairs of a served answer equal an in-process Result's."""
    assert served["status"] == result.status
    if result.pose is None:
        assert served["pose"] is None
    else:
        np.testing.assert_allclose(np.array(served["pose"]), result.pose, atol=1e-9, rtol=0)
    assert [[(p["global"], p["local"]) for p in h["pairs"]] for h in served["hypotheses"]] == [
        h.pairs for h in result.hypotheses
    ]


def test_health_maps_and_versions(serve, building):
    server = serve()
    client = Client(server.url)
    assert client.health()["status"] == "ok"
    status, created = raw(
        server.url, "PUT", "/v1/maps/office", json.dumps(map_to_dict(building)).encode()
    )
    assert (status, created) == (201, {"map_id": "office", "version": 1})
    assert client.put_map("office", building) == 2
    stored = client.get_map("office")
    assert list(stored.ids) == list(building.ids)
    np.testing.assert_array_equal(stored.positions, building.positions)
    assert [v["version"] for v in client.versions("office")] == [1, 2]
    assert {v["source"] for v in client.versions("office")} == {"upload"}
    assert all(v["created"].endswith("+00:00") for v in client.versions("office"))
    assert len(client.get_map("office", version=1)) == len(building)
    assert client.maps() == [{"map_id": "office", "version": 2}]
    assert raw(server.url, "GET", "/v1/maps/office?version=3")[0] == 404
    assert raw(server.url, "GET", "/v1/maps/office?version=0")[0] == 422
    assert raw(server.url, "GET", "/v1/maps/nowhere")[0] == 404
    assert raw(server.url, "GET", "/v1/maps/nowhere/versions")[0] == 404
    assert raw(server.url, "GET", "/openapi.json")[0] == 200


def test_localize_equals_the_in_process_answer(serve, building):
    client = Client(serve().url)
    client.put_map("office", building)
    for indices in (TABLE, [20, 21, 22, 23, 24, 25], [0, 1, 2]):
        local = view(building, indices, T_TRUE)
        served = client.localize("office", local)
        same_answer(served, semloc.localize(building, local))
        assert served["map_version"] == 1
        assert set(served) >= {"status", "pose", "confidence", "reason", "hypotheses", "changes",
                               "labels", "steps", "timing_ms", "next_look"}  # fmt: skip
        expected = semloc.localize(building, local).to_dict()["next_look"]
        assert served["next_look"] == expected  # where to look next, as in process
    assert served["status"] == "ambiguous" and served["reason"]
    local = view(building, TABLE, T_TRUE)
    answer = client.localize("office", local)
    assert answer["status"] == "localized"
    rotation, translation = pose_error(np.array(answer["pose"]), T_TRUE)
    assert rotation < 0.1 and translation < 0.01


def test_a_session_streams_updates_like_an_in_process_localizer(serve, building):
    client = Client(serve().url)
    client.put_map("office", building)
    local = view(building, TABLE, T_TRUE)
    reference = semloc.Localizer(building, local_up=local.up)
    with client.session("office", up=local.up.tolist()) as session:
        for k, obj in enumerate(local):
            served = session.update([obj], stamp=100.0 + k)
            assert served["stamp"] == 100.0 + k and served["update"] == k + 1
            same_answer(served, reference.update([obj]))
        assert served["status"] == "localized"
        session_id = session.session_id
    assert raw(client.url, "POST", f"/v1/sessions/{session_id}/objects",
               b'{"objects": [], "stamp": 0}')[0] == 404  # fmt: skip
    assert raw(client.url, "DELETE", f"/v1/sessions/{session_id}")[0] == 404


def test_any_worker_serves_any_update_of_a_session(serve, building, tmp_path):
    """Two servers over one store, taking turns: the session is rebuilt from its stored batches
    where it is not in memory, and every answer equals an uninterrupted session's."""
    store = tmp_path / "shared"
    first = serve(store=open_store(store))
    second = serve(store=open_store(store))
    Client(first.url).put_map("office", building)
    local = view(building, TABLE, T_TRUE)
    session = Client(first.url).session("office", up=local.up.tolist())
    reference = semloc.Localizer(building, local_up=local.up)
    clients = [Client(first.url), Client(second.url)]
    for k, obj in enumerate(local):
        session.client = clients[(k // 2) % 2]  # 2 updates on one, 2 on the other, ...
        same_answer(session.update([obj], stamp=k), reference.update([obj]))


def test_two_objects_per_update_and_redetections(serve, building):
    client = Client(serve().url)
    client.put_map("office", building)
    local = list(view(building, TABLE, T_TRUE))
    moved_a_bit = local[0].replace(position=local[0].position + [0.02, 0.0, 0.0])
    batches = [local[:2], local[2:5], [moved_a_bit, *local[5:]]]
    reference = semloc.Localizer(building, local_up=view(building, TABLE, T_TRUE).up)
    session = client.session("office", up=reference.local_up.tolist())
    for batch in batches:
        same_answer(session.update(batch), reference.update(map_from_dict(
            map_to_dict(ObjectMap(batch)))))  # fmt: skip


def test_sessions_expire_when_idle(serve, building, monkeypatch):
    """On the service's own clock (a stand-in here: no wall-clock window to fit in)."""
    now = [time.time()]
    clock = SimpleNamespace(time=lambda: now[0], monotonic=time.monotonic, sleep=time.sleep)
    for module in (service_module, store_module):
        monkeypatch.setattr(module, "time", clock)
    client = Client(serve(session_idle_s=0.3).url)
    client.put_map("office", building)
    session = client.session("office")
    session.update([])
    now[0] += 0.5
    with pytest.raises(ServerError) as error:
        session.update([])
    assert error.value.status == 404


def _moved_view(building: ObjectMap, shift=(0.9, 0.6, 0.0)) -> ObjectMap:
    """The table group seen with one chair (global id '7') moved by `shift` metres."""
    moved = building.with_objects(
        [o.transformed(yaw_pose(0.0, shift)) if o.id == "7" else o for o in building]
    )
    return view(moved, TABLE, T_TRUE)


def test_a_change_report_becomes_a_new_version(serve, building):
    client = Client(serve().url)
    client.put_map("office", building)
    local = _moved_view(building)
    answer = client.localize("office", local)
    assert answer["status"] == "localized"
    assert [m["global"] for m in answer["changes"]["moved"]] == ["7"]
    status, refused = raw(client.url, "POST", "/v1/maps/office/changes",
                          json.dumps({**answer, "localization_id": "unknown"}).encode())  # fmt: skip
    assert status == 404 and "localization_id" in refused["detail"]
    # the answer as it came: the server kept the local objects under its localization_id
    status, created = raw(
        client.url, "POST", "/v1/maps/office/changes", json.dumps(answer).encode()
    )
    assert (status, created) == (201, {"version": 2, "changed": True})
    updated = client.get_map("office")
    np.testing.assert_allclose(updated.get("7").position, building.get("7").position + [0.9, 0.6, 0],
                               atol=0.02)  # fmt: skip
    assert [v["source"] for v in client.versions("office")] == [
        "upload",
        "changes (from version 1)",
    ]
    # the same view again on the new version: nothing left to change, no new version
    again = client.localize("office", local)
    assert again["changes"]["moved"] == [] and again["map_version"] == 2
    assert client.report_changes("office", again, local=local) == {"version": 2, "changed": False}


def test_a_stale_change_report_conflicts_and_a_disjoint_one_applies(serve, building):
    client = Client(serve().url)
    client.put_map("office", building)
    local = _moved_view(building)
    answer = client.localize("office", local)
    # another device moved chair 7 elsewhere meanwhile: version 2
    other = _moved_view(building, shift=(-0.8, -0.5, 0.0))
    assert (
        client.report_changes("office", client.localize("office", other), local=other)["version"]
        == 2
    )
    with pytest.raises(ServerError) as error:
        client.report_changes("office", answer, local=local)
    assert error.value.status == 409 and error.value.error == "conflict"
    assert [v["version"] for v in client.versions("office")] == [1, 2]
    # a report of version 2 about another corner of the map applies on top of version 3 = ...
    corner = [20, 21, 22, 23, 24, 25]
    shifted = building.with_objects(
        [o.transformed(yaw_pose(0.0, [0.0, 0.9, 0.0])) if o.id == "22" else o for o in building]
    )
    corner_view = view(shifted, corner, T_TRUE)
    corner_answer = client.localize("office", corner_view)
    assert [m["global"] for m in corner_answer["changes"]["moved"]] == ["22"]
    chair = _moved_view(building, shift=(0.0, 0.0, 0.0))  # chair 7 seen back in place: version 3
    assert (
        client.report_changes("office", client.localize("office", chair), local=chair)["version"]
        == 3
    )
    assert client.report_changes("office", corner_answer, local=corner_view)["version"] == 4
    final = client.get_map("office")
    np.testing.assert_allclose(final.get("22").position, shifted.get("22").position, atol=0.02)
    np.testing.assert_allclose(final.get("7").position, building.get("7").position, atol=0.02)


def test_change_reports_need_a_localized_answer_and_the_local_objects(serve, building):
    server = serve()
    client = Client(server.url)
    client.put_map("office", building)
    local = view(building, [0, 1, 2], T_TRUE)
    answer = client.localize("office", local)
    assert answer["status"] == "ambiguous"
    # the answer as it came (ambiguous); one that says `localized` although the server's own
    # record of it (its localization_id) says otherwise: a conflict with what the server kept
    for body, status in ((answer, 422), ({**answer, "status": "localized"}, 409),
                         ({"map_version": 1}, 422), ([1, 2], 422)):  # fmt: skip
        code, error = raw(server.url, "POST", "/v1/maps/office/changes", json.dumps(body).encode())
        assert code == status and set(error) == {"error", "detail"}, (body, error)
    with pytest.raises(ServerError) as refused:
        client.report_changes("office", {**answer, "map_version": 7, "accept_ambiguous": True},
                              local=local)  # fmt: skip
    assert refused.value.status == 404 and "version 7" in refused.value.detail


def test_a_session_reports_its_own_changes(serve, building):
    client = Client(serve().url)
    client.put_map("office", building)
    local = _moved_view(building)
    with client.session("office", up=local.up.tolist()) as session:
        answer = session.update(list(local))
        assert answer["status"] == "localized"
        assert client.report_changes("office", answer)["version"] == 2


def test_bad_input_is_a_4xx_with_the_error_shape_and_the_server_goes_on(serve, building):
    server = serve(max_body=200_000)
    url = server.url
    good = json.dumps(map_to_dict(building.with_objects(list(building)[:3]))).encode()
    cases = [
        ("PUT", "/v1/maps/a", b"{not json", 400),
        ("PUT", "/v1/maps/a", b'{"format": "semloc-map", "version": 1, "objects": [{"id": "1", '
         b'"label": "chair", "position": [NaN, 0, 0]}]}', 400),
        ("PUT", "/v1/maps/a", b'{"a": 1, "a": 2}', 400),
        ("PUT", "/v1/maps/a", b"\xff\xfe", 400),
        ("PUT", "/v1/maps/a", b'{"format": "semloc-map", "version": 1}', 422),
        ("PUT", "/v1/maps/a", b'{"format": "semloc-map", "version": 1, "objects": [{"id": "1", '
         b'"label": "chair", "position": [1e300, 0, 0]}]}', 422),
        ("PUT", "/v1/maps/a", b'{"format": "semloc-map", "version": 1, "objects": [], '
         b'"points_file": "semloc.sqlite3"}', 422),
        ("PUT", "/v1/maps/a", b"[" * 100_000 + b"]" * 100_000, 400),
        ("PUT", "/v1/maps/a", b" " * 300_000, 413),
        ("POST", "/v1/maps/a/localize", good, 404),
        ("POST", "/v1/sessions/nope/objects", b'{"objects": []}', 404),
        ("DELETE", "/v1/sessions/nope", None, 404),
        ("GET", "/v1/nothing", None, 404),
        ("PATCH", "/v1/maps/a", good, 405),
    ]  # fmt: skip
    for method, path, body, status in cases:
        code, error = raw(url, method, path, body)
        assert code == status, (method, path, body[:40] if body else body, code, error)
        assert isinstance(error, dict) and set(error) == {"error", "detail"}, error
    assert raw(url, "PUT", "/v1/maps/a", good)[0] == 201
    session = Client(url).session("a")
    for body in (b'{"objects": 3}', b'{"stamp": 1}', b'{"objects": [], "stamp": "x"}',
                 b'{"objects": [{"id": "1"}]}', b'[]'):  # fmt: skip
        code, error = raw(url, "POST", f"/v1/sessions/{session.session_id}/objects", body)
        assert code == 422 and set(error) == {"error", "detail"}, (body, error)
    assert session.update([])["update"] == 1  # refused batches were not stored
    assert raw(url, "POST", "/v1/maps/a/sessions", b'{"up": [0, 0]}')[0] == 422
    assert raw(url, "POST", "/v1/maps/a/sessions", b"\t")[0] == 400  # not JSON, not absent
    assert raw(url, "POST", "/v1/maps/a/sessions", b"null")[0] == 422
    assert raw(url, "POST", "/v1/maps/a/sessions", b"")[0] == 201  # absent: no up
    assert raw(url, "POST", "/v1/maps/a/sessions", b'{"down": 1}')[0] == 422


def test_past_the_rate_a_token_gets_429(serve, building):
    server = serve(rate=5)
    codes = [raw(server.url, "GET", "/v1/maps")[0] for _ in range(30)]
    assert codes[:10] == [200] * 10 and 429 in codes
    time.sleep(1.0)
    assert raw(server.url, "GET", "/v1/maps")[0] == 200


def test_two_writers_on_one_map_get_distinct_whole_versions(serve, building):
    client = Client(serve().url)
    client.put_map("office", building)
    versions: list[int] = []
    small = building.with_objects(list(building)[:5])

    def write(objmap: ObjectMap) -> None:
        for _ in range(5):
            versions.append(client.put_map("office", objmap))

    threads = [threading.Thread(target=write, args=(m,)) for m in (building, small)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert sorted(versions) == list(range(2, 12))
    for version in range(1, 12):
        assert len(client.get_map("office", version)) in (len(building), 5)


def test_the_page_is_served(serve, building):
    server = serve()
    with urllib.request.urlopen(server.url + "/", timeout=10) as response:
        html = response.read().decode()
    assert response.status == 200 and "<svg" in html and "/v1/maps" in html


def test_a_service_object_can_be_used_without_http(tmp_path, building):
    service = Service(open_store(tmp_path))
    assert service.put_map("office", map_to_dict(building)) == 1
    version, objmap = service.object_map("office")
    assert version == 1 and len(objmap) == len(building)


def test_two_workers_over_postgresql(serve, building, postgres_url):
    """The service on a PostgreSQL store: uploads, a session served by two workers in turn, a
    change report."""
    first = serve(store=open_store(".", postgres_url))
    second = serve(store=open_store(".", postgres_url))
    client = Client(first.url)
    assert client.put_map("office", building) == 1
    local = _moved_view(building)
    session = client.session("office", up=local.up.tolist())
    reference = semloc.Localizer(building, local_up=local.up)
    clients = [Client(first.url), Client(second.url)]
    for k, obj in enumerate(local):
        session.client = clients[k % 2]
        answer = session.update([obj], stamp=k)
        same_answer(answer, reference.update([obj]))
    assert answer["status"] == "localized"
    assert Client(second.url).report_changes("office", answer)["version"] == 2
    assert [v["version"] for v in client.versions("office")] == [1, 2]
    with first.service.store._transaction(write=True) as cur:
        cur.execute("DROP TABLE IF EXISTS maps, map_versions, sessions, session_batches, "
                    "session_states, session_owners, request_keys, localizations, schema_version")  # fmt: skip


def test_replies_leave_without_waiting_for_an_acknowledgement():
    """The listening socket is TCP with TCP_NODELAY, so accepted connections are too (without
    it every kept-alive request waited 40 ms for the client's delayed acknowledgement)."""
    import socket

    from semloc.serve.server import bind

    sock = bind("127.0.0.1", 0)
    try:
        assert sock.proto == socket.IPPROTO_TCP
        assert sock.getsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY) == 1
        with socket.create_connection(sock.getsockname()):
            accepted, _ = sock.accept()
            with accepted:
                assert accepted.getsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY) == 1
    finally:
        sock.close()


def test_racing_change_reports_of_one_object_give_one_version_and_one_409(serve, building):
    """Two devices report chair 7 moved to two different places, both from version 1, at
    once: one report becomes version 2, the other is refused (409), never a mix."""
    client = Client(serve().url)
    client.put_map("office", building)
    reports = []
    for shift in ((0.9, 0.6, 0.0), (-0.8, -0.5, 0.0)):
        local = _moved_view(building, shift)
        reports.append((client.localize("office", local), local))
    outcomes: list[object] = []
    barrier = threading.Barrier(2)

    def report(answer, local) -> None:
        barrier.wait()
        try:
            outcomes.append(Client(client.url).report_changes("office", answer, local=local))
        except ServerError as error:
            outcomes.append(error.status)

    threads = [threading.Thread(target=report, args=r) for r in reports]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert sorted(map(str, outcomes)) == sorted(["409", str({"version": 2, "changed": True})])
    moved = client.get_map("office").get("7").position - building.get("7").position
    assert min(np.linalg.norm(moved - s) for s in ([0.9, 0.6, 0], [-0.8, -0.5, 0])) < 0.05
    assert [v["version"] for v in client.versions("office")] == [1, 2]


# Safe retries -------------------------------------------------------------------------------
def test_a_session_update_whose_answer_was_lost_is_answered_again_and_applied_once(serve, building):
    """The proxy drops the answer of the first session update (served, then the connection
    closes): the client sends it again with the same Idempotency-Key and gets the same answer;
    the session holds one batch, and the next update is update 2."""
    server = serve()
    Client(server.url).put_map("office", building)
    proxy = DroppingProxy(server.url, lambda method, path: path.endswith("/objects"))
    local = view(building, TABLE, T_TRUE)
    client = Client(proxy.url)
    session = client.session("office", up=local.up.tolist())
    reference = semloc.Localizer(building, local_up=local.up)
    first = session.update(list(local)[:4], stamp=1.0)
    assert proxy.dropped == [f"POST /v1/sessions/{session.session_id}/objects 200"]
    assert first["update"] == 1 and first["stamp"] == 1.0
    same_answer(first, reference.update(list(local)[:4]))
    second = session.update(list(local)[4:], stamp=2.0)
    assert second["update"] == 2 and second["status"] == "localized"
    same_answer(second, reference.update(list(local)[4:]))
    assert [b.seq for b in server.service.store.batches(session.session_id)] == [1, 2]
    proxy.close()


def test_a_change_report_whose_answer_was_lost_gets_its_answer_not_a_409(serve, building):
    server = serve()
    Client(server.url).put_map("office", building)
    proxy = DroppingProxy(server.url, lambda method, path: path.endswith("/changes"))
    client = Client(proxy.url)
    local = _moved_view(building)
    answer = client.localize("office", local)
    assert client.report_changes("office", answer) == {"version": 2, "changed": True}
    assert proxy.dropped == ["POST /v1/maps/office/changes 201"]
    assert [v["version"] for v in client.versions("office")] == [1, 2]
    proxy.close()


def test_an_upload_whose_answer_was_lost_is_one_version(serve, building):
    server = serve()
    proxy = DroppingProxy(server.url, lambda method, path: method == "PUT")
    client = Client(proxy.url)
    assert client.put_map("office", building) == 1
    assert proxy.dropped == ["PUT /v1/maps/office 201"]
    assert [v["version"] for v in client.versions("office")] == [1]
    proxy.close()


def test_idempotency_keys_same_body_same_answer_another_body_422(serve, building):
    server = serve()
    url = server.url
    Client(url).put_map("office", building)
    local = view(building, TABLE, T_TRUE)
    session = Client(url).session("office", up=local.up.tolist())
    path = f"/v1/sessions/{session.session_id}/objects"
    body = json.dumps({"objects": map_to_dict(local)["objects"][:3], "stamp": 5.0}).encode()
    key = {"Idempotency-Key": "update-1"}
    first = raw(url, "POST", path, body, headers=key)
    assert first[0] == 200 and first[1]["update"] == 1
    other = json.dumps({"objects": [], "stamp": 6.0}).encode()
    assert raw(url, "POST", path, other, headers={"Idempotency-Key": "update-2"})[1]["update"] == 2
    assert raw(url, "POST", path, body, headers=key) == first  # after another update, too
    status, refused = raw(url, "POST", path, other, headers=key)
    assert status == 422 and refused["error"] == "idempotency key reused"
    assert [b.seq for b in server.service.store.batches(session.session_id)] == [1, 2]
    # change reports: one version per key, its answer again for the same body
    moved = _moved_view(building)
    report = json.dumps({**Client(url).localize("office", moved)}).encode()
    key = {"Idempotency-Key": "report-1"}
    assert raw(url, "POST", "/v1/maps/office/changes", report, headers=key) == (
        201, {"version": 2, "changed": True})  # fmt: skip
    assert raw(url, "POST", "/v1/maps/office/changes", report, headers=key) == (
        201, {"version": 2, "changed": True})  # fmt: skip
    assert raw(url, "POST", "/v1/maps/office/changes", b'{"status": "localized"}',
               headers=key)[0] == 422  # fmt: skip
    assert [v["version"] for v in Client(url).versions("office")] == [1, 2]
    for bad in ("", "x" * 201, "tab\there"):
        assert raw(url, "POST", path, other, headers={"Idempotency-Key": bad})[0] in (400, 422)


def test_a_repeated_update_whose_first_answer_was_never_stored_is_replayed(tmp_path, building):
    """A worker died between storing a batch and storing its answer: the update sent again
    with its key is answered by replaying the session up to that batch, not applied twice."""
    from semloc.serve.service import Idempotency, request_key
    from semloc.serve.store import session_scope

    service = Service(open_store(tmp_path))
    service.put_map("office", map_to_dict(building))
    local = view(building, TABLE, T_TRUE)
    session_id = service.create_session("office", {"up": local.up.tolist()})
    objects = map_to_dict(local)["objects"]
    service.update_session(session_id, {"objects": objects[:3], "stamp": 1.0})
    body = {"objects": objects[3:], "stamp": 2.0}
    sent = Idempotency.of("k", json.dumps(body).encode())
    key = request_key(session_scope(session_id), sent)  # as the first request stored it
    assert service.store.append_batch(session_id, 2.0, body["objects"], 600.0, key) == 2
    answer = service.update_session(session_id, body, sent)
    reference = semloc.Localizer(building, local_up=local.up)
    reference.update(list(local)[:3])
    same_answer(answer, reference.update(list(local)[3:]))
    assert answer["update"] == 2 and answer["stamp"] == 2.0
    assert [b.seq for b in service.store.batches(session_id)] == [1, 2]


def test_if_match_and_etag(serve, building):
    """PUT answers ETag "<version>"; with If-Match it writes only while the latest version is
    the one named (412 otherwise, nothing written)."""
    server = serve()
    url = server.url
    document = json.dumps(map_to_dict(building)).encode()
    assert raw(url, "PUT", "/v1/maps/office", document, headers={"If-Match": '"1"'})[0] == 412
    request = urllib.request.Request(url + "/v1/maps/office", data=document, method="PUT")
    with urllib.request.urlopen(request, timeout=60) as response:
        assert response.status == 201 and response.headers["ETag"] == '"1"'
    for latest, tag in enumerate(('"1"', "2", 'W/"3"', '"7", "4"', "*"), start=1):
        assert raw(url, "PUT", "/v1/maps/office", document, headers={"If-Match": tag}) == (
            201, {"map_id": "office", "version": latest + 1}), tag  # fmt: skip
        status, refused = raw(url, "PUT", "/v1/maps/office", document,
                              headers={"If-Match": f'"{latest}"'})  # fmt: skip
        assert status == 412 and refused["error"] == "precondition failed", tag
    assert raw(url, "PUT", "/v1/maps/office", document, headers={"If-Match": "nonsense"})[0] == 412
    client = Client(url)
    assert client.put_map("office", building, if_match=6) == 7
    with pytest.raises(ServerError) as error:
        client.put_map("office", building, if_match=6)
    assert error.value.status == 412
    assert [v["version"] for v in client.versions("office")] == list(range(1, 8))
    with urllib.request.urlopen(url + "/v1/maps/office?version=2", timeout=60) as response:
        assert response.headers["ETag"] == '"2"'


def test_the_client_waits_as_429_says_and_keeps_a_base_path(serve, building, monkeypatch):
    server = serve(rate=2)  # bursts of 4
    proxy = DroppingProxy(server.url, prefix="/semloc")
    client = Client(proxy.url)  # http://127.0.0.1:PORT/semloc
    waits: list[float] = []  # the client's own waits (its module's `time`; the server's apart)
    recording = SimpleNamespace(sleep=lambda s: waits.append(s) or time.sleep(s))
    monkeypatch.setattr(client_module, "time", recording)
    assert client.put_map("office", building) == 1
    assert all(client.versions("office")[0]["version"] == 1 for _ in range(8))
    assert waits and all(s >= 1 for s in waits)  # it waited as Retry-After said, then went on
    impatient = Client(proxy.url, retries=0)
    with pytest.raises(ServerError) as error:
        for _ in range(10):
            impatient.maps()
    assert error.value.status == 429
    proxy.close()
