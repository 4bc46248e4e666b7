"""Geometry helpers of the importers: upright boxes, voxel filter, surface sampling."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from semloc.io.geometry import (
    quaternion_matrix,
    sample_box_surface,
    upright_box,
)
from semloc.pointsets import voxel_downsample

_points = arrays(np.float64, st.tuples(st.integers(1, 40), st.just(3)),
                 elements=st.floats(-5, 5, allow_nan=False))  # fmt: skip


@settings(max_examples=80)
@given(points=_points)
def test_upright_box_is_tight_and_no_larger_than_the_axis_aligned_box(points):
    centre, size, rotation = upright_box(points)
    np.testing.assert_allclose(rotation @ rotation.T, np.eye(3), atol=1e-9)
    np.testing.assert_allclose(rotation[:, 2], [0, 0, 1])
    local = (points - centre) @ rotation
    assert np.all(np.abs(local) <= size / 2 + 1e-9)
    assert size[0] >= size[1] - 1e-9
    assert size[2] == np.ptp(points[:, 2])
    aabb = np.ptp(points[:, :2], axis=0)
    assert size[0] * size[1] <= aabb[0] * aabb[1] + 1e-9


@settings(max_examples=40)
@given(
    yaw=st.floats(-np.pi, np.pi),
    size=st.tuples(st.floats(0.2, 3), st.floats(0.2, 3), st.floats(0.1, 2)),
    up=st.sampled_from([(0, 0, 1), (0, 1, 0), (1, 1, 1)]),
)
def test_upright_box_recovers_a_sampled_box(yaw, size, up):
    up = np.array(up, float) / np.linalg.norm(up)
    from semloc.io.geometry import up_basis

    basis = up_basis(up)
    c, s = np.cos(yaw), np.sin(yaw)
    rotation = basis @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) / 2
    points = (corners * size) @ rotation.T + [1, 2, 3]
    centre, got, _ = upright_box(points, up)
    np.testing.assert_allclose(centre, [1, 2, 3], atol=1e-7)
    np.testing.assert_allclose(sorted(got[:2]), sorted(size[:2]), atol=1e-7)
    assert abs(got[2] - size[2]) < 1e-7


def test_voxel_downsample_means_per_voxel():
    points = np.array([[0.01, 0.01, 0.01], [0.03, 0.03, 0.03], [1.0, 1.0, 1.0]])
    np.testing.assert_allclose(voxel_downsample(points, 0.1), [[0.02, 0.02, 0.02], [1, 1, 1]])
    assert len(voxel_downsample(points, 0)) == 3


def test_box_surface_points_lie_on_the_faces():
    rng = np.random.default_rng(0)
    rotation = quaternion_matrix(0.9, 0.1, 0.3, -0.2)
    points = sample_box_surface(np.array([1, 2, 3.0]), np.array([2, 1, 0.5]), rotation, 500, rng)
    local = (points - [1, 2, 3]) @ rotation
    np.testing.assert_allclose(np.max(np.abs(local) / [1, 0.5, 0.25], axis=1), 1.0)
