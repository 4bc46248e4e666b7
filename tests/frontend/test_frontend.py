"""Object fusion: real-detection interface, stable ids, new/updated reporting, simulated truth."""

from __future__ import annotations

from collections import Counter

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from semloc.frontend import FusionConfig, ObjectFusion, Segment, voxel_downsample
from semloc.maps import MapError
from semloc.sim.noise import DetectionNoise
from semloc.sim.scenario import simulate_sequence
from semloc.transforms import yaw_pose


def _box_points(centre, size, n, rng):
    return np.asarray(centre) + (rng.random((n, 3)) - 0.5) * np.asarray(size)


def _yaw(x, y, angle):
    return yaw_pose(angle, (x, y, 1.5))


def test_segments_from_several_frames_fuse_into_stable_objects():
    rng = np.random.default_rng(0)
    fusion = ObjectFusion()
    chair = ([2.0, 0.0, 0.45], [0.5, 0.5, 0.9])
    table = ([2.0, 1.5, 0.4], [1.4, 0.8, 0.8])
    first = fusion.integrate([
        Segment("chair", _box_points(*chair, 300, rng), 0.9),
        Segment("table", _box_points(*table, 400, rng)),
    ])  # fmt: skip
    assert first.new == [] and first.keyframe == 0  # published after two detections
    second = fusion.integrate([
        Segment("chair", _box_points(*chair, 300, rng), 0.8),
        Segment("table", _box_points(*table, 400, rng)),
    ])  # fmt: skip
    assert sorted(second.new) == sorted(first.assignments)
    assert second.assignments == first.assignments  # same objects, same ids
    local = fusion.local_map()
    assert len(local) == 2 and list(local.up) == [0, 0, 1]
    chair_obj = local.get(second.assignments[0])
    assert chair_obj.label == "chair" and chair_obj.seen == 0
    np.testing.assert_allclose(chair_obj.position, chair[0], atol=0.05)
    assert chair_obj.score == pytest.approx(0.85)
    third = fusion.integrate(
        [Segment("chair", _box_points([2.2, 0.0, 0.45], [0.5, 0.5, 0.9], 300, rng))]
    )
    assert third.new == [] and third.updated == [second.assignments[0]]


def test_camera_frame_segments_are_moved_by_the_frame_pose():
    rng = np.random.default_rng(1)
    world_points = _box_points([3.0, 1.0, 0.5], [0.6, 0.6, 1.0], 500, rng)
    fusion = ObjectFusion(FusionConfig(min_observations=1))
    for k, T in enumerate([_yaw(0, 0, 0.2), _yaw(1.0, -0.5, 0.6)]):
        in_camera = (world_points - T[:3, 3]) @ T[:3, :3]
        update = fusion.integrate([Segment("cabinet", in_camera)], T, frame="camera", keyframe=k)
    assert update.assignments == ["0"]
    obj = fusion.local_map()[0]
    np.testing.assert_allclose(obj.position, [3.0, 1.0, 0.5], atol=0.05)
    assert obj.extra["observations"] == 2


def test_a_new_object_far_away_gets_a_new_id_and_keyframe():
    rng = np.random.default_rng(2)
    fusion = ObjectFusion(FusionConfig(min_observations=1))
    fusion.integrate([Segment("chair", _box_points([0, 0, 0.4], [0.5, 0.5, 0.8], 200, rng))])
    update = fusion.integrate(
        [Segment("chair", _box_points([0.9, 0, 0.4], [0.5, 0.5, 0.8], 200, rng))]
    )
    assert update.new == ["1"]
    assert [o.seen for o in fusion.local_map()] == [0, 1]


def test_stray_background_points_do_not_move_the_centre():
    rng = np.random.default_rng(3)
    points = np.vstack([_box_points([1, 1, 0.5], [0.4, 0.4, 0.4], 400, rng),
                        _box_points([5, 1, 1.5], [0.1, 0.1, 0.1], 30, rng)])  # fmt: skip
    fusion = ObjectFusion(FusionConfig(min_observations=1))
    fusion.integrate([Segment("plant", points)])
    np.testing.assert_allclose(fusion.local_map()[0].position, [1, 1, 0.5], atol=0.05)


def test_bad_segments_are_rejected():
    with pytest.raises(MapError, match="shape"):
        Segment("chair", np.zeros((5, 2)))
    with pytest.raises(MapError, match="label"):
        Segment("", np.zeros((5, 3)))
    with pytest.raises(MapError, match="non-finite"):
        Segment("chair", np.full((5, 3), np.nan))
    with pytest.raises(MapError, match="frame pose"):
        ObjectFusion().integrate([Segment("chair", np.zeros((20, 3)))], frame="camera")


def test_voxel_downsample_keeps_one_point_per_voxel():
    points = np.array([[0.01, 0.01, 0.01], [0.02, 0.02, 0.02], [0.51, 0.0, 0.0]])
    out = voxel_downsample(points, 0.1)
    assert len(out) == 2
    np.testing.assert_allclose(sorted(out[:, 0]), [0.015, 0.51])


@pytest.fixture(scope="module")
def sequence():
    return simulate_sequence(
        0, "tiny", "reconstruction", "orbit", n_keyframes=24, resolution=(160, 120)
    )


