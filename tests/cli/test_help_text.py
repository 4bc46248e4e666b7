"""`--help` of every command and group: flags show no `<bool>` metavar (they take no value),
and options that take one still show its type."""

from __future__ import annotations

import typer
from typer.testing import CliRunner

from semloc.cli import app


def _paths(command, prefix: tuple[str, ...] = ()) -> list[tuple[str, ...]]:
    """Every command path of the app: (), ("localize",), ("maps", "put"), ..."""
    found = [prefix]
    for name, sub in getattr(command, "commands", {}).items():
        found += _paths(sub, (*prefix, name))
    return found


def test_no_flag_shows_a_bool_metavar():
    paths = _paths(typer.main.get_command(app))
    assert ("maps", "put") in paths and ("bench",) in paths
    for path in paths:
        text = CliRunner().invoke(app, [*path, "--help"], terminal_width=200).output
        assert "--help" in text, path
        assert "<bool>" not in text, (path, text)
    bench = CliRunner().invoke(app, ["bench", "--help"], terminal_width=200).output
    assert "<int range>" in bench and "<path>" in bench  # valued options keep their type
