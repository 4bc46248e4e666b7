"""What a new user meets first (issue 39, item 8): the JSON says whether its pose is an answer,
help and tables fit 80 columns, the warm-up is reported apart and announced when it compiles,
the pictures of a real scene are readable (labels, distinct colours, zoom, error, rivals), and
a scene's mesh given to `convert scannet` finds its scene."""

from __future__ import annotations

import itertools
import json
import re

import numba
import numpy as np
import pytest
import typer.main
from format_fixtures import write_scannet
from rich.console import Console

import semloc
from semloc import compiling as warmup_module
from semloc.cli import app, main
from semloc.cli.files import ResultFile
from semloc.cli.render import print_result, timing_line
from semloc.cli.simulation import _heading
from semloc.compiling import COMPILING, WarmUp, compile_notice, warm_up
from semloc.io import load_map
from semloc.pictures.colors import color_distance, label_colors
from semloc.results import Hypothesis, Result, Step
from semloc.sim.layouts import layout, observe
from semloc.transforms import yaw_pose


@pytest.fixture(scope="module")
def maps(tmp_path_factory):
    folder = tmp_path_factory.mktemp("maps")
    g = layout(40, seed=3)
    obs = observe(g, 6, seed=2, spurious=0, wrong_label_rate=0.0, bias=(0.0, 0.05))
    semloc.save_map(g, folder / "global.json")
    semloc.save_map(obs.local_map, folder / "local.json")
    return folder, obs


# The JSON of localize: reason, confidence, and whether the pose is an answer ------------------
def test_json_has_reason_confidence_and_marks_the_pose(maps, capsys):
    folder, _ = maps
    argv = ["localize", str(folder / "global.json"), str(folder / "local.json"), "--format", "json"]
    assert main(argv) == 0
    out = json.loads(capsys.readouterr().out)
    assert {"status", "pose", "hypotheses", "steps", "timing_ms"} <= set(
        out
    )  # docs/contracts.md's keys
    assert out["pose_is_answer"] is (out["status"] == "localized")
    assert out["confidence"] == out["hypotheses"][0]["confidence"]
    assert isinstance(out["reason"], str) and out["warm_up_ms"] > 0


def test_an_ambiguous_pose_is_not_an_answer():
    h = Hypothesis(1, 2.0, [("a", "1"), ("b", "2")], yaw_pose(0.3), confidence=0.4)
    ambiguous = Result.of("ambiguous", [h], [], {}, "too few pairs")
    assert ambiguous.pose is not None and not ambiguous.pose_is_answer
    document = ambiguous.to_dict()
    assert document["pose_is_answer"] is False and document["reason"] == "too few pairs"
    assert document["confidence"] == 0.4
    assert Result.of("localized", [h], [], {}).pose_is_answer
    assert Result.of("failed", [], [], {}, "no sets").to_dict()["confidence"] is None


# 80 columns: help and the hypotheses table ----------------------------------------------------
COMMANDS = list(typer.main.get_command(app).commands)


@pytest.mark.parametrize("command", ["", *COMMANDS])
def test_help_fits_80_columns(command, monkeypatch, capsys):
    """Nothing is cut short: no ellipsis, and every option's names appear whole."""
    monkeypatch.setenv("COLUMNS", "80")
    assert main([*([command] if command else []), "--help"]) == 0
    text = capsys.readouterr().out
    assert "…" not in text, text
    assert max(len(line) for line in text.splitlines()) <= 80
    params = typer.main.get_command(app).commands[command].params if command else []
    for name in (n for p in params for n in [*p.opts, *p.secondary_opts] if n.startswith("--")):
        assert re.search(rf"{re.escape(name)}\b", text), name


def test_hypotheses_table_keeps_its_last_column_at_80_columns():
    pairs = [(f"g{i}", f"l{i}") for i in range(6)]
    hypotheses = [Hypothesis(r, 9.0, pairs, yaw_pose(0.1 * r), fitness=0.9, confidence=0.9)
                  for r in (1, 2)]  # fmt: skip
    out = Console(record=True, width=80)
    print_result(Result.of("localized", hypotheses, [], {}), out)
    text = out.export_text()
    assert "…" not in text and max(len(line) for line in text.splitlines()) <= 80
    found = re.findall(r"l\d→g\d", text)
    assert sorted(found) == sorted([f"{lid}→{gid}" for gid, lid in pairs] * 2)


# Warm-up: announced when it compiles, reported apart from the updates -------------------------
def test_timing_reports_the_warm_up_apart():
    steps = [Step(i, i + 1, 3, [1.0], ms) for i, ms in enumerate([2.0, 4.0, 3.0])]
    result = Result.of("localized", [], steps, {"total": 9.0})
    assert timing_line(result) == "3 updates: 9.0 ms in all, 3.0 ms per update (median)"
    loading = timing_line(result, WarmUp(0.31, compiled=False))
    assert loading.endswith("; before them, 0.31 s loading the compiled code (once per process)")
    assert "compiling the inner loops (once after install)" in timing_line(
        result, WarmUp(40.0, compiled=True)
    )


def test_a_compilation_of_semlocs_code_is_announced_once_and_a_load_not_at_all(monkeypatch):
    monkeypatch.setattr(warmup_module._NOTICE, "shown", False)  # as in a new process
    scope = {"__name__": "semloc.stand_in", "numba": numba}  # a new function of semloc's
    exec("@numba.njit\ndef twice(x):\n    return 2 * x\n", scope)

    @numba.njit  # a new function of someone else's: not announced
    def plus_one(x):
        return x + 1

    said = []
    with compile_notice(said.append) as compiled:
        assert plus_one(1) == 2 and not compiled.shown and said == []
        assert scope["twice"](2) == 4 and scope["twice"](2.5) == 5.0  # two compilations
    assert said == [COMPILING] and compiled.shown  # one notice
    warm_up()  # whatever the cache held, everything is loaded now
    again = []
    warm = warm_up(again.append)
    assert again == [] and not warm.compiled  # loaded, not compiled: no notice


