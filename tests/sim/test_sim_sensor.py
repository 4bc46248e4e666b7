"""The ray-cast depth sensor against analytic ray-box intersections."""

from __future__ import annotations

import numpy as np

from semloc.sim.sensor import DepthSensor, Intrinsics, backproject, look_at
from semloc.sim.shapes import box


def _slab(origin, directions, lo, hi):
    """Distance along each direction to the box [lo, hi] (inf where the ray misses)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (lo - origin) / directions
        t2 = (hi - origin) / directions
    t_near = np.nanmax(np.minimum(t1, t2), axis=1)
    t_far = np.nanmin(np.maximum(t1, t2), axis=1)
    hit = (t_far >= t_near) & (t_near > 0)
    return np.where(hit, t_near, np.inf)


def test_depth_equals_analytic_ray_box_distance():
    K = Intrinsics.scannet(160, 120)
    lo, hi = np.array([2.0, -0.5, 0.2]), np.array([2.6, 0.7, 1.4])
    sensor = DepthSensor(intrinsics=K, meshes=[box(tuple((lo + hi) / 2), tuple(hi - lo))])
    T = look_at(np.array([0.0, 0.1, 1.0]), np.array([2.0, 0.0, 0.7]))
    frame = sensor.render(T)
    dirs = K.ray_directions().reshape(-1, 3) @ T[:3, :3].T  # camera z = 1: t is the z-depth
    expected = _slab(T[:3, 3], dirs, lo, hi).reshape(K.height, K.width)
    hit = np.isfinite(expected)
    assert hit.sum() > 1000 and (~hit).sum() > 1000  # the box fills part of the view
    both = hit & (frame.depth > 0)
    assert (both.sum() / hit.sum()) > 0.99  # only grazing edge pixels may differ
    np.testing.assert_allclose(frame.depth[both], expected[both], atol=1e-4)
    assert np.all(frame.instance[both] == 0)
    assert np.count_nonzero((~hit) & (frame.depth > 0)) <= 0.01 * hit.sum()
    assert np.all(frame.instance[frame.depth == 0] == -1)


def test_backprojected_points_lie_on_the_box_surface():
    K = Intrinsics.scannet(80, 60)
    sensor = DepthSensor(intrinsics=K, meshes=[box((3.0, 0.0, 1.0), (1.0, 1.0, 1.0))])
    T = look_at(np.array([0.0, 0.0, 1.2]), np.array([3.0, 0.0, 1.0]))
    frame = sensor.render(T)
    points = backproject(frame.depth, K) @ T[:3, :3].T + T[:3, 3]
    assert len(points) > 100
    np.testing.assert_allclose(points[:, 0], 2.5, atol=1e-4)  # the face towards the camera


def test_depth_noise_grows_with_distance_and_is_seeded():
    K = Intrinsics.scannet(64, 48)
    sensor = DepthSensor(intrinsics=K, meshes=[box((4.0, 0.0, 1.0), (0.2, 6.0, 6.0))])
    T = look_at(np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 1.0]))
    clean = sensor.render(T).depth
    noisy = sensor.render(T, np.random.default_rng(1)).depth
    again = sensor.render(T, np.random.default_rng(1)).depth
    np.testing.assert_array_equal(noisy, again)
    error = (noisy - clean)[clean > 0]
    assert 0.002 < error.std() < 0.05


def test_max_depth_gives_no_return():
    K = Intrinsics.scannet(32, 24)
    sensor = DepthSensor(
        intrinsics=K, meshes=[box((10.0, 0.0, 1.0), (0.2, 8.0, 8.0))], max_depth=8.0
    )
    frame = sensor.render(look_at(np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 1.0])))
    assert np.all(frame.depth == 0) and np.all(frame.instance == -1)