def test_fused_objects_match_the_true_instances(sequence):
    local = sequence.local_map.transformed(sequence.T_global_local)  # into the world frame
    matched = {lid: wid for lid, wid in sequence.local_truth.items() if wid is not None}
    assert len(matched) >= 0.9 * len(local)
    assert len(set(matched.values())) >= 0.75 * len(sequence.world.objects)
    right = 0
    for lid, wid in matched.items():
        truth = sequence.world.object(wid)
        obj = local.get(lid)
        bias = max(0.5, 0.35 * truth.model.extent.max())  # large objects are seen in part
        assert np.linalg.norm(obj.position - truth.box_center) < bias, (lid, truth.label)
        right += obj.label == truth.label
    assert right >= 0.9 * len(matched)


def test_the_true_transform_is_not_the_identity_and_keeps_up(sequence):
    T = sequence.T_global_local
    assert np.linalg.norm(T[:3, 3]) > 0.5
    np.testing.assert_allclose(T[:3, 2], [0, 0, 1], atol=1e-9)
    assert not np.allclose(T[:3, :3], np.eye(3))


def test_keyframes_report_new_and_updated_objects(sequence):
    new = [i for kf in sequence.keyframes for i in kf.new]
    assert sorted(new, key=int) == sorted(sequence.local_map.ids.tolist(), key=int)
    assert len(new) == len(set(new))
    assert sum(len(kf.updated) for kf in sequence.keyframes) > 0
    last = sequence.local_map_at(len(sequence.keyframes) - 1)
    assert set(last.ids) == set(sequence.local_map.ids)


def test_the_simulation_is_deterministic():
    a = simulate_sequence(3, "tiny", "cad", "walk", n_keyframes=8, resolution=(96, 72))
    b = simulate_sequence(3, "tiny", "cad", "walk", n_keyframes=8, resolution=(96, 72))
    np.testing.assert_array_equal(a.local_map.positions, b.local_map.positions)
    assert a.local_truth == b.local_truth


def test_noise_changes_labels_only_sometimes():
    seq = simulate_sequence(1, "tiny", "reconstruction", "orbit", n_keyframes=16, resolution=(96, 72),
                            noise=DetectionNoise(confusion_prob=0.5))  # fmt: skip
    wrong = Counter(seq.local_map.get(l).label == seq.world.object(w).label
                    for l, w in seq.local_truth.items() if w is not None)  # fmt: skip
    assert wrong[True] > 0


def test_segments_from_masks_backproject_each_instance():
    from semloc.frontend import segments_from_masks
    from semloc.sim.sensor import DepthSensor, Intrinsics, look_at
    from semloc.sim.shapes import box

    K = Intrinsics.scannet(80, 60)
    sensor = DepthSensor(
        intrinsics=K, meshes=[box((3, -0.6, 1), (0.5, 0.5, 0.5)), box((3, 0.6, 1), (0.5, 0.5, 0.5))]
    )
    T = look_at(np.array([0.0, 0.0, 1.0]), np.array([3.0, 0.0, 1.0]))
    frame = sensor.render(T)
    depth_mm = np.round(frame.depth * 1000).astype(np.uint16)
    masks = [frame.instance == 0, frame.instance == 1]
    segments = segments_from_masks(
        depth_mm, masks, ["cabinet", "plant"], K.matrix, [0.9, 0.8], depth_scale=0.001
    )
    assert [s.label for s in segments] == ["cabinet", "plant"]
    fusion = ObjectFusion(FusionConfig(min_observations=1))
    fusion.integrate(segments, T, frame="camera")
    centres = fusion.local_map().positions
    assert np.all((centres[:, 0] > 2.75) & (centres[:, 0] < 2.85))  # front faces + a bit of side
    np.testing.assert_allclose(centres[:, 1], [-0.6, 0.6], atol=0.05)
    with pytest.raises(MapError, match="masks"):
        segments_from_masks(depth_mm, masks, ["cabinet"], K.matrix)


def test_replay_from_a_later_keyframe_moves_the_odometry_origin(sequence):
    from semloc.sim.trajectory import odometry_origin

    same = sequence.replay(0)
    np.testing.assert_array_equal(same.local_map.positions, sequence.local_map.positions)
    later = sequence.replay(10, 20)
    assert [kf.index for kf in later.keyframes] == list(range(10, 20))
    np.testing.assert_allclose(
        later.T_global_local, odometry_origin(later.keyframes[0].T_world_camera)
    )
    assert all(o.seen >= 10 for o in later.local_map)
    placed = later.local_map.transformed(later.T_global_local)
    for lid, wid in later.local_truth.items():
        if wid is not None:
            truth = sequence.world.object(wid)
            assert np.linalg.norm(placed.get(lid).position - truth.box_center) < max(
                0.5, 0.35 * truth.model.extent.max()
            )
    with pytest.raises(ValueError, match="start"):
        sequence.replay(30)


@given(
    st.lists(st.tuples(*[st.floats(-50, 50, allow_nan=False)] * 3), min_size=1, max_size=60),
    st.sampled_from([0.01, 0.05, 0.3]),
)
@settings(max_examples=60, derandomize=True)
def test_voxel_downsample_gives_one_centroid_inside_each_occupied_voxel(points, size):
    from semloc.pointsets import voxel_keys

    points = np.array(points)
    out = voxel_downsample(points, size)
    assert len(out) == len(np.unique(voxel_keys(points, size)))
    assert len(np.unique(voxel_keys(out, size))) == len(out)  # centroids stay in their voxel
    assert set(voxel_keys(out, size).tolist()) == set(voxel_keys(points, size).tolist())
