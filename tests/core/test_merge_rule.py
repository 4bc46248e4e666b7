"""The merge rule is one rule: the compiled gate (`_clustering_fast.agreement`, `gate`,
`gate_window`) is the paper's formula, and every other place that applies it — the Python
`MergeCriterion` and `merge_metric`, the clustering's sweep window, place retrieval's bins —
agrees with it on random inputs."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from semloc import _clustering_fast as kernels
from semloc.clustering import MergeCriterion, merge_metric
from semloc.maps import ObjectMap, SemanticObject
from semloc.places import PlaceIndex, RetrievalConfig

distances = st.floats(0.0, 60.0)
criteria = st.builds(
    MergeCriterion,
    gamma=st.floats(0.05, 0.99),
    tolerance=st.floats(0.0, 1.0),
    min_distance=st.floats(0.0, 0.6),
)


def literal_h(d_global: float, d_local: float, tolerance: float, min_distance: float) -> float:
    """The criterion as clustering.py's docstring states it, in plain Python."""
    d_max = max(d_global, d_local)
    if d_max < min_distance or d_max <= 0:
        return 1.0
    return 1.0 - max(0.0, abs(d_global - d_local) - tolerance) / d_max


@settings(deadline=None)  # the first example loads the compiled kernels
@given(distances, distances, criteria)
def test_the_compiled_gate_is_the_documented_formula(d_global, d_local, criterion):
    tolerance, gamma, min_distance = criterion.tolerance, criterion.gamma, criterion.min_distance
    h = literal_h(d_global, d_local, tolerance, min_distance)
    assert kernels.agreement(d_global, d_local, tolerance, min_distance) == h
    assert kernels.gate(d_global, d_local, tolerance, gamma, min_distance) == (h > gamma)
    assert kernels.agreement(d_global, d_local, 0.0, min_distance) == literal_h(
        d_global, d_local, 0.0, min_distance
    )


@given(st.lists(st.tuples(distances, distances), min_size=1, max_size=12), criteria)
def test_merge_criterion_applies_the_compiled_gate_element_wise(pairs, criterion):
    d_global, d_local = np.array(pairs).T
    tolerance, gamma, min_distance = criterion.tolerance, criterion.gamma, criterion.min_distance
    gates = [kernels.gate(g, l, tolerance, gamma, min_distance) for g, l in pairs]
    scores = [kernels.agreement(g, l, 0.0, min_distance) for g, l in pairs]
    softened = [kernels.agreement(g, l, tolerance, min_distance) for g, l in pairs]
    assert criterion.compatible(d_global, d_local).tolist() == gates
    assert criterion.score(d_global, d_local).tolist() == scores
    assert merge_metric(d_global, d_local, tolerance, min_distance).tolist() == softened
    # broadcasting, as the clustering's revalidation uses it (rows against columns)
    table = criterion.compatible(d_global[:, None], d_local[None, :])
    assert table.shape == (len(pairs), len(pairs))
    assert table[2 % len(pairs), 1 % len(pairs)] == kernels.gate(
        d_global[2 % len(pairs)], d_local[1 % len(pairs)], tolerance, gamma, min_distance
    )
    assert np.shape(merge_metric(d_global[0], d_local[0])) == ()


@given(distances, distances, criteria)
def test_the_gate_passes_only_distances_within_its_window(d_global, d_local, criterion):
    """The sweep tests only global pairs within the window's top (a hair wider, as the
    clustering widens it), place retrieval only the bins within the window: neither may miss
    a pair the gate passes; and the window is tight (just outside it the gate fails)."""
    tolerance, gamma, min_distance = criterion.tolerance, criterion.gamma, criterion.min_distance
    lowest, highest = criterion.window(np.array([d_local]))
    lowest, highest = float(lowest[0]), float(highest[0])
    assert (lowest, highest) == kernels.gate_window(d_local, tolerance, gamma, min_distance)
    if kernels.gate(d_global, d_local, tolerance, gamma, min_distance):
        assert lowest <= d_global <= highest
    assert not kernels.gate(highest * (1 + 1e-6) + 1e-9, d_local, tolerance, gamma, min_distance)
    if lowest > 1e-6:
        below = lowest * (1 - 1e-6) - 1e-9
        assert not kernels.gate(below, d_local, tolerance, gamma, min_distance)


@settings(max_examples=60)
@given(st.floats(0.0, 7.0), st.floats(0.0, 7.0), criteria, st.sampled_from([0.25, 0.5, 1.0]))
def test_place_retrieval_looks_up_every_map_distance_the_gate_passes(
    map_gap, local_gap, criterion, bin_size
):
    """A map chair and table `map_gap` apart support a local chair with a table `local_gap`
    from it whenever the gate passes the pair and its window lies within the index's reach."""
    objects = [SemanticObject("c", "chair", [0.1, 0.1, 0.1]),
               SemanticObject("t", "table", [0.1 + map_gap, 0.1, 0.1])]  # fmt: skip
    index = PlaceIndex(ObjectMap(objects, name="pair"), RetrievalConfig(cell=20.0, bin=bin_size))
    local_xyz = np.array([[0.0, 0, 0], [local_gap, 0, 0]])
    d_map = float(np.linalg.norm(objects[1].position - objects[0].position))  # as indexed
    d_local = float(np.linalg.norm(local_xyz[1] - local_xyz[0]))
    passes = kernels.gate(
        d_map, d_local, criterion.tolerance, criterion.gamma, criterion.min_distance
    )
    indexed = criterion.window(np.array([d_local]))[1][0] <= index.config.reach
    support = index.support(local_xyz, [np.array([0]), np.array([1])], criterion)
    if passes and indexed and d_map <= index.config.reach:
        assert support[0].max() == 1
