"""Nearest-neighbour search in compiled code: a KD-tree per object cloud, searched in bounds,
and the shape of each point's neighbourhood (normal and surface variation).

Pose recovery asks, many times per localization, for the k nearest points of a partner object
within a radius (ICP correspondences, fitness, the rotation search).  The search must run
inside the compiled ICP loop, so the tree is plain arrays that numba functions read:

- `KdTree.build(points)` stores the points in tree order (`points`), the split axis of each
  node (`axes`) and where each tree-ordered point came from (`order`).  The tree is implicit: the
  node of a range [lo, hi) splits at its median `mid = (lo + hi) // 2` on `axes[mid]`; ranges of
  at most `LEAF` points are scanned.  Built once per object cloud.
- `knn_within(...)` (compiled) writes the k nearest points closer than a bound, sorted by
  distance; a query farther than the bound from every point costs a few node visits.
- `Forest.of(trees)` concatenates the trees of several objects so that one compiled call
  searches each query in its own object's tree (`Forest.nearest`); answers are rows of the
  concatenated tree-ordered points.  `knn_in_tree(...)` (compiled) searches one tree of a forest
  and answers "none" without a search when the tree's bounding box is beyond the bound (the
  rotation search, whose rotations put most points far from their partner).
- `neighbourhood_shapes(tree, k)`: per point, the unit normal of its k-neighbourhood (the
  smallest-eigenvalue direction of the covariance, in closed form) and its surface variation.

Pure computation on numpy arrays (no I/O).
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass

import numba
import numpy as np

__all__ = ["Forest", "KdTree", "knn_in_tree", "knn_within", "neighbourhood_shapes"]

LEAF = 8  # ranges of at most this many points are scanned, not split
_STACK = 128  # deeper than any tree of up to 2^60 points needs


@numba.njit(cache=True, nogil=True)
def _widest_axis(points: np.ndarray, rows: np.ndarray) -> int:
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    for r in rows:
        for c in range(3):
            lo[c] = min(lo[c], points[r, c])
            hi[c] = max(hi[c], points[r, c])
    return int(np.argmax(hi - lo))


@numba.njit(cache=True, nogil=True)
def _build(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tree order and split axes: each range is sorted on its widest axis, split at its median."""
    n = len(points)
    order = np.arange(n)
    axes = np.zeros(n, dtype=np.int8)
    stack = np.empty((_STACK, 2), dtype=np.int64)
    stack[0, 0], stack[0, 1] = 0, n
    top = 1
    while top > 0:
        top -= 1
        lo, hi = stack[top, 0], stack[top, 1]
        if hi - lo <= LEAF:
            continue
        axis = _widest_axis(points, order[lo:hi])
        keys = np.empty(hi - lo)
        for i in range(hi - lo):
            keys[i] = points[order[lo + i], axis]
        order[lo:hi] = order[lo:hi][np.argsort(keys, kind="mergesort")]
        mid = (lo + hi) // 2
        axes[mid] = axis
        stack[top, 0], stack[top, 1] = lo, mid
        stack[top + 1, 0], stack[top + 1, 1] = mid + 1, hi
        top += 2
    return order, axes


_EMPTY = np.array([np.inf] * 3 + [-np.inf] * 3)  # the box of no points (shared: read-only)
_EMPTY.flags.writeable = False


@dataclass(frozen=True)
class KdTree:
    """A static KD-tree over (n, 3) points: the points in tree order, the split axes, and for
    each tree row the index of its point in the array the tree was built from."""

    points: np.ndarray
    axes: np.ndarray
    order: np.ndarray
    box: np.ndarray  # (6,): the points' lower then upper corner (inf / -inf without points)

    @classmethod
    def build(cls, points: np.ndarray) -> KdTree:
        points = np.ascontiguousarray(points, dtype=np.float64)
        order, axes = _build(points)
        box = np.concatenate([points.min(axis=0), points.max(axis=0)]) if len(points) else _EMPTY
        return cls(np.ascontiguousarray(points[order]), axes, order.astype(np.int32), box)

    def __len__(self) -> int:
        return len(self.points)


@numba.njit(cache=True, nogil=True, inline="always")
def _insert(d2: float, j: int, found: int, k: int, best_d2, best_j) -> int:
    """Insert (d2, j) into the sorted best lists; returns the new count."""
    i = min(found, k - 1)
    while i > 0 and best_d2[i - 1] > d2:
        best_d2[i], best_j[i] = best_d2[i - 1], best_j[i - 1]
        i -= 1
    best_d2[i], best_j[i] = d2, j
    return min(found + 1, k)


@numba.njit(cache=True, nogil=True, inline="always")
def _offer(points, j: int, query, found: int, worst: float, k: int, bound2: float, best_d2, best_j):
    """Offer tree row j to the best lists; returns the new count and pruning distance."""
    d2 = 0.0
    for c in range(3):
        diff = query[c] - points[j, c]
        d2 += diff * diff
    if d2 < worst:
        found = _insert(d2, j, found, k, best_d2, best_j)
        if found == k:
            worst = min(bound2, best_d2[k - 1])
    return found, worst


