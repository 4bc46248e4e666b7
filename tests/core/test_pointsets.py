"""The axes along which positions spread most (the sweeps of the clustering and of guided
matching sort along the first)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from semloc.pointsets import axes_by_spread


def test_largest_extent_first_and_ties_keep_axis_order():
    points = np.array([[0.0, 0.0, 0.0], [1.0, 5.0, 1.0]])
    assert axes_by_spread(points).tolist() == [1, 0, 2]
    assert axes_by_spread(np.zeros((0, 3))).tolist() == [0, 1, 2]


@settings(max_examples=100, deadline=None)
@given(arrays(float, st.tuples(st.integers(1, 20), st.just(3)), elements=st.floats(-1e3, 1e3)))
def test_extents_never_increase_along_the_order(points):
    order = axes_by_spread(points)
    extent = np.ptp(points, axis=0)[order]
    assert sorted(order.tolist()) == [0, 1, 2]
    assert np.all(np.diff(extent) <= 0)
