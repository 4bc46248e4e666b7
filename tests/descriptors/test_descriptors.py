"""Shape descriptors: invariance, stability, shapes, shipped weights, numpy == torch forward."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from semloc import descriptors
from semloc.descriptors import voxnet
from semloc.descriptors.frame import canonical
from semloc.eval.descriptors.data import HELD_OUT, full_view, instances, partial_view
from semloc.maps import ObjectMap
from semloc.sim.shapes import model
from semloc.transforms import yaw_rotation

FIXTURE = Path(__file__).parent / "data" / "voxnet_fixture.npz"
KINDS = ["geometric", "voxnet"]


def _yaw(points, angle, shift):
    return points @ yaw_rotation(angle).T + np.asarray(shift)


@pytest.fixture(scope="module")
def clouds():
    rng = np.random.default_rng(7)
    return {
        (label, style): model(label, style).mesh.sample_surface(3000, rng)
        for label, style in [("chair", 1), ("table", 0), ("sofa", 0), ("lamp", 0)]
    }


@pytest.mark.parametrize("kind", KINDS)
def test_shape_dtype_and_batch(kind, clouds):
    points = list(clouds.values())
    one = descriptors.compute(points[0], kind)
    many = descriptors.compute_batch(points, kind)
    assert one.ndim == 1 and many.shape == (len(points), one.size)
    assert np.issubdtype(many.dtype, np.floating) and np.all(np.isfinite(many))
    np.testing.assert_allclose(many[0], one, atol=1e-6)
    if kind == "voxnet":
        assert one.size == 64
        np.testing.assert_allclose(np.linalg.norm(many, axis=1), 1.0, atol=1e-5)


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("angle", [0.4, 1.9, -2.7])
def test_invariant_to_yaw_and_translation(kind, angle, clouds):
    for points in clouds.values():
        a = descriptors.compute(points, kind)
        b = descriptors.compute(_yaw(points, angle, [4.0, -3.0, 0.7]), kind)
        assert np.linalg.norm(a - b) < 0.02, np.linalg.norm(a - b)


def test_canonical_frame_is_yaw_invariant(clouds):
    points = clouds[("table", 0)]
    a = canonical(points, voxel=0)
    b = canonical(_yaw(points, 2.2, [1.0, 2.0, 3.0]), voxel=0)
    np.testing.assert_allclose(a, b, atol=1e-9)
    assert a[:, 2].min() == pytest.approx(0.0)


@pytest.mark.parametrize("kind", KINDS)
def test_stable_under_subsampling(kind, clouds):
    rng = np.random.default_rng(3)
    keys = list(clouds)
    own, others = [], []
    for key in keys:
        full = descriptors.compute(clouds[key], kind)
        half = descriptors.compute(clouds[key][rng.random(len(clouds[key])) < 0.5], kind)
        own.append(np.linalg.norm(full - half))
        others.extend(
            np.linalg.norm(full - descriptors.compute(clouds[k], kind)) for k in keys if k != key
        )
    assert max(own) < 0.25 * min(others), (own, min(others))
    assert max(own) < 0.1


def test_bad_input():
    with pytest.raises(ValueError, match="shape"):
        descriptors.compute(np.zeros((5, 2)))
    with pytest.raises(ValueError, match="at least 3"):
        descriptors.compute(np.zeros((2, 3)))
    with pytest.raises(ValueError, match="unknown descriptor kind"):
        descriptors.compute(np.zeros((5, 3)), "sift")


def test_occupancy_grid_keeps_metric_size(clouds):
    grid = voxnet.occupancy_grid(clouds[("table", 0)])
    assert grid.shape == (32, 32, 32) and grid.dtype == np.float32
    filled = np.argwhere(grid > 0)
    extent = (filled.max(axis=0) - filled.min(axis=0) + 1) * voxnet.VOXEL
    assert extent[0] == pytest.approx(1.6, abs=0.15)  # long side of the table top
    assert extent[2] == pytest.approx(0.76, abs=0.1)


def test_shipped_weights_load():
    assert voxnet.WEIGHTS_FILE.exists()
    assert voxnet.WEIGHTS_FILE.stat().st_size < 5e6
    weights = voxnet.load_weights()
    assert set(voxnet.PARAMETERS) <= set(weights)
    assert all(w.dtype == np.float32 and np.all(np.isfinite(w)) for w in weights.values())


def test_numpy_forward_equals_torch_fixture():
    with np.load(FIXTURE, allow_pickle=False) as data:
        grids, expected = data["grids"], data["embeddings"]
    got = voxnet.forward(grids.astype(np.float32))
    np.testing.assert_allclose(got, expected, atol=1e-5)


@pytest.mark.skipif(importlib.util.find_spec("torch") is None, reason="torch not installed")
def test_numpy_forward_equals_torch_live():
    import torch

    from semloc.eval.descriptors.train import build_model, embed

    torch.manual_seed(0)
    net = build_model()
    modules = [m for m in net if hasattr(m, "weight")]
    weights = {}
    for name, module in zip([*voxnet.LAYERS, *voxnet.FC], modules):
        weights[f"{name}.weight"] = module.weight.detach().numpy()
        weights[f"{name}.bias"] = module.bias.detach().numpy()
    grids = (np.random.default_rng(0).random((3, 32, 32, 32)) < 0.05).astype(np.float32)
    np.testing.assert_allclose(voxnet.forward(grids, weights), embed(net, grids), atol=1e-5)


def test_with_descriptors_fills_only_missing():
    pts = model("chair", 0).mesh.sample_surface(500, np.random.default_rng(0))
    gmap = ObjectMap.from_arrays(
        ["a", "b", "c"],
        ["chair", "chair", "chair"],
        np.zeros((3, 3)),
        points=[pts, pts[:5], pts],
        descriptors=[None, None, [1.0, 2.0]],
    )
    out = descriptors.with_descriptors(gmap, "geometric")
    assert out.get("a").descriptor is not None
    assert out.get("b").descriptor is None  # too few points
    np.testing.assert_array_equal(out.get("c").descriptor, [1.0, 2.0])


def test_simulated_views_and_splits():
    rng = np.random.default_rng(0)
    assert set(instances("held_out")) == set(HELD_OUT)
    assert not set(instances("train")) & HELD_OUT
    view = partial_view("chair", 0, rng)
    full = full_view("chair", 0, rng)
    assert view.shape[1] == 3 and len(view) >= 20 and len(full) > len(view) / 4


def _chairs():
    rng = np.random.default_rng(5)
    pts = [model("chair", s).mesh.sample_surface(800, rng) for s in (0, 1, 0)]
    shift = [np.array([0.0, 0, 0]), np.array([3.0, 0, 0]), np.array([0.0, 3, 0])]
    gmap = ObjectMap.from_arrays(
        ["g0", "g1", "g2"],
        ["chair"] * 3,
        [p.mean(axis=0) + t for p, t in zip(pts, shift)],
        points=[p + t for p, t in zip(pts, shift)],
        up=[0, 0, 1],
    )
    local = ObjectMap.from_arrays(
        ["l0"], ["chair"], [pts[1].mean(axis=0)], points=[pts[1]], up=[0, 0, 1]
    )
    return gmap, local


def test_localizer_default_ignores_points():
    from semloc.association import CandidateIndex
    from semloc.localizer import Localizer, LocalizerConfig

    gmap, local = _chairs()
    config = LocalizerConfig()
    loc = Localizer(gmap, config)
    assert config.association.descriptor is None and loc.descriptor_gate == 0.5
    assert all(o.descriptor is None for o in loc.global_map)
    index = CandidateIndex(gmap, config.association)
    assert index.candidates(local[0]).tolist() == [0, 1, 2]


@pytest.mark.parametrize("kind", KINDS)
def test_localizer_descriptor_gate(kind):
    from semloc.localizer import Localizer, LocalizerConfig

    gmap, local = _chairs()
    config = LocalizerConfig(descriptor=kind, descriptor_delta=0.05)
    loc = Localizer(gmap, config)
    assert loc.descriptor_gate == 0.05
    assert (
        Localizer(gmap, LocalizerConfig(descriptor=kind)).descriptor_gate
        == descriptors.DELTAS[kind]
    )
    assert all(o.descriptor is not None for o in loc.global_map)
    loc.update(local)
    assert loc._context.candidates.candidates(loc.local_map[0]).tolist() == [1]


def test_cli_descriptors_eval_small(tmp_path):
    from semloc.cli import main

    code = main(
        ["descriptors-eval", "--kind", "geometric", "--views", "1", "--sequences", "0",
         "--out", str(tmp_path)]
    )  # fmt: skip
    assert code == 0
    import json

    report = json.loads((tmp_path / "descriptors_eval.json").read_text())
    held = report["kinds"]["geometric"]["retrieval"]["held_out"]
    assert held["queries"] == len(HELD_OUT)
    assert 0 <= held["all"]["top1"] <= held["all"]["top5"] <= 1
    assert (tmp_path / "descriptors_retrieval.png").exists()


@pytest.mark.skipif(importlib.util.find_spec("torch") is not None, reason="torch is installed")
def test_cli_train_without_torch(capsys):
    from semloc.cli import main

    assert main(["train-descriptor", "--epochs", "1"]) == 2
    assert "pip install 'semloc[train]'" in capsys.readouterr().err


def test_calibrate_quantile_and_removed_share():
    from semloc.eval.descriptors.evaluate import calibrate

    true = np.linspace(0.0, 1.0, 101).tolist()
    wrong = np.linspace(0.5, 2.0, 100).tolist()
    c = calibrate({"cad": {"true": true, "wrong": wrong}}, 0.98)
    assert c["delta"] == pytest.approx(0.99)
    assert c["maps"]["cad"]["true_pass"] >= 0.98
    expected = np.mean(np.asarray(wrong) >= c["delta"])
    assert c["maps"]["cad"]["wrong_removed"] == pytest.approx(expected)


def test_calibrated_deltas_are_positive():
    assert set(descriptors.DELTAS) == set(descriptors.KINDS)
    assert all(d > 0 for d in descriptors.DELTAS.values())