@numba.njit(cache=True, nogil=True)
def knn_within(
    points, axes, lo0: int, hi0: int, query, k: int, bound2: float, best_d2, best_j, stack, gaps
) -> int:
    """The k nearest tree points of `query` with squared distance < `bound2`, in the tree
    occupying rows [lo0, hi0) of `points`/`axes` (a `KdTree` or one tree of a `Forest`).
    Writes squared distances and tree rows, ascending, into `best_d2` / `best_j`; returns
    how many were found.  `stack` (_STACK, 2) int64 and `gaps` (_STACK,) are scratch space."""
    found = 0
    worst = bound2
    stack[0, 0], stack[0, 1], gaps[0] = lo0, hi0, 0.0
    top = 1
    while top > 0:
        top -= 1
        if gaps[top] >= worst:
            continue
        lo, hi, gap = stack[top, 0], stack[top, 1], gaps[top]
        if hi - lo <= LEAF:
            for j in range(lo, hi):
                found, worst = _offer(points, j, query, found, worst, k, bound2, best_d2, best_j)
            continue
        mid = (lo + hi) // 2
        found, worst = _offer(points, mid, query, found, worst, k, bound2, best_d2, best_j)
        axis = axes[mid]
        side = query[axis] - points[mid, axis]
        far_gap = max(gap, side * side)
        if side < 0:  # far side first on the stack, so the near side is searched first
            stack[top, 0], stack[top, 1], gaps[top] = mid + 1, hi, far_gap
            stack[top + 1, 0], stack[top + 1, 1], gaps[top + 1] = lo, mid, gap
        else:
            stack[top, 0], stack[top, 1], gaps[top] = lo, mid, far_gap
            stack[top + 1, 0], stack[top + 1, 1], gaps[top + 1] = mid + 1, hi, gap
        top += 2
    return found


@numba.njit(cache=True, nogil=True, inline="always")
def knn_in_tree(points, axes, starts, boxes, tree: int, query, k: int, bound2: float, best_d2,
                best_j, stack, gaps) -> int:  # fmt: skip
    """`knn_within` in tree `tree` of a forest's arrays; no search when the tree's bounding
    box is not closer than the bound (the same answer: no point is closer than its box, in
    floating point too, as each squared axis gap is at most the point's)."""
    gap2 = 0.0
    for c in range(3):
        below = boxes[tree, c] - query[c]
        above = query[c] - boxes[tree, 3 + c]
        if below > 0:
            gap2 += below * below
        elif above > 0:
            gap2 += above * above
    if gap2 >= bound2:
        return 0
    lo, hi = starts[tree], starts[tree + 1]
    return knn_within(points, axes, lo, hi, query, k, bound2, best_d2, best_j, stack, gaps)


@numba.njit(cache=True, nogil=True)
def scratch() -> tuple[np.ndarray, np.ndarray]:
    """The scratch space `knn_within` needs (allocate once per batch of queries)."""
    return np.empty((_STACK, 2), dtype=np.int64), np.empty(_STACK)


@numba.njit(cache=True, nogil=True)
def _nearest_rows(points, axes, starts, boxes, tree_of_row, queries, k: int, bound: float):
    """`Forest.nearest` in compiled code: forest rows and distances, -1 / inf
    where fewer than k points are within `bound`."""
    n = len(queries)
    idx = np.full((n, k), -1, dtype=np.int64)
    dist = np.full((n, k), np.inf)
    best_d2 = np.empty(k)
    best_j = np.empty(k, dtype=np.int64)
    stack, gaps = scratch()
    bound2 = bound * bound
    for r in range(n):
        found = knn_in_tree(
            points, axes, starts, boxes, tree_of_row[r], queries[r], k, bound2, best_d2, best_j,
            stack, gaps,
        )  # fmt: skip
        for i in range(found):
            idx[r, i] = best_j[i]
            dist[r, i] = np.sqrt(best_d2[i])
    return idx, dist


