"""A command whose optional extra is missing exits 2 with one line naming the extra."""

from __future__ import annotations

import pytest

from semloc.cli import extras, main


@pytest.mark.parametrize(
    "args, absent, extra",
    [
        (["demo"], "open3d", "sim"),
        (["demo"], "matplotlib", "viz"),
        (["simulate", "out"], "open3d", "sim"),
        (["view", "map.json"], "matplotlib", "viz"),
        (["bench", "--quick"], "dask", "bench"),
        (["bench", "--quick"], "open3d", "sim"),
        (["train-descriptor"], "torch", "train"),
        (["descriptors-eval"], "open3d", "sim"),
    ],
)
def test_missing_extra_is_named(args, absent, extra, monkeypatch, capsys, tmp_path):
    monkeypatch.chdir(tmp_path)
    real = extras.missing
    monkeypatch.setattr(extras, "missing", lambda module: module == absent or real(module))
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"semloc: error: semloc {args[0]} needs")
    assert f"{absent} is not installed" in err and f"pip install 'semloc[{extra}]'" in err
    assert not (tmp_path / "out").exists()


def test_missing_checks_without_importing():
    assert extras.missing("surely_no_such_module_here")
    assert not extras.missing("numpy")
