"""Exit statuses: `update-map` exits 1 when it writes nothing because the answer is not
localized; every command's `--help` lists its exit statuses."""

from __future__ import annotations

import pytest
from helpers import room
from typer.testing import CliRunner

import semloc
from semloc.cli import app, main
from semloc.maps import ObjectMap


def test_update_map_exits_1_when_not_localized(tmp_path, capsys):
    a = room(12)
    semloc.save_map(a, tmp_path / "g.json")
    semloc.save_map(ObjectMap(list(a)[:1]), tmp_path / "l.json")  # one object: `failed`
    out = tmp_path / "new.json"
    assert main(["update-map", str(tmp_path / "g.json"), str(tmp_path / "l.json"),
                 "-o", str(out)]) == 1  # fmt: skip
    assert "not localized (status failed): no map written" in capsys.readouterr().out
    assert not out.exists()


COMMANDS = sorted(info.name or info.callback.__name__.replace("_", "-")
                  for info in app.registered_commands)  # fmt: skip


@pytest.mark.parametrize("command", [c for c in COMMANDS if c != "serve"])
def test_every_command_lists_its_exit_statuses_in_its_help(command):
    text = " ".join(CliRunner().invoke(app, [command, "--help"], terminal_width=200).output.split())
    assert "Exit status: 0 " in text and "; 2 bad input or usage" in text, text
    assert "; 130 interrupted" in text
    assert ("; 1 nothing written: the answer is not localized" in text) == (command == "update-map")


def test_serve_lists_the_statuses_it_ends_with():
    """The service runs until a signal stops it: 130 (Ctrl-C) or 143 (SIGTERM), never 0."""
    text = " ".join(CliRunner().invoke(app, ["serve", "--help"], terminal_width=200).output.split())
    assert "Exit status: 2 bad input or usage" in text
    assert "130 stopped by Ctrl-C (SIGINT), 143 stopped by SIGTERM" in text
    assert "Exit status: 0" not in text and "; 0 " not in text
