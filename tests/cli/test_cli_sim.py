"""`semloc simulate`, `semloc view` and `semloc demo` end to end (in-process, small worlds)."""

from __future__ import annotations

import json

import numpy as np
import pytest

import semloc
from semloc.cli import main
from semloc.transforms import pose_error

PNG = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim")
    argv = ["simulate", str(out), "--size", "tiny", "--keyframes", "10", "--resolution", "96x72"]
    assert main(argv) == 0
    return out


def test_simulate_writes_loadable_maps_and_ground_truth(simulated):
    world = json.loads((simulated / "world.json").read_text())
    truth = json.loads((simulated / "ground_truth.json").read_text())
    local = semloc.load_map(simulated / "local.json")
    assert len(local) > 0 and list(local.up) == [0, 0, 1]
    for kind in ("reconstruction", "cad", "dynamic"):
        gmap = semloc.load_map(simulated / f"global_{kind}.json")
        assert len(gmap) > 0 and all(o.points is not None for o in gmap)
        for pair in truth["correspondences"][kind]:
            assert pair["global"] in gmap and pair["local"] in local
    assert len(truth["keyframes"]) == 10
    assert np.asarray(truth["T_global_local"]).shape == (4, 4)
    assert set(truth["dynamic"]) == {"deleted", "moved"}
    assert len(world["objects"]) >= 10
    snapshots = sorted((simulated / "keyframes").glob("local_*.json"))
    assert len(snapshots) == 10
    assert len(semloc.load_map(snapshots[-1])) == len(local)
    assert (simulated / "world.png").read_bytes()[:8] == PNG


def test_simulate_can_store_descriptors(tmp_path):
    argv = ["simulate", str(tmp_path), "--size", "tiny", "--keyframes", "3", "--resolution",
            "64x48", "--no-snapshots", "--descriptor", "geometric"]  # fmt: skip
    assert main(argv) == 0
    for name in ("global_cad.json", "local.json"):
        objects = [o for o in semloc.load_map(tmp_path / name) if o.points is not None]
        assert objects and all(o.descriptor is not None for o in objects if len(o.points) >= 10)


def test_ground_truth_places_local_objects_on_their_global_objects(simulated):
    truth = json.loads((simulated / "ground_truth.json").read_text())
    T = np.asarray(truth["T_global_local"])
    gmap = semloc.load_map(simulated / "global_reconstruction.json")
    local = semloc.load_map(simulated / "local.json").transformed(T)
    errors = [np.linalg.norm(gmap.get(p["global"]).position - local.get(p["local"]).position)
              for p in truth["correspondences"]["reconstruction"]]  # fmt: skip
    assert np.median(errors) < 0.3


