"""Compiled KD-trees: exact bounded k-nearest search per tree of a forest, neighbourhood shapes."""

from __future__ import annotations

import numpy as np
from hypothesis import example, given, settings
from hypothesis import strategies as st

from semloc.neighbours import Forest, KdTree, neighbourhood_shapes

seeds = st.integers(0, 2**32 - 1)


def brute_knn(points: np.ndarray, query: np.ndarray, k: int, bound: float):
    d = np.linalg.norm(points[None] - query[:, None], axis=2)
    order = np.argsort(d, axis=1, kind="stable")[:, :k]
    dist = np.take_along_axis(d, order, axis=1)
    idx = np.where(dist < bound, order, -1)
    return idx, np.where(dist < bound, dist, np.inf)


@settings(max_examples=40)
@given(seeds, st.integers(1, 300), st.integers(1, 20), st.floats(0.01, 3.0))
def test_forest_search_equals_brute_force_in_each_tree(seed, n, k, bound) -> None:
    rng = np.random.default_rng(seed)
    clouds = [rng.normal(size=(int(m), 3)) * rng.uniform(0.1, 2) + rng.normal(0, 5, 3)
              for m in rng.integers(1, n + 1, size=3)]  # fmt: skip
    trees = [KdTree.build(c) for c in clouds]
    forest = Forest.of(trees)
    offsets = np.cumsum([0] + [len(c) for c in clouds])
    for tree, cloud in enumerate(clouds):
        query = cloud[rng.integers(len(cloud), size=25)] + rng.normal(0, 0.5, (25, 3))
        idx, dist = forest.nearest(query, np.full(25, tree), k, bound)
        kk = min(k, len(cloud))
        ref_idx, ref_dist = brute_knn(cloud, query, kk, bound)
        np.testing.assert_allclose(dist[:, :kk], ref_dist, rtol=1e-12, atol=1e-12)
        found = ref_idx >= 0
        # equal distances may come in either order: compare the distances of the points found
        got = trees[tree].order[np.where(found, idx[:, :kk] - offsets[tree], 0)]
        np.testing.assert_allclose(
            np.where(found, np.linalg.norm(cloud[got] - query[:, None], axis=2), np.inf), ref_dist
        )
        assert np.all(idx[:, kk:] == -1) and np.all(np.isinf(dist[:, kk:]))


def test_far_queries_find_nothing_and_duplicates_are_kept() -> None:
    points = np.array([[0.0, 0.0, 0.0]] * 5 + [[1.0, 0.0, 0.0]] * 20)
    tree = KdTree.build(points)
    idx, dist = Forest.of([tree]).nearest(
        np.array([[0.1, 0, 0], [50.0, 0, 0]]), np.zeros(2), 6, 0.5
    )
    np.testing.assert_allclose(dist[0, :5], 0.1)
    assert sorted(tree.order[idx[0, :5]]) == [0, 1, 2, 3, 4] and idx[0, 5] == -1
    assert np.all(idx[1] == -1) and np.all(np.isinf(dist[1]))


@settings(max_examples=25)
@given(seeds, st.integers(8, 200))
def test_neighbourhood_shapes_match_an_eigendecomposition(seed, n) -> None:
    rng = np.random.default_rng(seed)
    points = rng.normal(size=(n, 3)) * [1.0, 0.7, 0.05]  # a noisy slab: well-defined normals
    tree = KdTree.build(points)
    normals, variation = neighbourhood_shapes(tree, 8)
    np.testing.assert_array_equal(tree.points, points[tree.order])
    points = tree.points  # the shapes come in tree order
    idx = np.argsort(np.linalg.norm(points[None] - points[:, None], axis=2), axis=1)[:, :8]
    nb = points[idx] - points[idx].mean(axis=1, keepdims=True)
    values, vectors = np.linalg.eigh(np.swapaxes(nb, 1, 2) @ nb)
    np.testing.assert_allclose(variation, values[:, 0] / values.sum(axis=1), atol=1e-9)
    separated = values[:, 1] > 1.01 * values[:, 0]  # a unique smallest direction
    cos = np.abs(np.sum(normals * vectors[:, :, 0], axis=1))
    np.testing.assert_allclose(cos[separated], 1.0, atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0)


@settings(max_examples=40)
@given(seeds, st.floats(0.05, 2.0))
@example(0, 0.36874235689686835)  # a point at squared distance bound * bound, 1 ulp below bound**2
def test_box_test_keeps_answers_at_the_bound_on_lattice_points(seed, bound) -> None:
    """Points and queries on a lattice put many distances exactly at the bound and queries
    exactly on the trees' box faces: the box test must answer as the search does."""
    rng = np.random.default_rng(seed)
    step = bound / rng.integers(1, 4)
    clouds = [rng.integers(-3, 4, size=(int(m), 3)) * step for m in rng.integers(1, 30, size=3)]
    forest = Forest.of([KdTree.build(c) for c in clouds])
    queries = rng.integers(-8, 9, size=(200, 3)) * step
    tree_of_row = rng.integers(0, 3, size=200)
    idx, dist = forest.nearest(queries, tree_of_row, 2, bound)
    for r, (q, t) in enumerate(zip(queries, tree_of_row)):
        rows = np.arange(forest.starts[t], forest.starts[t + 1])
        d = np.sqrt(np.sum((forest.points[rows] - q) ** 2, axis=1))
        # within the bound: squared distance below bound * bound, as the search compares (pow's
        # bound**2 may round 1 ulp higher, and a lattice point can sit exactly there)
        within = np.sort(d[np.sum((forest.points[rows] - q) ** 2, axis=1) < bound * bound])[:2]
        assert np.array_equal(np.sort(dist[r][np.isfinite(dist[r])]), within)
        assert np.all((idx[r] >= 0) == np.isfinite(dist[r]))


def test_a_tree_without_points_has_an_empty_box_and_finds_nothing() -> None:
    empty = KdTree.build(np.zeros((0, 3)))
    forest = Forest.of([empty, KdTree.build(np.zeros((1, 3)))])
    idx, dist = forest.nearest(np.zeros((2, 3)), np.array([0, 1]), 1, 1.0)
    assert idx.tolist() == [[-1], [0]] and dist[1, 0] == 0.0  # the empty tree has no rows
