"""Detection noise, odometry drift and camera paths."""

from __future__ import annotations

import numpy as np

from semloc.sim.noise import CONFUSIONS, DetectionNoise, detect, drift
from semloc.sim.sensor import DepthSensor, Intrinsics
from semloc.sim.shapes import SMALL_CLASSES
from semloc.sim.trajectory import camera_path, odometry_origin
from semloc.sim.world import generate_world


def _frames(world, n=12, size=(120, 90), path="orbit"):
    K = Intrinsics.scannet(*size)
    sensor = DepthSensor(world, K)
    return K, [sensor.render(T) for T in camera_path(world, path, n, n_rooms=3)]


def test_perfect_detection_finds_every_well_visible_object_with_its_label():
    world = generate_world(0, "tiny")
    K, frames = _frames(world)
    rng = np.random.default_rng(0)
    for frame in frames:
        visible, counts = np.unique(frame.instance[frame.instance >= 0], return_counts=True)
        found = detect(frame, world, K, DetectionNoise.perfect(), rng)
        assert {d.instance for d in found} >= set(visible[counts > 50].tolist())
        assert all(d.label == world.objects[d.instance].label for d in found)


def test_noise_misses_small_objects_more_and_confuses_only_similar_labels():
    world = generate_world(1, "small")
    K, frames = _frames(world, n=40, path="walk")
    rng = np.random.default_rng(1)
    noise = DetectionNoise(confusion_prob=0.3, small_miss_prob=0.6, miss_prob=0.05)
    seen = {"small": [0, 0], "other": [0, 0]}
    for frame in frames:
        found = {d.instance: d for d in detect(frame, world, K, noise, rng)}
        visible, counts = np.unique(frame.instance[frame.instance >= 0], return_counts=True)
        for inst in visible[counts > 60].tolist():
            label = world.objects[inst].label
            kind = "small" if label in SMALL_CLASSES else "other"
            seen[kind][0] += 1
            seen[kind][1] += inst in found
            if inst in found and found[inst].label != label:
                assert found[inst].label in CONFUSIONS[label]
    rate = {k: hit / max(total, 1) for k, (total, hit) in seen.items()}
    assert seen["small"][0] > 5 and rate["small"] < rate["other"]


def test_drift_grows_with_distance_and_keeps_gravity():
    poses = np.stack([np.eye(4)] * 30)
    poses[:, 0, 3] = np.linspace(0, 15, 30)
    assert np.array_equal(drift(poses, DetectionNoise(), np.random.default_rng(0)), poses)
    noise = DetectionNoise(drift_translation=0.02, drift_yaw_deg=2.0)
    runs = [drift(poses, noise, np.random.default_rng(seed)) for seed in range(8)]
    errors = np.mean([np.linalg.norm(n[:, :3, 3] - poses[:, :3, 3], axis=1) for n in runs], axis=0)
    assert errors[0] == 0 and errors[-1] > 3 * errors[5] and errors[-1] > 0.1
    noisy = runs[0]
    np.testing.assert_allclose(noisy[:, :3, 2], poses[:, :3, 2], atol=1e-9)


def test_camera_paths_stay_inside_the_walked_rooms_and_look_slightly_down():
    world = generate_world(0, "small")
    for kind in ("walk", "orbit"):
        poses = camera_path(world, kind, 30)
        assert poses.shape == (30, 4, 4)
        for T in poses:
            assert world.room_at(T[:2, 3]) is not None or kind == "walk"
            assert 1.2 < T[2, 3] < 1.6
            assert -0.6 < T[2, 2] < -0.1  # the optical axis points a little down
    steps = np.linalg.norm(np.diff(camera_path(world, "walk", 40)[:, :2, 3], axis=0), axis=1)
    assert steps.max() < 1.0


def test_the_odometry_origin_is_the_first_camera_made_gravity_aligned():
    world = generate_world(0, "tiny")
    T_wc = camera_path(world, "orbit", 5)[0]
    T_wo = odometry_origin(T_wc)
    np.testing.assert_allclose(T_wo[:3, 3], T_wc[:3, 3])
    np.testing.assert_allclose(T_wo[:3, 2], [0, 0, 1], atol=1e-12)
    forward = T_wc[:3, 2].copy()
    forward[2] = 0
    np.testing.assert_allclose(T_wo[:3, 0], forward / np.linalg.norm(forward), atol=1e-9)
