"""Every command that writes files refuses an output that is one of its inputs, a points file
an input map names, or another output of the same run: one line, exit 2, nothing written."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
from format_fixtures import write_scan2cad
from helpers import room

import semloc
from semloc.cli import main
from semloc.maps import ObjectMap, SemanticObject


@pytest.fixture()
def folder(tmp_path, monkeypatch):
    """g.json (points in g.points.npz), l.json, c.json (settings), t.json and x.gt.json (a pose),
    r.json (a result), labels.json; the commands run in this folder."""
    a = room(12)
    rng = np.random.default_rng(0)
    objects = [o.replace(points=o.position + rng.normal(0, 0.1, (30, 3))) for o in a]
    semloc.save_map(ObjectMap(objects, up=[0, 0, 1]), tmp_path / "g.json", points="file")
    semloc.save_map(ObjectMap(list(a)[:6], up=[0, 0, 1]), tmp_path / "l.json")
    (tmp_path / "c.json").write_text('{"gamma": 0.8}\n')
    for name in ("t.json", "x.gt.json"):
        (tmp_path / name).write_text(json.dumps({"T_global_local": np.eye(4).tolist()}))
    (tmp_path / "r.json").write_text(
        json.dumps({"status": "localized", "pose": np.eye(4).tolist()})
    )
    (tmp_path / "labels.json").write_text('{"sofa": "couch"}')
    # inputs named with an output's suffix (view writes .png, export .ply): any name is read
    for name, source in (("r.ply", "r.json"), ("t.png", "t.json"), ("l.ply", "l.json"),
                         ("l.png", "l.json"), ("g.png", "l.json")):  # fmt: skip
        (tmp_path / name).write_bytes((tmp_path / source).read_bytes())
    monkeypatch.chdir(tmp_path)
    return tmp_path


def snapshot(folder) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.is_file()}


CASES = [
    (["localize", "g.json", "l.json", "--format", "json", "-o", "l.json"],
     "l.json: --output would overwrite the local map, an input"),
    (["localize", "g.json", "l.json", "-o", "./g.json"],
     "g.json: --output would overwrite the global map, an input"),
    (["localize", "g.json", "l.json", "-o", "g.points.npz"],
     "--output would overwrite the points file of the global map, an input"),
    (["localize", "g.json", "l.json", "--config", "c.json", "-o", "c.json"],
     "--output would overwrite the --config file, an input"),
    (["localize", "g.json", "l.json", "--gt", "t.json", "-o", "t.json"],
     "--output would overwrite the --gt file, an input"),
    (["localize", "g.json", "l.json", "--label-map", "labels.json", "-o", "labels.json"],
     "--output would overwrite the --label-map file, an input"),
    (["update-map", "g.json", "l.json", "-o", "l.json"],
     "l.json: --output would overwrite the local map, an input"),
    (["update-map", "g.json", "l.json", "-o", "g.json"],
     "g.json: --output would overwrite the global map, an input"),
    (["update-map", "g.json", "l.json", "-o", "g"],  # its points file would be g.points.npz
     "g.points.npz: --output would overwrite the points file of the global map, an input"),
    (["update-map", "g.json", "l.json", "--result", "r.json", "-o", "r.json"],
     "--output would overwrite the --result file, an input"),
    (["crop", "g.json", "--center", "1", "1", "1", "--radius", "3", "-o", "g.json"],
     "g.json: --output would overwrite MAP, an input"),
    (["crop", "g.json", "--center", "1", "1", "1", "--radius", "3", "-o", "x.json",
      "--transform", "x.gt.json"], "x.gt.json: --output would overwrite the --transform file"),
    (["config", "--dump", "--config", "c.json", "-o", "c.json"],
     "c.json: --output would overwrite the --config file, an input"),
    (["export", "g.json", "-o", "g.points.npz"], "--output writes a PLY point cloud"),
    (["export", "g.json", "--local", "l.ply", "--result", "r.json", "-o", "l.ply"],
     "l.ply: --output would overwrite the --local map, an input"),
    (["export", "g.json", "--local", "l.json", "--result", "r.ply", "-o", "r.ply"],
     "r.ply: --output would overwrite the --result file, an input"),
    (["view", "g.png", "-o", "g.png"], "g.png: --output would overwrite MAP, an input"),
    (["view", "g.json", "--result", "r.json", "--local", "l.png", "-o", "l.png"],
     "l.png: --output would overwrite the --local map, an input"),
    (["view", "g.json", "--gt", "t.png", "-o", "t.png"],
     "t.png: --output would overwrite the --gt file, an input"),
    (["align", "g.json", "l.json", "-o", "l.json"],
     "l.json: --output would overwrite map B, an input"),
    (["train-descriptor", "--out", "w.npz", "--fixture", "w.npz"],
     "w.npz: --output and --fixture would both write it"),
]  # fmt: skip


@pytest.mark.parametrize(("argv", "message"), CASES, ids=[" ".join(argv) for argv, _ in CASES])
def test_an_output_that_is_an_input_or_another_output_is_refused(folder, capsys, argv, message):
    before = snapshot(folder)
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("semloc: error: "), err
    assert message in err, err
    assert snapshot(folder) == before  # nothing written, nothing replaced


def test_a_link_to_an_input_is_the_input(folder, capsys):
    """A symlink or a hard link to an input names the same file."""
    os.symlink("l.json", folder / "soft.json")
    os.link(folder / "l.json", folder / "hard.json")
    before = snapshot(folder)
    for name in ("soft.json", "hard.json"):
        assert main(["localize", "g.json", "l.json", "--format", "json", "-o", name]) == 2
        assert "would overwrite the local map" in capsys.readouterr().err
    assert snapshot(folder) == before


def test_convert_refuses_its_input_and_two_outputs_of_one_file(folder, capsys):
    annotation = write_scan2cad(folder / "scene")
    before = snapshot(annotation.parent)
    argv = ["convert", "scan2cad", str(annotation)]
    assert main([*argv, "-o", str(annotation)]) == 2
    assert "--output would overwrite INPUT, an input" in capsys.readouterr().err
    assert main([*argv, "-o", "m.json", "--scan-output", "m.json"]) == 2
    assert "--output and --scan-output would both write it" in capsys.readouterr().err
    assert main([*argv, "-o", "m.json", "--scan-output", "m.points.npz"]) == 2
    assert "--output and --scan-output would both write it" in capsys.readouterr().err
    assert snapshot(annotation.parent) == before and not (folder / "m.json").exists()


def test_separate_outputs_are_written(folder, capsys):
    """The check refuses only real clashes: distinct files are written as before."""
    assert main(["localize", "g.json", "l.json", "--format", "json", "-o", "out.json"]) == 0
    assert json.loads((folder / "out.json").read_text())["status"]
    objects = [SemanticObject("x", "chair", [0, 0, 0])]
    semloc.save_map(ObjectMap(objects), folder / "one.json")
    assert main(["config", "--dump", "--config", "c.json", "-o", "c2.json"]) == 0


def test_view_refuses_two_outputs_of_one_file(folder, capsys):
    os.symlink("x.png", folder / "x.rrd")  # one file by two names
    before = snapshot(folder)
    assert main(["view", "g.json", "-o", "x.png", "--rrd", "x.rrd"]) == 2
    assert "x.rrd: --output and --rrd would both write it" in capsys.readouterr().err
    assert snapshot(folder) == before
