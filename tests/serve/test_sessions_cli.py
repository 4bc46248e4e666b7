"""`semloc sessions list | show | end` against a live server, and a 404 for a map the token
may not see that says so."""

from __future__ import annotations

import json

import pytest
from conftest import T_TRUE, view

from semloc.cli import main
from semloc.client import Client, ServerError
from semloc.serve.access import Access

DEVICE, OTHER, LAB_ONLY = "device-token-1", "other-device-2", "lab-only-token"
WRITER = "map-writer-token"


@pytest.fixture
def hub(serve, tmp_path):
    tokens = tmp_path / "tokens.json"
    tokens.write_text(json.dumps({"tokens": [
        {"token": DEVICE, "maps": {"*": ["read", "localize"]}},
        {"token": OTHER, "maps": {"*": ["read", "localize"]}},
        {"token": LAB_ONLY, "maps": {"lab": ["read"]}},
        {"token": WRITER, "maps": {"*": ["write"]}},
    ]}))  # fmt: skip
    server = serve(access=Access.from_file(tokens))
    return server.url


def _sessions(url: str, token: str, *args: str) -> int:
    return main(["sessions", *args, "--server", url, "--token", token])


def test_list_show_end(hub, building, capsys):
    admin = Client(hub, DEVICE)
    Client(hub, WRITER).put_map("office", building)
    local = view(building, [3, 4, 5, 6, 7, 8, 9], T_TRUE)
    mine = admin.session("office", up=local.up.tolist())
    mine.update(list(local), stamp=3.0)
    Client(hub, OTHER).session("office")
    assert _sessions(hub, DEVICE, "list", "office") == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 2
    own = next(line for line in lines if line.endswith("\tmine")).split("\t")
    assert own[0] == mine.session_id and own[1] == "localized"
    assert any(line.startswith("-\t") and line.endswith("another token's") for line in lines)
    assert _sessions(hub, DEVICE, "show", "office", mine.session_id) == 0
    shown = json.loads(capsys.readouterr().out)
    assert shown["session_id"] == mine.session_id and shown["last"]["status"] == "localized"
    assert _sessions(hub, OTHER, "end", mine.session_id) == 2  # not its session
    assert "404" in capsys.readouterr().err
    assert _sessions(hub, DEVICE, "end", mine.session_id) == 0
    assert f"ended session {mine.session_id}" in capsys.readouterr().out
    assert _sessions(hub, DEVICE, "show", "office", mine.session_id) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no live session" in err


def test_a_map_the_token_may_not_see_is_404_and_says_so(hub, building, capsys):
    Client(hub, WRITER).put_map("office", building)
    assert main(["maps", "versions", "office", "--server", hub, "--token", LAB_ONLY]) == 2
    err = capsys.readouterr().err
    assert "404 not found: map 'office' (or your token may not see it)" in err, err
    assert main(["maps", "versions", "nowhere", "--server", hub, "--token", DEVICE]) == 2
    assert "404 not found: map 'nowhere' (or your token may not see it)" in capsys.readouterr().err


def test_maps_delete_needs_write_and_yes_and_numbers_go_on(hub, building, tmp_path, capsys):
    writer = Client(hub, WRITER)
    writer.put_map("office", building)
    writer.put_map("office", building)
    session = Client(hub, DEVICE).session("office")
    args = ["maps", "delete", "office", "--server", hub]
    assert main([*args, "--token", WRITER]) == 2  # no --yes: nothing deleted
    assert "add --yes" in capsys.readouterr().err
    assert main([*args, "--yes", "--token", DEVICE]) == 2  # read and localize, no write
    assert "403" in capsys.readouterr().err
    assert main([*args, "--yes", "--token", WRITER]) == 0
    assert "deleted office" in capsys.readouterr().out
    reader = Client(hub, DEVICE)
    assert reader.maps() == []
    with pytest.raises(ServerError) as gone:
        reader.get_map("office")
    assert gone.value.status == 404
    with pytest.raises(ServerError) as ended:
        session.update([], stamp=1.0)
    assert ended.value.status == 404
    assert main([*args, "--yes", "--token", WRITER]) == 2  # deleted already
    assert "404 not found: map 'office'" in capsys.readouterr().err
    assert writer.put_map("office", building) == 3  # a number never names two documents
    assert [v["version"] for v in reader.versions("office")] == [3]
    assert reader.get_map("office").ids.tolist() == building.ids.tolist()


def test_a_new_id_never_starts_with_a_dash(monkeypatch):
    """A session id starting with "-" was read as an option by `semloc sessions show`."""
    from semloc.serve import service

    drawn = iter(["-jcuolRcH4g9AFeo0pEHihv8", "--cuolRcH4g9AFeo0pEHihv", "jcuolRcH4g9AFeo0pEHihv8"])
    monkeypatch.setattr(service.secrets, "token_urlsafe", lambda n: next(drawn))
    assert service.new_id() == "jcuolRcH4g9AFeo0pEHihv8"
