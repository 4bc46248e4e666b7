"""`semloc localize` end to end: JSON contract, text output, exit codes, one-line errors."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from helpers import room
from hypothesis import given, settings
from hypothesis import strategies as st
from rich.console import Console

import semloc
from semloc import ObjectMap, save_map
from semloc.cli import main
from semloc.cli.app import CliError
from semloc.cli.files import read_label_map
from semloc.cli.render import print_result
from semloc.results import Hypothesis, Result
from semloc.sim.layouts import layout, observe
from semloc.transforms import yaw_pose


@pytest.fixture(scope="module")
def maps(tmp_path_factory):
    folder = tmp_path_factory.mktemp("maps")
    g = layout(60, seed=5)
    obs = observe(g, 8, seed=8, spurious=0, wrong_label_rate=0.0, bias=(0.0, 0.05))
    semloc.save_map(g, folder / "global.json")
    semloc.save_map(obs.local_map, folder / "local.json")
    return folder, obs


def test_json_output_follows_the_contract(maps, capsys):
    folder, obs = maps
    assert main(["localize", str(folder / "global.json"), str(folder / "local.json"),
                 "--format", "json"]) == 0  # fmt: skip
    out = json.loads(capsys.readouterr().out)
    assert {"status", "pose", "hypotheses", "steps", "timing_ms", "changes", "labels"} <= set(out)
    assert out["pose_is_answer"] is True and out["reason"] == "" and out["confidence"] > 0.5
    assert out["changes"] == {"moved": [], "new": [], "missing": []}
    assert out["status"] == "localized"
    np.testing.assert_allclose(np.array(out["pose"]), obs.T_global_local, atol=0.1)
    first = out["hypotheses"][0]
    assert {"rank", "score", "pairs", "pose", "fitness"} <= set(first)
    assert first["rank"] == 1
    assert {(p["global"], p["local"]) for p in first["pairs"]} == set(obs.true_pairs)
    assert [s["step"] for s in out["steps"]] == list(range(8))
    assert {"step", "n_local", "n_sets", "top_scores", "ms"} <= set(out["steps"][0])
    assert out["timing_ms"]["total"] > 0


def test_text_output_and_output_file(maps, capsys, tmp_path):
    folder, _ = maps
    args = ["localize", str(folder / "global.json"), str(folder / "local.json"), "--top-k", "3"]
    assert main(args) == 0
    text = capsys.readouterr().out
    assert "status: localized" in text and "hypotheses" in text and "T_global_local" in text
    target = tmp_path / "r.json"
    assert main([*args, "--format", "json", "-o", str(target)]) == 0
    assert len(json.loads(target.read_text())["hypotheses"]) <= 3
    assert main([*args, "-o", str(tmp_path / "r.txt")]) == 0
    assert "status: localized" in (tmp_path / "r.txt").read_text()


def test_settings_file_and_options(maps, capsys, tmp_path):
    folder, _ = maps
    settings = tmp_path / "s.json"
    settings.write_text(json.dumps({"clustering": {"sets_per_object": 5}, "margin": 0.1}))
    args = ["localize", str(folder / "global.json"), str(folder / "local.json")]
    assert main([*args, "--config", str(settings), "--gamma", "0.85", "--format", "json"]) == 0
    assert json.loads(capsys.readouterr().out)["status"] == "localized"


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--gamma", "1.5"], "gamma"),
        (["--format", "xml"], "xml"),
        (["--top-k", "0"], "top_k"),
        (["--config", "/nonexistent/s.json"], "file not found"),
    ],
)
def test_bad_options_exit_2_with_one_line(maps, capsys, extra, message):
    folder, _ = maps
    code = main(["localize", str(folder / "global.json"), str(folder / "local.json"), *extra])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert len(err.splitlines()) == 1 and err.startswith("semloc: error:") and message in err


def test_bad_map_exits_2_naming_the_file(tmp_path, maps, capsys):
    folder, _ = maps
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": "semloc-map", "version": 1, "objects": [{"id": "a"}]}')
    assert main(["localize", str(folder / "global.json"), str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(bad) in err and "missing key 'label'" in err


def test_valid_input_that_cannot_localize_exits_0(tmp_path, maps, capsys):
    folder, _ = maps
    local = tmp_path / "aliens.json"
    semloc.save_map(semloc.ObjectMap([semloc.SemanticObject("x", "ufo", [0, 0, 0])]), local)
    assert main(["localize", str(folder / "global.json"), str(local), "--format", "json"]) == 0
    assert json.loads(capsys.readouterr().out)["status"] == "failed"


@pytest.mark.slow
def test_console_script_has_no_traceback(tmp_path):
    bad = tmp_path / "x.json"
    bad.write_text("{")
    run = subprocess.run(
        [sys.executable, "-m", "semloc.cli", "localize", str(bad), str(bad)],
        capture_output=True,
        text=True,
    )
    assert run.returncode == 2
    assert "Traceback" not in run.stderr and "not valid JSON" in run.stderr
    missing = subprocess.run(
        [sys.executable, "-m", "semloc.cli", "localize"], capture_output=True, text=True
    )
    assert missing.returncode == 2 and "Traceback" not in missing.stderr


def test_settings_file_is_kept_unless_an_option_overrides_it(maps, capsys, tmp_path):
    folder, _ = maps
    settings = tmp_path / "s.json"
    settings.write_text(json.dumps({"top_k": 1}))
    args = ["localize", str(folder / "global.json"), str(folder / "local.json"),
            "--config", str(settings), "--format", "json"]  # fmt: skip
    assert main(args) == 0
    assert len(json.loads(capsys.readouterr().out)["hypotheses"]) == 1
    assert main([*args, "--top-k", "3"]) == 0
    assert len(json.loads(capsys.readouterr().out)["hypotheses"]) == 3


def _with_box_points(objects, rng):
    """Objects with points on the surface of their boxes (0.4-1.2 m), so descriptors exist."""
    out = []
    for obj in objects:
        size = rng.uniform(0.4, 1.2, 3)
        p = rng.uniform(-0.5, 0.5, (300, 3)) * size
        axis = rng.integers(0, 3, 300)
        p[np.arange(300), axis] = np.sign(rng.uniform(-1, 1, 300)) * size[axis] / 2
        out.append(obj.replace(points=p + obj.position))
    return out


def test_descriptor_gate_from_the_command_line(tmp_path, capsys):
    rng = np.random.default_rng(3)
    g = layout(40, seed=2)
    g = semloc.ObjectMap(_with_box_points(g, rng), up=g.up)
    obs = observe(g, 6, seed=4, spurious=0, wrong_label_rate=0.0, bias=(0.0, 0.0))
    T = obs.T_global_local
    local = [o.replace(points=(g.get(gid).points - T[:3, 3]) @ T[:3, :3])
             for o in obs.local_map for gid, lid in obs.true_pairs if lid == o.id]  # fmt: skip
    semloc.save_map(g, tmp_path / "global.json")
    semloc.save_map(semloc.ObjectMap(local, up=obs.local_map.up), tmp_path / "local.json")
    args = ["localize", str(tmp_path / "global.json"), str(tmp_path / "local.json"),
            "--format", "json"]  # fmt: skip
    assert main([*args, "--descriptor", "geometric"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["status"] == "localized"
    np.testing.assert_allclose(np.array(out["pose"]), T, atol=0.05)
    assert main([*args, "--descriptor", "geometric", "--descriptor-delta", "0.05"]) == 0
    assert json.loads(capsys.readouterr().out)["status"] == "localized"
    # objects twice their map size: same places, other shapes; a tight gate removes them all
    grown = [o.replace(points=2.0 * (o.points - o.position) + o.position) for o in local]
    semloc.save_map(semloc.ObjectMap(grown, up=obs.local_map.up), tmp_path / "local.json")
    assert main(args) == 0
    # the associations are among the answers, but the points do not land on the map: not claimed
    out = json.loads(capsys.readouterr().out)
    best = out["hypotheses"][0]
    found = [sorted((p["global"], p["local"]) for p in h["pairs"]) for h in out["hypotheses"]]
    assert sorted(obs.true_pairs) in found[:3] and out["status"] == "ambiguous"
    assert best["fitness"] < 0.3
    assert main([*args, "--descriptor", "geometric", "--descriptor-delta", "0.05"]) == 0
    assert json.loads(capsys.readouterr().out)["status"] == "failed"
    assert main([*args, "--descriptor", "shape-context"]) == 2
    assert "shape-context" in capsys.readouterr().err


def test_an_ambiguous_pose_is_printed_with_a_warning():
    h = Hypothesis(1, 1.0, [("a", "1"), ("b", "2")], yaw_pose(0.2), fitness=1.0, confidence=0.3)
    out = Console(record=True, width=120)
    print_result(Result.of("ambiguous", [h], [], {}, "too few pairs: 2 agreeing pairs"), out)
    text = out.export_text()
    assert "reason: too few pairs" in text and "warning: not localized" in text
    assert "candidate pose T_global_local" in text and "confidence: 0.300" in text
    out = Console(record=True, width=120)
    print_result(Result.of("localized", [h], [], {}), out)
    assert "warning" not in out.export_text() and "reason" not in out.export_text()


def test_ground_truth_evaluation(maps, capsys, tmp_path):
    folder, obs = maps
    truth = tmp_path / "truth.gt.json"
    truth.write_text(json.dumps({"T_global_local": obs.T_global_local.tolist()}))
    args = ["localize", str(folder / "global.json"), str(folder / "local.json"), "--gt", str(truth)]
    assert main([*args, "--format", "json"]) == 0
    report = json.loads(capsys.readouterr().out)["ground_truth"]
    assert set(report) == {"rotation_deg", "translation_m", "success", "rank_of_first_correct"}
    assert report["success"] is True and report["rank_of_first_correct"] == 1
    assert report["rotation_deg"] < 2 and report["translation_m"] < 0.1
    assert main(args) == 0
    assert "success at 15° / 0.5 m" in " ".join(capsys.readouterr().out.split())


def test_ground_truth_of_a_wrong_place(maps, capsys, tmp_path):
    folder, obs = maps
    moved = obs.T_global_local.copy()
    moved[:3, 3] += [3.0, 0.0, 0.0]
    truth = tmp_path / "moved.json"
    truth.write_text(json.dumps(moved.tolist()))
    args = ["localize", str(folder / "global.json"), str(folder / "local.json"), "--gt", str(truth)]
    assert main([*args, "--format", "json"]) == 0
    report = json.loads(capsys.readouterr().out)["ground_truth"]
    assert report["success"] is False
    assert report["translation_m"] == pytest.approx(3.0, abs=0.1)
    bad = tmp_path / "bad.json"
    bad.write_text('{"T_global_local": [[1, 0], [0, 1]]}')
    assert main([*args[:-1], str(bad)]) == 2
    assert capsys.readouterr().err.startswith(f"semloc: error: {bad}:")


def test_progress_only_for_long_replays_on_a_terminal():
    import io

    from rich.console import Console

    from semloc.cli.render import LONG_REPLAY, replay_progress

    g = layout(30, seed=1)
    long = g.with_objects(o.replace(seen=i) for i, o in enumerate(g))
    short = g.with_objects(o.replace(seen=i % (LONG_REPLAY - 1)) for i, o in enumerate(g))
    terminal = Console(file=io.StringIO(), force_terminal=True)
    pipe = Console(file=io.StringIO(), force_terminal=False)
    with replay_progress(pipe, long) as callback:
        assert callback is None
    with replay_progress(terminal, short) as callback:
        assert callback is None
    calls = []
    with replay_progress(terminal, long) as callback:
        assert callback is not None
        semloc.localize(g, long.subset(long.ids[:12]), progress=lambda d, t: calls.append((d, t)))
        callback(5, 30)
    assert calls == [(i, 12) for i in range(1, 13)]
    assert "replaying updates" in terminal.file.getvalue()


def _vocabulary_maps(tmp_path):
    rng = np.random.default_rng(0)
    labels = ["armchair", "couch", "refrigerator", "coffee table", "television", "pillow", "lamp"]
    objects = [semloc.SemanticObject(str(i), lb, p)
               for i, (lb, p) in enumerate(zip(labels, rng.uniform(0, 6, (7, 3))))]  # fmt: skip
    names = {"armchair": "chair", "couch": "sofa", "refrigerator": "fridge", "lamp": "zorblax"}
    global_map = semloc.ObjectMap(objects)
    local = global_map.with_objects(o.replace(label=names.get(o.label, o.label)) for o in objects)
    semloc.save_map(global_map, tmp_path / "g.json")
    semloc.save_map(local, tmp_path / "l.json")
    return tmp_path / "g.json", tmp_path / "l.json"


def test_localize_reports_how_labels_were_read(tmp_path, capsys):
    g, l = _vocabulary_maps(tmp_path)
    assert main(["localize", str(g), str(l), "--format", "json"]) == 0
    captured = capsys.readouterr()
    assert json.loads(captured.out)["labels"] == {
        "chair": {"resolved": "child", "map_labels": ["armchair", "couch"]},
        "coffee table": {"resolved": "exact", "map_labels": ["coffee table"]},
        "fridge": {"resolved": "synonym", "map_labels": ["refrigerator"]},
        "pillow": {"resolved": "exact", "map_labels": ["pillow"]},
        "sofa": {"resolved": "synonym", "map_labels": ["couch"]},
        "television": {"resolved": "exact", "map_labels": ["television"]},
        "zorblax": {"resolved": "unmatched", "map_labels": []},
    }
    err = " ".join(captured.err.split())
    assert 'local label "zorblax" matches no map label' in err
    assert '{"zorblax": "<map label>"}' in err


def test_localize_label_map_option_json_and_yaml(tmp_path, capsys):
    g, l = _vocabulary_maps(tmp_path)
    (tmp_path / "m.json").write_text('{"zorblax": "lamp"}')
    (tmp_path / "m.yaml").write_text("zorblax: lamp\n")
    for name in ("m.json", "m.yaml"):
        args = ["localize", str(g), str(l), "--format", "json", "--label-map", str(tmp_path / name)]
        assert main(args) == 0
        captured = capsys.readouterr()
        labels = json.loads(captured.out)["labels"]
        assert labels["zorblax"] == {"resolved": "exact", "map_labels": ["lamp"]}
        assert "warning" not in captured.err
    assert main(["localize", str(g), str(l)]) == 0
    text = capsys.readouterr().out
    assert "labels (local → map)" in text and "unmatched" in text


@pytest.mark.parametrize("content", ['["x"]', '{"a": ""}', "a: [1"])
def test_localize_bad_label_map_is_one_line_exit_2(tmp_path, capsys, content):
    g, l = _vocabulary_maps(tmp_path)
    bad = tmp_path / ("bad.yaml" if content.startswith("a:") else "bad.json")
    bad.write_text(content)
    assert main(["localize", str(g), str(l), "--label-map", str(bad)]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


_JSON = st.recursive(
    st.none() | st.booleans() | st.integers() | st.text(max_size=8),
    lambda inner: (
        st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner, max_size=4)
    ),
    max_leaves=10,
)


@settings(max_examples=60)
@given(document=_JSON)
def test_label_map_files_are_a_mapping_of_strings_or_one_error(tmp_path_factory, document):
    path = tmp_path_factory.mktemp("lm") / "m.json"
    path.write_text(json.dumps(document))
    try:
        mapping = read_label_map(path)
    except CliError:
        return
    assert all(isinstance(k, str) and k.strip() and isinstance(v, str) and v.strip()
               for k, v in mapping.items())  # fmt: skip


# ---------------------------------------------------------------- position prior (--near)
def test_near_and_radius_narrow_the_answer_and_are_in_the_json(maps, capsys):
    folder, obs = maps
    args = ["localize", str(folder / "global.json"), str(folder / "local.json"), "--format", "json"]
    x, y, z = (obs.T_global_local[:3, 3] + [0.5, -0.5, 0.0]).tolist()
    assert main([*args, "--near", str(x), str(y), str(z), "--radius", "2"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["status"] == "localized"
    assert out["prior"] == {"position": [x, y, z], "radius": 2.0}
    assert out["hypotheses"][0]["outside_prior"] is False
    np.testing.assert_allclose(out["pose"], obs.T_global_local, atol=0.5)
    # a prior far from the true place: never localized there, and the JSON says why
    x, y, z = (obs.T_global_local[:3, 3] + [40.0, 0.0, 0.0]).tolist()
    assert main([*args, "--near", str(x), str(y), str(z), "--radius", "2"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["status"] != "localized" and "prior" in out["reason"]
    assert all(h["outside_prior"] for h in out["hypotheses"])


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--near", "1", "2", "3"], "--near X Y Z and --radius R go together"),
        (["--radius", "2"], "--near X Y Z and --radius R go together"),
        (["--near", "1", "2", "3", "--radius", "0"], "radius must be > 0"),
        (["--near", "1", "2", "3", "--radius", "-1"], "radius must be > 0"),
        (["--near", "1", "nan", "3", "--radius", "1"], "--near must be a finite number"),
        (["--near", "1", "2", "3", "--radius", "inf"], "--radius must be a finite number"),
        (["--near", "1", "2", "--radius", "1"], "--near"),
    ],
)
def test_bad_prior_options_exit_2_with_one_line(maps, capsys, extra, message):
    folder, _ = maps
    code = main(["localize", str(folder / "global.json"), str(folder / "local.json"), *extra])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert len(err.splitlines()) == 1 and err.startswith("semloc: error:") and message in err


# ------------------------------------------------------------------- look there next
def test_an_ambiguous_answer_says_where_to_look_next_in_the_table_and_the_json(tmp_path, capsys):
    a = list(room(12))
    shift = np.array([40.0, 0.0, 0.0])
    b = [o.replace(id=o.id.replace("a", "b"), position=o.position + shift) for o in a[:-2]]
    truth = yaw_pose(0.3, [0.5, 0.5, 0.0])
    view = [o.transformed(np.linalg.inv(truth)).replace(id=f"l{k}", seen=k)
            for k, o in enumerate(a[:5])]  # fmt: skip
    save_map(ObjectMap([*a, *b], up=[0, 0, 1], name="two copies"), tmp_path / "global.json")
    save_map(ObjectMap(view, up=[0, 0, 1], name="view"), tmp_path / "local.json")
    args = ["localize", str(tmp_path / "global.json"), str(tmp_path / "local.json")]
    assert main([*args, "--format", "json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["status"] == "ambiguous"
    assert out["next_look"][0]["global_id"] in {"a10", "a11"}  # what the other copy lacks
    assert main(args) == 0
    table = capsys.readouterr().out
    assert "look there next" in table and out["next_look"][0]["global_id"] in table


def test_the_text_table_marks_hypotheses_outside_the_prior():
    """`outside_prior` of the JSON is a `*` beside the rank in the text, explained below."""
    inside = Hypothesis(1, 3.0, [("a", "1"), ("b", "2"), ("c", "3")], yaw_pose(0.2), fitness=1.0,
                        confidence=0.4, outside_prior=False)  # fmt: skip
    outside = Hypothesis(2, 3.0, [("a", "2"), ("b", "3"), ("c", "1")], yaw_pose(1.2),
                         fitness=1.0, confidence=0.4, outside_prior=True)  # fmt: skip
    out = Console(record=True, width=120)
    print_result(Result.of("ambiguous", [inside, outside], [], {}, "two places"), out)
    lines = out.export_text().splitlines()
    ranks = [line.split()[0] for line in lines if line.strip()[:2] in ("1 ", "2*")]
    assert ranks == ["1", "2*"], lines
    assert any("* outside the position prior" in line for line in lines)
    out = Console(record=True, width=120)
    print_result(Result.of("ambiguous", [inside], [], {}, "one place"), out)
    assert "outside the position prior" not in out.export_text()
