"""Who may do what: the token file, and the auth matrix (token x right x map) over HTTP."""

from __future__ import annotations

import json
import time

import pytest
from conftest import T_TRUE, view
from test_api import raw

import semloc
from semloc.io import map_to_dict
from semloc.serve.access import Access, TokenFileError, digest

READER, LOCALIZER, WRITER, ADMIN, OTHER = (
    "reader-token-1", "localizer-token", "writer-token-1", "admin-token-1", "other-map-token",
)  # fmt: skip
DEVICE_A, DEVICE_B = "device-a-token", "device-b-token"  # the same rights, two devices
TOKENS = {
    "tokens": [
        {"token": READER, "maps": {"office": ["read"]}},
        {"token": LOCALIZER, "maps": {"office": ["localize"], "*": ["read"]}},
        {"sha256": digest(WRITER), "maps": {"office": ["read", "write"]}},
        {"token": ADMIN, "maps": {"*": ["read", "localize", "write"]}},
        {"token": OTHER, "maps": {"lab": ["read", "localize", "write"]}},
        {"token": DEVICE_A, "maps": {"office": ["read", "localize"]}},
        {"token": DEVICE_B, "maps": {"office": ["read", "localize"]}},
    ]
}


@pytest.fixture
def secured(serve, building, tmp_path):
    path = tmp_path / "tokens.json"
    path.write_text(json.dumps(TOKENS))
    server = serve(access=Access.from_file(path))
    document = json.dumps(map_to_dict(building)).encode()
    assert raw(server.url, "PUT", "/v1/maps/office", document, ADMIN)[0] == 201
    assert raw(server.url, "PUT", "/v1/maps/lab", document, ADMIN)[0] == 201
    return server, document


def test_the_auth_matrix(secured, building):
    server, document = secured
    url = server.url
    local = json.dumps(map_to_dict(view(building, [3, 4, 5], T_TRUE))).encode()
    requests = {  # what -> (method, path, body)
        "read": ("GET", "/v1/maps/office", None),
        "versions": ("GET", "/v1/maps/office/versions", None),
        "sessions list": ("GET", "/v1/maps/office/sessions", None),
        "localize": ("POST", "/v1/maps/office/localize", local),
        "open session": ("POST", "/v1/maps/office/sessions", None),
        "write": ("PUT", "/v1/maps/office", document),
    }
    expected = {  # token -> the status of each request, in order
        None: [401] * 6,
        "not-a-token": [401] * 6,
        READER: [200, 200, 200, 403, 403, 403],
        LOCALIZER: [200, 200, 200, 200, 201, 403],
        WRITER: [200, 200, 200, 403, 403, 201],
        ADMIN: [200, 200, 200, 200, 201, 201],
        OTHER: [404] * 6,  # office is not theirs: as if it did not exist
    }
    for token, statuses in expected.items():
        got = [raw(url, m, p, b, token)[0] for m, p, b in requests.values()]
        assert got == statuses, (token, dict(zip(requests, got)))


def test_sessions_and_change_reports_follow_the_map_rights(secured, building):
    server, _ = secured
    url = server.url
    opened = raw(url, "POST", "/v1/maps/office/sessions", None, LOCALIZER)
    assert opened[0] == 201
    path = f"/v1/sessions/{opened[1]['session_id']}/objects"
    update = b'{"objects": [], "stamp": 1.5}'
    assert raw(url, "POST", path, update)[0] == 401
    status, answer = raw(url, "POST", path, update, LOCALIZER)
    assert status == 200 and answer["stamp"] == 1.5
    report = json.dumps({**answer, "local": map_to_dict(view(building, [3], T_TRUE))}).encode()
    assert raw(url, "POST", "/v1/maps/office/changes", report, LOCALIZER)[0] == 403
    assert raw(url, "POST", "/v1/maps/office/changes", report, OTHER)[0] == 404


def test_a_session_belongs_to_the_token_that_opened_it(secured, building):
    """The ownership matrix: every other token's update or deletion of device A's session is
    refused with 404 (as for a session that does not exist), the session list never shows
    another token's session id, and A's session goes on as if nobody had tried; a token with
    `write` on the map may end it."""
    server, _ = secured
    url = server.url
    local = view(building, [3, 4, 5, 6, 7, 8, 9], T_TRUE)
    objects = map_to_dict(local)["objects"]
    status, opened = raw(url, "POST", "/v1/maps/office/sessions",
                         json.dumps({"up": local.up.tolist()}).encode(), DEVICE_A)  # fmt: skip
    assert status == 201
    session_id = opened["session_id"]
    path = f"/v1/sessions/{session_id}/objects"
    first = json.dumps({"objects": objects[:3], "stamp": 1.0}).encode()
    assert raw(url, "POST", path, first, DEVICE_A)[0] == 200

    fake = json.dumps({"objects": [{"id": "x", "label": "chair", "position": [0, 0, 0]}],
                       "stamp": 2.0}).encode()  # fmt: skip
    for token in (DEVICE_B, READER, LOCALIZER, WRITER, ADMIN, OTHER):
        assert raw(url, "POST", path, fake, token)[0] == 404, token
    for token in (DEVICE_B, READER, LOCALIZER, OTHER):
        assert raw(url, "DELETE", f"/v1/sessions/{session_id}", None, token)[0] == 404, token
    for token in (DEVICE_B, READER, LOCALIZER, WRITER, ADMIN):
        status, listed = raw(url, "GET", "/v1/maps/office/sessions", None, token)
        assert status == 200 and session_id not in json.dumps(listed), token
        assert [(s["session_id"], s["mine"], s["last"]["update"]) for s in listed] == [
            (None, False, 1)
        ]
    status, listed = raw(url, "GET", "/v1/maps/office/sessions", None, DEVICE_A)
    assert [(s["session_id"], s["mine"]) for s in listed] == [(session_id, True)]

    # A's session is as it was: its second update is update 2 and answers as a Localizer fed
    # A's two batches only (the fake object never reached it)
    rest = json.dumps({"objects": objects[3:], "stamp": 3.0}).encode()
    status, answer = raw(url, "POST", path, rest, DEVICE_A)
    reference = semloc.Localizer(building, local_up=local.up)
    reference.update(list(local)[:3])
    expected = reference.update(list(local)[3:])
    assert status == 200 and answer["update"] == 2 and answer["status"] == expected.status
    assert answer["status"] == "localized" and "x" not in json.dumps(answer["hypotheses"])

    # a token that may write the map ends any of its sessions
    assert raw(url, "DELETE", f"/v1/sessions/{session_id}", None, WRITER)[0] == 204
    assert raw(url, "POST", path, rest, DEVICE_A)[0] == 404


