"""`semloc export`: the global map and placed local objects as a PLY coloured by label."""

from __future__ import annotations

import json

import numpy as np

import semloc
from semloc.cli import main
from semloc.io.ply import read_ply
from semloc.pictures.colors import label_colors, rgb
from semloc.sim.layouts import layout, observe


def test_export_writes_global_and_placed_local_objects(tmp_path, capsys):
    g = layout(20, seed=2)
    obs = observe(g, 5, seed=3, spurious=0, wrong_label_rate=0.0, bias=(0.0, 0.0))
    semloc.save_map(g, tmp_path / "g.json")
    semloc.save_map(obs.local_map, tmp_path / "l.json")
    (tmp_path / "r.json").write_text(json.dumps({"pose": obs.T_global_local.tolist()}))
    out = tmp_path / "scene.ply"
    argv = ["export", str(tmp_path / "g.json"), "--result", str(tmp_path / "r.json"),
            "--local", str(tmp_path / "l.json"), "-o", str(out)]  # fmt: skip
    assert main(argv) == 0
    vertices = read_ply(out).vertices
    local = vertices[vertices["local"] == 1]
    glob = vertices[vertices["local"] == 0]
    global_points, _ = g.cloud()
    assert len(glob) == len(global_points)
    placed = obs.local_map.transformed(obs.T_global_local)
    xyz = np.stack([local["x"], local["y"], local["z"]], axis=1)
    np.testing.assert_allclose(xyz, placed.cloud()[0], atol=1e-4)
    colors = label_colors([*g.labels, *obs.local_map.labels])
    first = g[0]
    expected = rgb(colors[first.label])
    assert (glob["red"][0], glob["green"][0], glob["blue"][0]) == expected
    assert f"{len(g)} global objects and {len(obs.local_map)} local objects" in " ".join(
        capsys.readouterr().out.split()
    )
    assert main(["export", str(tmp_path / "g.json"), "-o", str(tmp_path / "a.ply"), "--ascii"]) == 0
    assert (tmp_path / "a.ply").read_bytes().startswith(b"ply\nformat ascii")


def test_export_needs_a_pose_for_local_objects(tmp_path, capsys):
    semloc.save_map(layout(5, seed=1), tmp_path / "g.json")
    argv = ["export", str(tmp_path / "g.json"), "--local", str(tmp_path / "g.json"), "-o", "x.ply"]
    assert main(argv) == 2
    assert "--local needs a --result" in capsys.readouterr().err
