"""The learned models of the SVL and FCGF-style baselines: shipped weights (small, no pickles,
clear errors on bad files), numpy inference equal to the torch models, the geometry of their
inputs, and seeded training that repeats itself (torch tests skip without torch)."""

from __future__ import annotations

import numpy as np
import pytest

from semloc.descriptors import fcgf, svl

MODELS = {"svl": svl, "fcgf-dense": fcgf}


@pytest.mark.parametrize("kind", MODELS)
def test_shipped_weights_are_small_npz_without_pickles(kind):
    module = MODELS[kind]
    assert module.WEIGHTS_FILE.stat().st_size <= 5_000_000
    with np.load(module.WEIGHTS_FILE, allow_pickle=False) as data:
        assert sorted(data.files) == sorted(module.PARAMETERS)
        assert all(data[k].dtype == np.float32 for k in data.files)
    weights = module.load_weights()
    assert all(np.isfinite(w).all() for w in weights.values())


@pytest.mark.parametrize("kind", MODELS)
def test_bad_weight_files_give_a_one_line_error(kind, tmp_path):
    module = MODELS[kind]
    missing = tmp_path / "missing.npz"
    with pytest.raises(FileNotFoundError, match=f"--kind {kind}"):
        module.load_weights(missing)
    garbage = tmp_path / "garbage.npz"
    garbage.write_bytes(b"not a weight file at all")
    array = tmp_path / "array.npy"
    np.save(array, np.zeros(3))
    partial = tmp_path / "partial.npz"
    np.savez(partial, **{module.PARAMETERS[0]: np.zeros(3)})
    for path, words in ((garbage, "not a"), (array, "not a"), (partial, "missing")):
        with pytest.raises(ValueError, match=words) as info:
            module.load_weights(path)
        assert "\n" not in str(info.value)


def test_svl_volume_turns_with_the_scene():
    """A scene turned by 90 degrees about an object, seen at yaw 90 degrees, gives the volume of
    the unturned scene at yaw 0 (points at cell centres: no rounding at cell borders)."""
    rng = np.random.default_rng(0)
    cells = rng.integers(0, [20, 20, 12], (300, 3))
    centre = np.array([3.0, -1.0, 0.0])
    points = (cells + 0.5) * svl.CELL + [-2.0, -2.0, 0.0] + centre
    points[0, 2] = 0.0  # the floor at z = 0
    channels = rng.integers(0, svl.CHANNELS, len(points))
    turned = points.copy()
    turned[:, :2] = (points[:, :2] - centre[:2]) @ np.array([[0, 1], [-1, 0]]) + centre[:2]
    a = svl.volumes(points, channels, centre)
    b = svl.volumes(turned, channels, centre, [np.pi / 2])
    assert a.sum() > 250 and np.array_equal(a, b)


def test_svl_labels_outside_the_classes_go_to_other():
    assert svl.CLASSES[svl.channel_of("Coffee Table")] == "coffee_table"
    assert svl.CLASSES[svl.channel_of("piano")] == "other"


def test_fcgf_features_do_not_depend_on_where_the_cloud_is():
    rng = np.random.default_rng(1)
    points = rng.uniform(0, 2.0, (800, 3))
    moved = points + np.array([3, -7, 2]) * fcgf.VOXEL
    a, b = fcgf.point_features(points), fcgf.point_features(moved)
    assert a.shape == (800, fcgf.FEATURE)
    np.testing.assert_allclose(np.linalg.norm(a, axis=1), 1, atol=1e-5)
    np.testing.assert_allclose(a, b, atol=1e-6)


def test_svl_numpy_encoder_equals_torch():
    torch = pytest.importorskip("torch")
    from semloc.eval.descriptors.train_svl import build_model, load_into

    net = build_model()
    load_into(net, svl.load_weights())
    vols = np.random.default_rng(2).random((3, svl.CHANNELS, *svl.GRID)) > 0.95
    vols = vols.astype(np.float32)
    with torch.no_grad():
        expected = net.encode(torch.from_numpy(vols))[0].numpy()
    np.testing.assert_allclose(svl.encode(vols), expected, atol=1e-4)


def test_fcgf_numpy_features_equal_the_dense_torch_network():
    torch = pytest.importorskip("torch")
    from semloc.eval.descriptors.train_fcgf import build_model, grid_inputs, load_into

    net = build_model()
    load_into(net, fcgf.load_weights())
    grid = np.zeros((18, 20, 16), np.float32)  # the band of occupied cells inside the grid:
    grid[2:-2, 2:-2, 2:-2] = np.random.default_rng(3).random((14, 16, 12)) > 0.9
    cells = np.argwhere(grid > 0)
    with torch.no_grad():
        dense = net(torch.from_numpy(grid_inputs(grid[None])))[0].numpy()
    expected = dense[:, cells[:, 0], cells[:, 1], cells[:, 2]].T
    np.testing.assert_allclose(fcgf.cell_features(cells), expected, atol=1e-5)


def test_svl_training_repeats_itself():
    pytest.importorskip("torch")
    from semloc.eval.descriptors.train_svl import SvlTrainConfig, train

    config = SvlTrainConfig(worlds=1, epochs=1, batches_per_epoch=2, batch=4)
    a, summary = train(config, log=lambda _: None)
    b, _ = train(config, log=lambda _: None)
    assert sorted(a) == sorted(svl.PARAMETERS)
    assert all(np.array_equal(a[k], b[k]) for k in a)
    assert np.isfinite(summary["losses"]).all()


def test_fcgf_training_repeats_itself():
    pytest.importorskip("torch")
    from semloc.eval.descriptors.train_fcgf import FcgfTrainConfig, train

    config = FcgfTrainConfig(worlds=1, epochs=1, batches_per_epoch=2, pairs=1, positives=64)
    a, summary = train(config, log=lambda _: None)
    b, _ = train(config, log=lambda _: None)
    assert sorted(a) == sorted(fcgf.PARAMETERS)
    assert all(np.array_equal(a[k], b[k]) for k in a)
    assert np.isfinite(summary["losses"]).all()
