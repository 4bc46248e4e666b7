"""Outputs are all or nothing also when an interrupt lands right after a temporary file or
folder was created: it is removed, never left beside the outputs (in any thread layout: the
temporary is named for clean-up before it exists, no signal mask is relied on)."""

from __future__ import annotations

import os
import signal
from pathlib import Path

import pytest

from semloc.io import output


class Stop(Exception):
    """What the test's SIGINT handler raises (the CLI's raises `Interrupted`)."""


@pytest.fixture
def interrupt_after(monkeypatch):
    """`interrupt_after("open")`: the next creation of a hidden temporary file ("open") or
    folder ("mkdir") by `os` is followed at once by a SIGINT to this process, whose handler
    raises `Stop`."""
    previous = signal.signal(signal.SIGINT, lambda signum, frame: (_ for _ in ()).throw(Stop()))

    def arm(name: str) -> None:
        real = getattr(os, name)

        def created_then_interrupted(target, *args, **kwargs):
            made = real(target, *args, **kwargs)
            if Path(target).name.startswith("."):  # the temporary one, not another file
                os.kill(os.getpid(), signal.SIGINT)
            return made

        monkeypatch.setattr(os, name, created_then_interrupted)

    yield arm
    signal.signal(signal.SIGINT, previous)


def leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


@pytest.mark.parametrize("count", [1, 3])
def test_write_files_leaves_no_temporary_file(tmp_path, interrupt_after, count):
    interrupt_after("open")
    files = [(tmp_path / f"out{i}.json", "{}") for i in range(count)]
    with pytest.raises(Stop):
        output.write_files(files)
    assert leftovers(tmp_path) == []


def test_staged_folder_leaves_no_temporary_folder(tmp_path, interrupt_after):
    interrupt_after("mkdir")
    with pytest.raises(Stop), output.staged_folder(tmp_path / "out") as stage:
        (stage / "a.json").write_text("{}")
    assert leftovers(tmp_path) == []


def test_without_an_interrupt_the_files_are_written(tmp_path):
    output.write_files([(tmp_path / "a.json", "1"), (tmp_path / "b.json", "2")])
    assert leftovers(tmp_path) == ["a.json", "b.json"]