def test_the_map_list_shows_only_readable_maps(secured):
    url = secured[0].url
    assert [m["map_id"] for m in raw(url, "GET", "/v1/maps", None, READER)[1]] == ["office"]
    assert [m["map_id"] for m in raw(url, "GET", "/v1/maps", None, LOCALIZER)[1]] == [
        "lab",
        "office",
    ]
    assert [m["map_id"] for m in raw(url, "GET", "/v1/maps", None, OTHER)[1]] == ["lab"]
    assert raw(url, "GET", "/v1/health")[0] == 200  # no token needed


def test_401_names_the_scheme(secured):
    status, error = raw(secured[0].url, "GET", "/v1/maps/office", None, None)
    assert status == 401 and error["error"] == "unauthorized"
    status, _ = raw(secured[0].url, "GET", "/v1/maps/office", None, None,
                    headers={"Authorization": "Basic eDp5"})  # fmt: skip
    assert status == 401


@pytest.mark.parametrize(
    "content, problem",
    [
        ("{", "not valid JSON"),
        ('{"tokens": {}}', '{"tokens": [...]}'),
        ('{"tokens": [{"maps": {"*": ["read"]}}]}', "exactly one of 'token' and 'sha256'"),
        ('{"tokens": [{"token": "short", "maps": {"*": ["read"]}}]}', "at least 8 characters"),
        ('{"tokens": [{"sha256": "abc", "maps": {"*": ["read"]}}]}', "64 hexadecimal digits"),
        ('{"tokens": [{"token": "longenough", "maps": {"*": ["fly"]}}]}', "must be a list of"),
        ('{"tokens": [{"token": "longenough", "maps": {}}]}', "'maps' must be an object"),
        (
            '{"tokens": [{"token": "longenough", "maps": {"*": ["read"]}}, '
            '{"sha256": "' + digest("longenough") + '", "maps": {"*": ["read"]}}]}',
            "twice",
        ),
    ],
)
def test_a_bad_token_file_is_one_line_naming_it(tmp_path, content, problem):
    path = tmp_path / "tokens.json"
    path.write_text(content)
    with pytest.raises(TokenFileError) as error:
        Access.from_file(path)
    assert str(path) in str(error.value) and problem in str(error.value)


def test_yaml_token_files_and_hashes(tmp_path):
    path = tmp_path / "tokens.yaml"
    path.write_text(
        f"tokens:\n  - sha256: {digest('robot-fleet-7')}\n    maps:\n      '*': [read]\n"
    )
    access = Access.from_file(path)
    assert access.grant("robot-fleet-7").rights("any") == {"read"}
    assert access.grant("robot-fleet-8") is None and access.grant(None) is None


def test_failed_logins_count_against_the_rate_of_their_address(serve, building, tmp_path):
    """Guessing tokens goes no faster than the rate: past it, failed logins from the address
    get 429 (not 401), while a valid token from the same address goes on; after a second of
    rest a failed login is a 401 again."""
    path = tmp_path / "tokens.json"
    path.write_text(json.dumps(TOKENS))
    server = serve(access=Access.from_file(path), rate=5)
    guesses = [raw(server.url, "GET", "/v1/maps", None, f"guess-{i:04d}")[0] for i in range(30)]
    assert guesses[:10] == [401] * 10 and guesses[-1] == 429
    status, error = raw(server.url, "GET", "/v1/maps", None, "guess-last")
    assert status == 429 and "failed logins" in error["detail"]
    assert raw(server.url, "GET", "/v1/maps", None, READER)[0] == 200
    time.sleep(1.0)
    assert raw(server.url, "GET", "/v1/maps", None, "guess-rested")[0] == 401


def test_the_gate_counts_requests_per_token_and_failures_per_address():
    from semloc.serve.access import RIGHTS, Gate, Grant, Refused

    gate = Gate(Access({digest(READER): Grant("r", {"*": frozenset(RIGHTS)})}), rate=1)
    assert [gate.admit(READER, "10.0.0.1").name for _ in range(2)] == ["r", "r"]  # burst of 2
    with pytest.raises(Refused, match="requests a second"):
        gate.admit(READER, "10.0.0.2")  # the token's bucket, whatever the address
    for _ in range(2):
        with pytest.raises(Refused, match="unauthorized"):
            gate.admit("wrong-token", "10.0.0.1")
    with pytest.raises(Refused, match="failed logins"):
        gate.admit(None, "10.0.0.1")
    with pytest.raises(Refused, match="unauthorized"):
        gate.admit(None, "10.0.0.3")  # another address has its own bucket