def test_view_draws_a_map_with_a_result(simulated, tmp_path, capsys):
    out = tmp_path / "view.png"
    argv = ["view", str(simulated / "global_cad.json"), "--local", str(simulated / "local.json"),
            "--result", str(simulated / "ground_truth.json"), "-o", str(out)]  # fmt: skip
    assert main(argv) == 0
    assert out.read_bytes()[:8] == PNG
    assert (
        main(["view", str(simulated / "global_cad.json"), "-o", str(tmp_path / "plain.png")]) == 0
    )
    assert (tmp_path / "plain.png").stat().st_size > 10_000


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["view", "missing.json"], "not found"),
        (["view", "{map}", "--result", "{world}"], "not a localization result"),
        (["view", "{map}", "--local", "{local}"], "--local needs a --result"),
        (["demo", "--size", "huge"], "unknown world size"),
        (["demo", "--resolution", "big"], "--resolution"),
        (["demo", "--map-kind", "sketch"], "sketch"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(simulated, tmp_path, capsys, argv, message):
    names = {"map": simulated / "global_cad.json", "world": simulated / "world.json",
             "local": simulated / "local.json"}  # fmt: skip
    argv = [a.format(**names) for a in argv] + (
        ["--out", str(tmp_path)] if argv[0] == "demo" else []
    )
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1, err


@pytest.mark.slow
def test_demo_localizes_a_tiny_world_and_writes_the_pictures(tmp_path, capsys):
    out = tmp_path / "demo"
    argv = [
        "demo",
        "--out",
        str(out),
        "--size",
        "tiny",
        "--keyframes",
        "16",
        "--resolution",
        "120x90",
    ]
    assert main([*argv, "--rrd", str(out / "demo.rrd")]) == 0
    text = capsys.readouterr().out
    assert "pose error vs ground truth" in text
    for name in ("scores.png", "map.png", "world.png"):
        assert (out / name).read_bytes()[:8] == PNG
    result = json.loads((out / "result.json").read_text())
    truth = json.loads((out / "ground_truth.json").read_text())
    assert result["status"] == "localized"
    rotation, translation = pose_error(
        np.asarray(result["pose"]), np.asarray(truth["T_global_local"])
    )
    assert rotation < 15 and translation < 0.5
    assert len(semloc.load_map(out / "global.json")) > 0
    rows = recording_rows(out / "demo.rrd")
    steps = [s for s in result["steps"]]  # the last ones: a result's history is bounded
    keyframes = [r["keyframe"] for r in rows["/status"]]
    assert len(keyframes) >= len(steps) > 0 and keyframes == sorted(keyframes)
    assert [s["step"] for s in steps] == list(range(len(keyframes) - len(steps), len(keyframes)))
    statuses = [r["TextLog:text"][0].split(": ")[1].split(",")[0] for r in rows["/status"]]
    assert statuses[-len(steps) :] == [s["status"] for s in steps]
    top1 = [r["Scalars:scalars"][0] for r in rows["/scores/top1"]]
    expected = [s["top_scores"][0] for s in steps if s["top_scores"]]
    assert top1[-len(expected) :] == pytest.approx(expected, rel=1e-6)
    sizes = [len(r["Points3D:positions"]) for r in rows["/world/local_true/centres"]]
    assert sizes[-len(steps) :] == [s["n_local"] for s in steps]  # the local map growing
    last = rows["/world/local_estimated/centres"][-1]["Points3D:positions"]
    # the final fused map; the localizer holds the last published version of each object
    placed = semloc.load_map(out / "local.json").transformed(np.asarray(result["pose"]))
    np.testing.assert_allclose(np.sort(np.asarray(last), 0), np.sort(placed.positions, 0),
                               atol=0.05)  # fmt: skip


def recording_rows(path):
    """Per entity path, the rows of a Rerun recording (read back with Rerun's own reader)."""
    from rerun.chunk import RrdReader

    rows: dict[str, list[dict]] = {}
    for chunk in RrdReader(path).stream().collect().stream():
        table = chunk.to_record_batch().to_pydict()
        for i in range(chunk.num_rows):
            rows.setdefault(chunk.entity_path, []).append({k: v[i] for k, v in table.items()})
    for entity in rows:
        if rows[entity] and "keyframe" in rows[entity][0]:
            rows[entity].sort(key=lambda r: r["keyframe"])
    return rows


def test_view_with_ground_truth_and_a_3d_recording(simulated, tmp_path, capsys):
    gmap = semloc.load_map(simulated / "global_reconstruction.json")
    local = semloc.load_map(simulated / "local.json")
    truth = np.asarray(json.loads((simulated / "ground_truth.json").read_text())["T_global_local"])
    estimate = truth.copy()
    estimate[:3, 3] += [0.5, 0.0, 0.0]
    pairs = json.loads((simulated / "ground_truth.json").read_text())["correspondences"]
    pairs = [{"global": p["global"], "local": p["local"]} for p in pairs["reconstruction"]]
    result = tmp_path / "result.json"
    result.write_text(json.dumps({"status": "localized", "pose": estimate.tolist(),
                                  "hypotheses": [{"pairs": pairs}]}))  # fmt: skip
    png, rrd = tmp_path / "v.png", tmp_path / "v.rrd"
    argv = ["view", str(simulated / "global_reconstruction.json"), "--result", str(result),
            "--local", str(simulated / "local.json"), "--gt", str(simulated / "ground_truth.json"),
            "-o", str(png), "--rrd", str(rrd)]  # fmt: skip
    assert main(argv) == 0
    assert png.read_bytes()[:8] == PNG
    rows = recording_rows(rrd)
    centres = rows["/world/global/centres"][0]
    assert len(centres["Points3D:positions"]) == len(gmap)
    assert sorted(centres["Points3D:labels"]) == sorted(f"{o.label} {o.id}" for o in gmap)
    boxes = rows["/world/global/boxes"][0]
    assert sorted(boxes["Boxes3D:labels"]) == sorted(o.label for o in gmap if o.size is not None)
    for entity, pose in (("local_estimated", estimate), ("local_true", truth)):
        got = np.asarray(rows[f"/world/{entity}/centres"][0]["Points3D:positions"])
        np.testing.assert_allclose(got, local.transformed(pose).positions, atol=1e-4)
    lines = rows["/world/associations"][0]["LineStrips3D:strips"]
    assert len(lines) == len(pairs)
    first = gmap.get(pairs[0]["global"]).position
    np.testing.assert_allclose(lines[0][0], first, atol=1e-4)
    colors = {c for c in centres["Points3D:colors"]}
    assert len(colors) == len(set(gmap.labels))  # one colour per label
    capsys.readouterr()
    only = tmp_path / "only.rrd"
    assert main(["view", str(simulated / "local.json"), "--rrd", str(only)]) == 0
    assert only.exists() and not (simulated / "local.png").exists()


def test_every_label_has_its_own_colour():
    from semloc.pictures.colors import CLASS_COLORS, label_colors

    labels = [*CLASS_COLORS, "clock", "bench", "stool", *(f"thing{i}" for i in range(40))]
    colors = label_colors(labels)
    assert len(set(colors.values())) == len(colors) == len(set(labels))
    assert colors["cabinet"] == CLASS_COLORS["cabinet"] and colors["clock"] != colors["cabinet"]
    assert label_colors(["chair", "bench"])["bench"] != CLASS_COLORS["chair"]


def test_a_local_map_alone_is_labelled_local(simulated, tmp_path):
    from semloc.pictures.viz import map_figure, plot_localization

    local = semloc.load_map(simulated / "local.json")
    fig, ax = map_figure(local.positions[:, :2])
    plot_localization(ax, local, map_role="local")
    texts = [t.get_text() for t in ax.get_legend().get_texts()]
    assert "local object" in texts and "global object" not in texts


def test_labels_appearing_later_keep_the_colours_handed_out():
    from semloc.pictures.colors import label_colors

    first = label_colors(["chair", "clock"])
    later = label_colors(["bench", "armchair"], first)
    assert {k: later[k] for k in first} == first
    assert len(set(later.values())) == len(later) == 4


def test_the_demo_plots_every_keyframe_not_only_the_last_steps(tmp_path, monkeypatch):
    """scores.png draws the whole run (the demo keeps its history; `Result.steps` keeps the
    last 10), each keyframe at its own index; the summary keeps the warm-up apart."""
    from rich.console import Console

    import semloc.pictures.viz as viz
    from semloc.tools.demo import DemoConfig, run_demo

    drawn = {}
    plot = viz.plot_scores

    def spy(ax, steps, **options):
        drawn["steps"], drawn["statuses"] = list(steps), options.get("statuses")
        return plot(ax, steps, **options)

    monkeypatch.setattr(viz, "plot_scores", spy)
    console = Console(record=True, width=200)
    config = DemoConfig(size="tiny", keyframes=16, resolution=(120, 90), out=tmp_path / "d")
    demo = run_demo(config, console)
    keyframes = [s.step for s in drawn["steps"]]
    assert keyframes == [s.step for s in demo.history] == sorted(keyframes)
    assert len(keyframes) > len(demo.result.steps) and keyframes[-1] >= 12
    assert drawn["statuses"] == [s.status for s in demo.history]
    assert drawn["statuses"][-1] == demo.result.status
    last = demo.result.steps[-1].top_scores
    assert list(drawn["steps"][-1].top_scores) == pytest.approx(list(last))
    text = " ".join(console.export_text().split())
    assert "s loading the compiled code" in text or "s compiling the inner loops" in text
    assert f"({len(keyframes)} updates, " in text
