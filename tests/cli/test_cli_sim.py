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
    assert main(argv) == 0
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
