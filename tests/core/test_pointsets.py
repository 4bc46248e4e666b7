"""Voxel sums, the axes along which positions spread most (the sweeps of the clustering and of
guided matching sort along the first) and the sweep order built on them."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from semloc.maps import ObjectMap, SemanticObject
from semloc.pointsets import SweepOrder, axes_by_spread, voxel_accumulate, voxel_keys


def test_largest_extent_first_and_ties_keep_axis_order():
    points = np.array([[0.0, 0.0, 0.0], [1.0, 5.0, 1.0]])
    assert axes_by_spread(points).tolist() == [1, 0, 2]
    assert axes_by_spread(np.zeros((0, 3))).tolist() == [0, 1, 2]


@settings(max_examples=100)
@given(arrays(float, st.tuples(st.integers(1, 20), st.just(3)), elements=st.floats(-1e3, 1e3)))
def test_extents_never_increase_along_the_order(points):
    order = axes_by_spread(points)
    extent = np.ptp(points, axis=0)[order]
    assert sorted(order.tolist()) == [0, 1, 2]
    assert np.all(np.diff(extent) <= 0)


@settings(max_examples=100)
@given(arrays(float, st.tuples(st.integers(0, 20), st.just(3)), elements=st.integers(-5, 5)))
def test_sweep_ranks_are_dense_and_follow_the_longest_axis(points):
    """Whole-number coordinates make ties along the axis common: equal coordinates share a
    rank, a larger coordinate has a larger one, and the ranks are 0..n_ranks-1."""
    order = SweepOrder.of(points)
    assert [order.axis, order.cross_axis] == axes_by_spread(points).tolist()[:2]
    along = points[:, order.axis]
    assert order.rank.dtype == np.int64 and len(order.rank) == len(points)
    assert order.n_ranks == len(np.unique(along))
    assert sorted(set(order.rank.tolist())) == list(range(order.n_ranks))
    less = along[:, None] < along[None, :]
    assert np.array_equal(order.rank[:, None] < order.rank[None, :], less)


def test_a_map_finds_its_sweep_order_once():
    objects = [SemanticObject(f"o{i}", "chair", [0.0, 2.0 * (i % 3), 0.1 * i]) for i in range(6)]
    world = ObjectMap(objects)
    order = world.sweep_order
    assert order is world.sweep_order  # cached with the map's other column views
    assert (order.axis, order.cross_axis) == (1, 2)
    assert order.rank.tolist() == [0, 1, 2, 0, 1, 2] and order.n_ranks == 3


@settings(max_examples=150)
@given(
    arrays(float, st.tuples(st.integers(0, 400), st.just(3)), elements=st.floats(-5, 5)),
    st.sampled_from([0.01, 0.05, 0.25, 1.0]),
    st.booleans(),
    st.booleans(),
)
def test_voxel_sums_are_numpys_unique_and_bincount(points, size, on_grid, single):
    """The compiled voxel sums equal the numpy formulation bit for bit (keys ascending, each
    voxel's points summed in input order), on voxel boundaries and in float32 as well."""
    if on_grid:
        points = np.round(points / size) * size  # many points on voxel boundaries and equal
    if single:
        points = points.astype(np.float32)
    keys = voxel_keys(points, size)
    unique, inverse = np.unique(keys, return_inverse=True)
    inverse = inverse.ravel()
    sums = np.stack([np.bincount(inverse, points[:, c], len(unique)) for c in range(3)], axis=1)
    counts = np.bincount(inverse, minlength=len(unique)).astype(float)
    got = voxel_accumulate(points, size)
    assert np.array_equal(got[0], unique)
    assert np.array_equal(got[1], sums.reshape(-1, 3)) and np.array_equal(got[2], counts)
