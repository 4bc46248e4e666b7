"""The demo on a real scan (semloc.tools.scandemo): localizes, writes its files, clear errors.

Needs the real samples (skips with a reason when absent); small images and few keyframes keep
it short, the default settings are checked by running `semloc demo --scan` itself.
"""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np
import pytest
from rich.console import Console

from semloc import schema
from semloc.eval.datasets import real_data_dir, real_sample
from semloc.io import write_atomic
from semloc.maps import MapError
from semloc.tools import scandemo
from semloc.tools.scandemo import ScanDemoConfig, resolve_scan, run_scan_demo


def test_scan2cad_demo_localizes_against_the_cad_map(tmp_path):
    if real_sample("scan2cad", "scene0470_00") is None:
        pytest.skip("real data sample scan2cad/scene0470_00 not found (set SEMLOC_DATA)")
    config = ScanDemoConfig(scan=Path("scan2cad/scene0470_00"), keyframes=30,
                            resolution=(120, 90), out=tmp_path)  # fmt: skip
    with open(tmp_path / "log.txt", "w") as log:
        demo = run_scan_demo(config, Console(file=log, width=100))
    assert demo.success and demo.result.status == "localized"
    assert demo.translation_error_m < 0.5 and demo.rotation_error_deg < 15
    for name in ("scores.png", "map.png", "scan.png", "global.json", "local.json"):
        assert (tmp_path / name).stat().st_size > 0
    truth = json.loads((tmp_path / "ground_truth.json").read_text())
    assert np.allclose(truth["T_global_local"], demo.sequence.T_global_local, atol=1e-6)
    assert truth["correspondences"]["cad"]
    result = json.loads((tmp_path / "result.json").read_text())
    assert result["status"] == "localized" and schema.problems(result) == []  # the one schema
    assert json.loads((tmp_path / "global.json").read_text())["name"] == "scene0470_00_cad"


def test_interrupted_writing_leaves_no_output_folder(tmp_path, monkeypatch):
    """Ctrl-C while the last file is written: the output folder is absent, not half-written."""
    if real_sample("scannet", "scene0000_00") is None:
        pytest.skip("real data sample scannet/scene0000_00 not found (set SEMLOC_DATA)")
    written = []

    def write_then_interrupt(path, data):
        written.append(path.name)
        if path.name == "ground_truth.json":
            raise KeyboardInterrupt
        return write_atomic(path, data)

    monkeypatch.setattr(scandemo, "write_atomic", write_then_interrupt)
    out = tmp_path / "out"
    config = ScanDemoConfig(scan=Path("scannet/scene0000_00"), keyframes=4, resolution=(40, 30),
                            out=out)  # fmt: skip
    with open(tmp_path / "log.txt", "w") as log, pytest.raises(KeyboardInterrupt):
        run_scan_demo(config, Console(file=log, width=100))
    assert written == ["result.json", "ground_truth.json"]  # the pictures and maps came before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["log.txt"]  # no out, no staging folder


def test_output_that_is_a_file_is_refused_before_the_walk(tmp_path):
    (tmp_path / "out").write_text("mine")
    config = ScanDemoConfig(scan=tmp_path / "no-scene", out=tmp_path / "out")
    with pytest.raises(MapError, match="out: exists and is not a folder"):
        run_scan_demo(config, Console(file=io.StringIO()))
    assert (tmp_path / "out").read_text() == "mine"


def test_missing_scan_folder_is_one_clear_error(tmp_path, monkeypatch):
    monkeypatch.setenv("SEMLOC_DATA", str(tmp_path))
    with pytest.raises(
        MapError, match=f"no such scene folder, nor under the data folder {tmp_path}"
    ):
        resolve_scan(Path("scannet/scene9999_00"))
    monkeypatch.setenv("SEMLOC_DATA", str(tmp_path / "absent"))
    with pytest.raises(MapError, match=r"no data folder \(\$SEMLOC_DATA"):
        resolve_scan(Path("scene9999_00"))


def test_short_names_are_found_in_the_data_folder():
    data = real_data_dir()
    if data is None or not (data / "scannet" / "scene0000_00").is_dir():
        pytest.skip("real data sample scannet/scene0000_00 not found (set SEMLOC_DATA)")
    assert resolve_scan(Path("scene0000_00")) == data / "scannet" / "scene0000_00"


def test_cli_demo_with_a_missing_scan_is_one_line_exit_2(tmp_path, monkeypatch, capsys):
    from semloc.cli import main

    monkeypatch.setenv("SEMLOC_DATA", str(tmp_path / "absent"))
    assert main(["demo", "--scan", "scene9999_00", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert err == ("semloc: error: --scan scene9999_00: no such scene folder, and no data folder "
                   "($SEMLOC_DATA or ../shared/data/real) exists")  # fmt: skip