@dataclass(frozen=True)
class Forest:
    """Several KD-trees in one set of arrays: tree i occupies rows [starts[i], starts[i+1])
    of the concatenated tree-ordered points; `boxes[i]` is its bounding box."""

    points: np.ndarray
    axes: np.ndarray
    starts: np.ndarray
    tree_boxes: tuple[np.ndarray, ...]  # each tree's `KdTree.box`

    @classmethod
    def of(cls, trees: Sequence[KdTree]) -> Forest:
        starts = np.cumsum([0] + [len(t) for t in trees]).astype(np.int64)
        boxes = tuple(t.box for t in trees)
        if not trees:
            return cls(np.zeros((0, 3)), np.zeros(0, np.int8), starts, boxes)
        points = np.concatenate([t.points for t in trees])
        return cls(points, np.concatenate([t.axes for t in trees]), starts, boxes)

    @functools.cached_property
    def boxes(self) -> np.ndarray:
        """(trees, 6): each tree's lower then upper corner (stacked when first asked: only
        the searches that test boxes need them)."""
        return np.stack(self.tree_boxes) if self.tree_boxes else np.zeros((0, 6))

    @property
    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(points, axes, starts, boxes), as `knn_in_tree` takes them."""
        return self.points, self.axes, self.starts, self.boxes

    def nearest(
        self, queries: np.ndarray, tree_of_row: np.ndarray, k: int, bound: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """Per query row, its k nearest points closer than `bound` in tree `tree_of_row[r]`:
        rows of the forest's points (n, k) and distances (n, k), ascending;
        index -1 and distance inf where there are fewer."""
        queries = np.ascontiguousarray(queries, dtype=np.float64).reshape(-1, 3)
        rows = np.ascontiguousarray(tree_of_row, dtype=np.int64)
        return _nearest_rows(*self.arrays, rows, queries, k, float(bound))


@numba.njit(cache=True, nogil=True)
def _smallest_eigenvector(C: np.ndarray, M: np.ndarray, out: np.ndarray) -> float:
    """Unit eigenvector (into `out`) and value of the smallest eigenvalue of a symmetric 3x3
    matrix: trigonometric eigenvalues, then the widest cross product of two rows of
    C - lambda I (written into the scratch `M`).  Isotropic or line-like neighbourhoods get
    (0, 0, 1)."""
    q = (C[0, 0] + C[1, 1] + C[2, 2]) / 3
    off = C[0, 1] ** 2 + C[0, 2] ** 2 + C[1, 2] ** 2
    diag = (C[0, 0] - q) ** 2 + (C[1, 1] - q) ** 2 + (C[2, 2] - q) ** 2
    p = np.sqrt((diag + 2 * off) / 6)
    scale = p if p > 0 else 1.0
    for a in range(3):
        for b in range(3):
            M[a, b] = (C[a, b] - (q if a == b else 0.0)) / scale  # B = (C - q I) / p
    det = (M[0, 0] * (M[1, 1] * M[2, 2] - M[1, 2] * M[2, 1])
           - M[0, 1] * (M[1, 0] * M[2, 2] - M[1, 2] * M[2, 0])
           + M[0, 2] * (M[1, 0] * M[2, 1] - M[1, 1] * M[2, 0]))  # fmt: skip
    phi = np.arccos(min(max(det / 2, -1.0), 1.0)) / 3
    smallest = q + 2 * p * np.cos(phi + 2 * np.pi / 3)
    for a in range(3):
        for b in range(3):
            M[a, b] = C[a, b] - (smallest if a == b else 0.0)
    best, size = -1, 0.0
    for a, b in ((0, 1), (0, 2), (1, 2)):
        x = M[a, 1] * M[b, 2] - M[a, 2] * M[b, 1]
        y = M[a, 2] * M[b, 0] - M[a, 0] * M[b, 2]
        z = M[a, 0] * M[b, 1] - M[a, 1] * M[b, 0]
        norm = np.sqrt(x * x + y * y + z * z)
        if norm > size:
            best, size = a + b, norm
            out[0], out[1], out[2] = x, y, z
    if best < 0 or size <= 1e-12 * max(q, 1e-300) ** 2:
        out[0], out[1], out[2] = 0.0, 0.0, 1.0
    else:
        out[0], out[1], out[2] = out[0] / size, out[1] / size, out[2] / size
    return max(smallest, 0.0)


@numba.njit(cache=True, nogil=True)
def _shapes(points, axes, k):
    n = len(points)
    normals = np.empty((n, 3))
    variation = np.empty(n)
    best_d2 = np.empty(k)
    best_j = np.empty(k, dtype=np.int64)
    stack, gaps = scratch()
    C, M = np.empty((3, 3)), np.empty((3, 3))
    mean = np.empty(3)
    for r in range(n):
        found = knn_within(points, axes, 0, n, points[r], k, np.inf, best_d2, best_j, stack, gaps)
        for c in range(3):
            total = 0.0
            for i in range(found):
                total += points[best_j[i], c]
            mean[c] = total / found
        for a in range(3):
            for b in range(a, 3):
                total = 0.0
                for i in range(found):
                    j = best_j[i]
                    total += (points[j, a] - mean[a]) * (points[j, b] - mean[b])
                C[a, b] = C[b, a] = total
        trace = C[0, 0] + C[1, 1] + C[2, 2]
        smallest = _smallest_eigenvector(C, M, normals[r])
        variation[r] = smallest / trace if trace > 0 else 1.0
    return normals, variation


def neighbourhood_shapes(tree: KdTree, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Per point of the tree (in tree order): the unit normal of its k nearest points
    (itself included; unoriented) and their surface variation, smallest eigenvalue / trace of
    their covariance (0 on a plane, 1/3 when isotropic; 1 for a single repeated point)."""
    return _shapes(tree.points, tree.axes, min(k, len(tree)))