def test_localize_text_separates_warm_up_from_updates(maps, capsys):
    folder, _ = maps
    assert main(["localize", str(folder / "global.json"), str(folder / "local.json")]) == 0
    text = " ".join(capsys.readouterr().out.split())
    assert re.search(r"\d+ updates: [\d.]+ ms in all, [\d.]+ ms per update \(median\); "
                     r"before them, [\d.]+ s (loading|compiling)", text), text  # fmt: skip


# Pictures of a real scene -----------------------------------------------------------------------
SCANNET_LABELS = [
    "backpack", "bed", "bookshelf", "cabinet", "clock", "couch", "counter", "curtain", "desk",
    "dishrack", "door", "guitar", "laundry basket", "microwave", "nightstand", "pillow",
    "refrigerator", "scale", "shower", "sink", "stool", "table", "tissue box", "toaster",
    "toaster oven", "toilet", "towel", "trashcan", "tv", "window",
]  # fmt: skip
"""The 30 labels of ScanNet's scene0000_00 as `semloc convert scannet` gives them."""


@pytest.mark.parametrize("labels", [SCANNET_LABELS, [f"class {i}" for i in range(30)]])
def test_thirty_labels_get_clearly_different_colours(labels):
    """CIE76 ΔE of at least 20 between any two labels' colours (about 2 is noticeable)."""
    colors = label_colors(labels)
    closest = min(color_distance(a, b) for a, b in itertools.combinations(colors.values(), 2))
    assert closest >= 20, closest


def _texts(ax) -> list[str]:
    return [t.get_text() for t in ax.texts] + [t.get_text() for t in ax.get_legend().get_texts()]


def test_view_draws_labels_zooms_to_the_local_objects_and_draws_rivals(maps):
    pytest.importorskip("matplotlib")
    from semloc.pictures.viz import ZOOM_MARGIN, map_figure, plot_localization

    folder, obs = maps
    g, local = load_map(folder / "global.json"), load_map(folder / "local.json")
    truth = obs.T_global_local
    rival = yaw_pose(1.0, truth[:3, 3] + [1.0, 0.5, 0.0])
    fig, ax = map_figure(g.positions[:, :2])
    plot_localization(ax, g, local, truth, [], true_pose=truth, names=True, zoom=True,
                      rivals=[(rival, [])])  # fmt: skip
    texts = _texts(ax)
    assert set(g.labels) <= set(texts)  # every label written beside its objects
    assert "rival (rank 2)" in texts and "rival place (another hypothesis)" in texts
    placed = np.vstack([local.transformed(T).positions for T in (truth, rival)])[:, :2]
    low, high = placed.min(axis=0) - ZOOM_MARGIN, placed.max(axis=0) + ZOOM_MARGIN
    assert np.allclose([*ax.get_xlim(), *ax.get_ylim()], [low[0], high[0], low[1], high[1]])


def test_view_title_has_the_error_against_the_truth(maps):
    folder, obs = maps
    g = load_map(folder / "global.json")
    truth = obs.T_global_local
    off = truth @ yaw_pose(np.radians(2.0), [0.1, 0.0, 0.0])
    title = _heading(folder / "global.json", g, ResultFile(off, "localized"), truth)
    assert title.startswith(f"global.json: {len(g)} objects (localized)\nerror 2.00°, 0.100 m")
    assert title.endswith("success at 15° / 0.5 m")
    assert "error" not in _heading(folder / "global.json", g, ResultFile(off), None)


def test_view_of_an_ambiguous_result_with_gt_end_to_end(maps, tmp_path, capsys):
    pytest.importorskip("matplotlib")
    folder, obs = maps
    truth, rival = obs.T_global_local, yaw_pose(1.0, [1.0, 2.0, 0.0])
    answer = {"status": "ambiguous", "pose": truth.tolist(),
              "hypotheses": [{"pairs": [], "pose": truth.tolist()},
                             {"pairs": [], "pose": rival.tolist()}]}  # fmt: skip
    (tmp_path / "r.json").write_text(json.dumps(answer))
    (tmp_path / "gt.json").write_text(json.dumps({"T_global_local": truth.tolist()}))
    argv = ["view", str(folder / "global.json"), "--result", str(tmp_path / "r.json"),
            "--local", str(folder / "local.json"), "--gt", str(tmp_path / "gt.json"),
            "-o", str(tmp_path / "v.png")]  # fmt: skip
    assert main(argv) == 0
    assert (tmp_path / "v.png").stat().st_size > 10_000


# convert scannet given one of the scene's files --------------------------------------------------
def test_convert_scannet_given_the_mesh_converts_its_scene(tmp_path, capsys):
    write_scannet(tmp_path / "scene")
    mesh = tmp_path / "scene" / "scene0001_00_vh_clean_2.ply"
    assert main(["convert", "scannet", str(mesh), "-o", str(tmp_path / "a.json")]) == 0
    assert (
        main(["convert", "scannet", str(tmp_path / "scene"), "-o", str(tmp_path / "b.json")]) == 0
    )
    a, b = load_map(tmp_path / "a.json"), load_map(tmp_path / "b.json")
    assert list(a.ids) == list(b.ids) and np.allclose(a.positions, b.positions)
    (tmp_path / "scene" / "scene0001_00.aggregation.json").unlink()
    capsys.readouterr()
    assert main(["convert", "scannet", str(mesh), "-o", str(tmp_path / "c.json")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "vh_clean_2_vh_clean_2" not in err
    assert "no scene0001_00*.aggregation.json beside it" in err
