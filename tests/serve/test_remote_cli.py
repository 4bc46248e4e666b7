"""`semloc localize --server` and `semloc update-map --server` against a live server."""

from __future__ import annotations

import json

import pytest
from conftest import T_TRUE, view
from test_api import _moved_view

from semloc.cli import main
from semloc.client import Client
from semloc.io import load_map, save_map
from semloc.serve.access import Access

TOKEN = "cli-token-1234"


@pytest.fixture
def office(serve, building, tmp_path):
    tokens = tmp_path / "tokens.json"
    tokens.write_text(
        json.dumps({"tokens": [{"token": TOKEN, "maps": {"*": ["read", "localize", "write"]}}]})
    )
    server = serve(access=Access.from_file(tokens))
    Client(server.url, TOKEN).put_map("office", building)
    return server


def test_localize_on_a_server_prints_and_writes_its_answer(
    office, building, tmp_path, capsys, monkeypatch
):
    local = tmp_path / "local.json"
    save_map(view(building, [3, 4, 5, 6, 7, 8, 9], T_TRUE), local)
    out = tmp_path / "answer.json"
    argv = ["localize", "office", str(local), "--server", office.url, "--token", TOKEN]
    assert main([*argv, "--format", "json", "-o", str(out)]) == 0
    answer = json.loads(out.read_text())
    served = Client(office.url, TOKEN).localize("office", load_map(local))
    assert answer["status"] == "localized" and answer["map_version"] == 1
    assert answer["pose"] == served["pose"] and answer["hypotheses"] == served["hypotheses"]
    monkeypatch.setenv("SEMLOC_TOKEN", TOKEN)
    assert main(["localize", "office", str(local), "--server", office.url]) == 0
    text = capsys.readouterr().out
    assert "status: localized" in text and "version 1" in text and "labels" in text


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--gamma", "0.7"], "--gamma: with --server the server's settings apply"),
        (["--server", "ftp://x"], "--server: server URL must be http(s)://host[:port]"),
    ],
)
def test_local_settings_and_bad_urls_are_refused(
    office, building, tmp_path, capsys, extra, message
):
    local = tmp_path / "local.json"
    save_map(view(building, [3, 4, 5], T_TRUE), local)
    argv = ["localize", "office", str(local), "--server", office.url, "--token", TOKEN, *extra]
    assert main(argv) == 2
    assert message in capsys.readouterr().err


def test_server_refusals_are_one_line(office, building, tmp_path, capsys):
    local = tmp_path / "local.json"
    save_map(view(building, [3, 4, 5], T_TRUE), local)
    assert main(["localize", "nowhere", str(local), "--server", office.url, "--token", TOKEN]) == 2
    assert "localize refused: 404 not found" in capsys.readouterr().err
    assert main(["localize", "office", str(local), "--server", office.url]) == 2
    assert "401 unauthorized" in capsys.readouterr().err
    assert main(["localize", "office", str(local), "--server", "http://127.0.0.1:9"]) == 2
    err = capsys.readouterr().err
    assert "cannot reach the server" in err and len(err.strip().splitlines()) == 1


def test_update_map_on_a_server_writes_the_next_version(office, building, tmp_path, capsys):
    local = tmp_path / "local.json"
    save_map(_moved_view(building), local)
    copy = tmp_path / "office_v2.json"
    argv = ["update-map", "office", str(local), "--server", office.url, "--token", TOKEN]
    assert main([*argv, "-o", str(copy)]) == 0
    assert "version 2 written" in capsys.readouterr().out
    client = Client(office.url, TOKEN)
    assert [v["version"] for v in client.versions("office")] == [1, 2]
    assert load_map(copy).get("7").extra["moved_m"] > 0.5
    assert main(argv) == 1  # the same view again: nothing left to change
    assert "stays at version 2" in capsys.readouterr().out
    ambiguous = tmp_path / "ambiguous.json"
    save_map(view(building, [0, 1, 2], T_TRUE), ambiguous)
    assert (
        main(["update-map", "office", str(ambiguous), "--server", office.url, "--token", TOKEN])
        == 1
    )
    assert "not localized (status ambiguous): no version written" in capsys.readouterr().out
    assert [v["version"] for v in client.versions("office")] == [1, 2]


def test_update_map_needs_an_output_without_a_server(building, tmp_path, capsys):
    local = tmp_path / "local.json"
    save_map(view(building, [3, 4, 5], T_TRUE), local)
    save_map(building, tmp_path / "global.json")
    assert main(["update-map", str(tmp_path / "global.json"), str(local)]) == 2
    assert "--output / -o is needed" in capsys.readouterr().err
