"""A sweep of every command and command group: with no arguments, with `--help`, and with a
standard output whose reader closed it early (`semloc ... | head -1`).

What it holds: no empty `semloc: error: ` line, no non-zero exit without one line that says
why, no traceback.  A group without its command prints its help and one error line, exit 2; a
closed standard output ends the command quietly with its own status (0 when done).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest
import typer
from helpers import room

import semloc
from semloc.cli import app, main

RUN_WITHOUT_ARGUMENTS = {"demo", "bench", "train-descriptor", "descriptors-eval", "config",
                         "warmup", "serve"}  # fmt: skip
"""Commands that do their work with no arguments (so the sweep does not run them bare)."""


def _paths(command, prefix: tuple[str, ...] = ()) -> list[tuple[str, ...]]:
    """Every command path of the app: (), ("localize",), ("maps", "put"), ..."""
    found = [prefix]
    for name, sub in getattr(command, "commands", {}).items():
        found += _paths(sub, (*prefix, name))
    return found


ROOT = typer.main.get_command(app)
PATHS = _paths(ROOT)


def _command(path: tuple[str, ...]):
    command = ROOT
    for name in path:
        command = command.commands[name]
    return command


GROUPS = [p for p in PATHS if hasattr(_command(p), "commands")]


def _needs_arguments(path: tuple[str, ...]) -> bool:
    return any(getattr(param, "required", False) for param in _command(path).params)


def _error_lines(err: str) -> list[str]:
    return [line for line in err.splitlines() if line.startswith("semloc: error:")]


def test_the_sweep_sees_every_command():
    leaves = {" ".join(p) for p in PATHS if p not in GROUPS}
    assert {"localize", "maps put", "ros2 echo", "bag info", "simulate"} <= leaves
    assert {(), ("maps",), ("ros2",), ("bag",)} <= set(GROUPS)
    bare = {" ".join(p) for p in PATHS if p not in GROUPS and not _needs_arguments(p)}
    assert bare == RUN_WITHOUT_ARGUMENTS  # a new command that runs bare is named here


@pytest.mark.parametrize("path", PATHS, ids=lambda p: " ".join(p) or "semloc")
def test_help_is_status_0_and_no_error(path, capsys):
    assert main([*path, "--help"]) == 0
    out, err = capsys.readouterr()
    assert "Usage:" in out and err == "", err


@pytest.mark.parametrize("path", GROUPS, ids=lambda p: " ".join(p) or "semloc")
def test_a_group_without_its_command_prints_its_help_and_one_error_line(path, capsys):
    assert main(list(path)) == 2
    out, err = capsys.readouterr()
    assert "Usage:" in out and "Commands" in out
    where = " ".join(("semloc", *path))
    assert err.endswith(f"a command is needed: {where} COMMAND (listed above)\n"), err
    assert err.count("\n") == 1 and err.startswith("semloc: error: ")


@pytest.mark.parametrize(
    "path",
    [p for p in PATHS if p not in GROUPS and _needs_arguments(p)],
    ids=" ".join,
)
def test_a_command_without_its_arguments_says_what_is_missing(path, capsys):
    assert main(list(path)) == 2
    _, err = capsys.readouterr()
    assert err.count("\n") == 1 and err.startswith("semloc: error: "), err
    assert "Missing" in err and len(err.strip()) > len("semloc: error:") + 8, err


SWEEP = """
import os, sys, tempfile
from semloc.cli import main
results = []
for line in sys.argv[1:]:
    bare, _, name = line.partition(":")
    path = name.split()
    for args in ([*path, "--help"], path) if bare == "bare" else ([*path, "--help"],):
        read, write = os.pipe()
        os.close(read)  # the reader went away before anything was written
        saved_out, saved_err = os.dup(1), os.dup(2)
        os.dup2(write, 1)
        with tempfile.TemporaryFile("w+") as err:
            os.dup2(err.fileno(), 2)
            status = main(args)
            sys.stdout.flush() if not sys.stdout.closed else None
            os.dup2(saved_out, 1); os.dup2(saved_err, 2)
            err.seek(0)
            results.append({"args": args, "status": status, "err": err.read()})
        os.close(write); os.close(saved_out); os.close(saved_err)
print(__import__("json").dumps(results))
"""


def test_a_closed_stdout_ends_quietly_with_the_commands_own_status():
    """`--help` with stdout closed: status 0, nothing on stderr; a group without its command:
    status 2 and its one error line; never a traceback (one process for the whole sweep)."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    names = [("bare:" if p in GROUPS or _needs_arguments(p) else "help:") + " ".join(p)
             for p in PATHS]  # fmt: skip
    done = subprocess.run([sys.executable, "-c", SWEEP, *names], env=env, capture_output=True,
                          text=True, timeout=600)  # fmt: skip
    assert done.returncode == 0, done.stderr
    results = json.loads(done.stdout)
    for found in results:
        args, status, err = found["args"], found["status"], found["err"]
        assert "Traceback" not in err, (args, err)
        if args and args[-1] == "--help":
            assert (status, err) == (0, ""), found
        else:  # bare: a group's or a command's missing arguments, one line
            assert status == 2 and err.count("\n") == 1, found
            assert err.startswith("semloc: error: ") and len(err) > 20, found


def test_localize_into_a_closed_pipe_finishes_with_status_0(tmp_path):
    """`semloc localize G L | head -1`: the reader leaves after its line; semloc finishes
    quietly (no traceback, no error line) with its status, 0."""
    semloc.save_map(room(12), tmp_path / "g.json")
    semloc.save_map(room(12), tmp_path / "l.json")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    command = [sys.executable, "-m", "semloc", "localize", str(tmp_path / "g.json"),
               str(tmp_path / "l.json")]  # fmt: skip
    proc = subprocess.Popen(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)  # fmt: skip
    first = proc.stdout.readline()
    proc.stdout.close()
    err = proc.stderr.read()
    assert proc.wait(timeout=600) == 0, err
    assert first.startswith("status: ")
    assert "Traceback" not in err and "error" not in err, err


def test_out_is_still_taken_as_output(tmp_path, capsys):
    """`--out` (the old name of demo's, bench's, train-descriptor's and descriptors-eval's
    output) is read as `--output`; `--help` shows only `-o/--output`."""
    from semloc.cli.app import with_optional_values

    assert with_optional_values(["demo", "--out", "x"]) == ["demo", "--output", "x"]
    assert with_optional_values(["bench", "--out=x"]) == ["bench", "--output=x"]
    for command in ("demo", "bench", "train-descriptor", "descriptors-eval"):
        assert main([command, "--help"]) == 0
        text = capsys.readouterr().out
        assert "--output" in text and "-o" in text and "--out " not in text, command


def test_arguments_are_named_in_capitals(capsys):
    assert main(["localize", "--help"]) == 0
    assert "{GLOBAL_MAP} {LOCAL_MAP}" in capsys.readouterr().out
    assert main(["simulate"]) == 2
    assert "Missing argument 'OUT'" in capsys.readouterr().err
