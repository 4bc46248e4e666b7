"""Point-set registration kernels in compiled code: the inner loops of pose recovery.

`semloc.pose` decides what to align and keeps the best candidate; this module owns the loops
that touch every point, compiled with numba so that no Python runs per iteration or per point:

- `icp`: the graduated robust ICP of `semloc.pose` (Tukey-weighted Gauss-Newton on
  point-to-plane plus a little point-to-point error, normal-compatible correspondences searched
  in each local point's partner object only, 4-DoF about an axis or 6-DoF);
- `fitness`: inlier share, inlier RMS and smooth score of a pose;
- `rotation_scores`: the smooth score of many rotations about a pivot (the global search);
- `thinned_rows`: which local points a problem moves (every point, or every (total / limit)-th
  of each cloud).

The partner objects of a problem are one `semloc.neighbours.Forest`; `tree_of_row[i]` names
the partner tree of local point i.  Targets (`normals`, `flatness`) are the partners' arrays
concatenated in the forest's order; the forest's points are the partners' points.  Pure computation on numpy arrays.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from semloc.neighbours import Forest, knn_in_tree, knn_within, scratch

__all__ = ["IcpSettings", "Targets", "fitness", "icp", "rotation_scores", "thinned_rows"]

_FIRST_NEIGHBOURS = 2  # neighbours tried before the full k of a correspondence search


class Targets(NamedTuple):
    """The partner objects of one problem: their forest (whose rows are their points) and
    their point attributes concatenated in the forest's order."""

    forest: Forest
    normals: np.ndarray  # (M, 3) unoriented unit normals
    flatness: np.ndarray  # (M,) in [0, 1]


class IcpSettings(NamedTuple):
    """The numbers of one ICP run (see `semloc.pose.PoseConfig` and its constants)."""

    iterations: int
    kernel_start: float
    kernel: float
    cos_max: float  # cosine of the normal-compatibility angle; 0 = no normal test
    neighbours_coarse: int
    neighbours_final: int
    converged: float  # an iteration moving the points less than this x kernel has converged
    point_to_point: float  # weight of the point-to-point error next to point-to-plane


@numba.njit(cache=True, nogil=True, inline="always")
def _move(R: np.ndarray, t: np.ndarray, x: np.ndarray, out: np.ndarray) -> None:
    """out = R @ x + t, without allocating (t may be a zero vector for a rotation)."""
    for c in range(3):
        out[c] = R[c, 0] * x[0] + R[c, 1] * x[1] + R[c, 2] * x[2] + t[c]


@numba.njit(cache=True, nogil=True)
def _rodrigues(v: np.ndarray) -> np.ndarray:
    """Rotation matrix of a rotation vector."""
    angle = np.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    R = np.eye(3)
    if angle < 1e-15:
        return R
    k = v / angle
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return R + np.sin(angle) * K + (1.0 - np.cos(angle)) * (K @ K)


@numba.njit(cache=True, nogil=True, inline="always")
def _first_compatible(best_j, found, start, pn, t_normals, t_flatness, cos_max) -> int:
    """The first of the found neighbours (from `start`) whose normal is within the angle of
    `pn` (unoriented; any normal of a non-flat point is); -1 if none."""
    for i in range(start, found):
        j = best_j[i]
        if cos_max <= 0 or t_flatness[j] < 0.5:
            return i
        if (
            abs(t_normals[j, 0] * pn[0] + t_normals[j, 1] * pn[1] + t_normals[j, 2] * pn[2])
            >= cos_max
        ):
            return i
    return -1


@numba.njit(cache=True, nogil=True, inline="always")
def _bound(p, f_points, last, first, kernel2) -> float:
    """A squared search bound for the `first` nearest of p: kernel2, or just above the larger
    squared distance to its two nearest of the last iteration when they are known (the second
    nearest is no farther; the margin keeps a tie with it inside)."""
    if first != 2 or last[1] < 0:
        return kernel2
    farther = 0.0
    for j in last:
        d2 = 0.0
        for c in range(3):
            diff = p[c] - f_points[j, c]
            d2 += diff * diff
        farther = max(farther, d2)
    return min(kernel2, farther * (1.0 + 1e-9) + 1e-300)


@numba.njit(cache=True, nogil=True)
def _correspondences(src, src_normals, tree_of_row, R, t, f_points, f_axes, f_starts,
                     t_normals, t_flatness, kernel, cos_max, k, m, q, n, w, last) -> int:  # fmt: skip
    """For each local point moved by (R, t): the nearest of its k nearest partner points within
    `kernel` whose normal is compatible (any normal of a non-flat point is).  Writes the moved
    point, its partner, the partner's normal scaled by sqrt(flatness) and the Tukey weight of
    each found correspondence into m, q, n, w; returns how many.

    `last` (n, 2) holds each point's two nearest partner rows of the previous call (-1: none)
    and is updated: their distances after the move bound the search for the two nearest (the
    same answer, fewer tree nodes visited, as points move little between iterations)."""
    if cos_max <= 0:
        k = 1
    best_d2 = np.empty(k)
    best_j = np.empty(k, dtype=np.int64)
    stack, gaps = scratch()
    kernel2 = kernel * kernel
    p, pn, zero = np.empty(3), np.empty(3), np.zeros(3)
    first = min(k, _FIRST_NEIGHBOURS)
    count = 0
    for r in range(len(src)):
        _move(R, t, src[r], p)
        _move(R, zero, src_normals[r], pn)
        lo, hi = f_starts[tree_of_row[r]], f_starts[tree_of_row[r] + 1]
        # the few nearest first: their order is that of the k nearest, and usually one fits
        found = knn_within(
            f_points, f_axes, lo, hi, p, first, _bound(p, f_points, last[r], first, kernel2),
            best_d2, best_j, stack, gaps,
        )  # fmt: skip
        if found == 2:
            last[r, 0], last[r, 1] = best_j[0], best_j[1]
        else:
            last[r, 1] = -1
        i = _first_compatible(best_j, found, 0, pn, t_normals, t_flatness, cos_max)
        if i < 0 and found == first < k:
            found = knn_within(
                f_points, f_axes, lo, hi, p, k, kernel2, best_d2, best_j, stack, gaps
            )
            i = _first_compatible(best_j, found, first, pn, t_normals, t_flatness, cos_max)
        if i < 0:
            continue
        j = best_j[i]
        m[count] = p
        q[count] = f_points[j]
        scale = np.sqrt(t_flatness[j])  # component-wise: no temporary array per point
        for c in range(3):
            n[count, c] = t_normals[j, c] * scale
        u = 1.0 - best_d2[i] / kernel2
        w[count] = u * u
        count += 1
    return count


@numba.njit(cache=True, nogil=True)
def _gauss_newton_step(m, q, n, w, count, axis, has_axis, point_to_point):
    """Rotation and translation that best move m[:count] onto q[:count] (see `icp`),
    linearised about the identity; with `has_axis`, a rotation about `axis` only."""
    P = 4 if has_axis else 6
    H = np.zeros((P, P))
    g = np.zeros(P)
    J = np.zeros((3, P))
    Jp = np.zeros(P)
    for i in range(count):
        mi = m[i]
        if has_axis:  # d(R(axis, theta) m) / d theta = axis x m
            J[0, 0] = axis[1] * mi[2] - axis[2] * mi[1]
            J[1, 0] = axis[2] * mi[0] - axis[0] * mi[2]
            J[2, 0] = axis[0] * mi[1] - axis[1] * mi[0]
        else:  # d(omega x m) / d omega = -[m]_x
            J[0, 1], J[0, 2], J[1, 2] = mi[2], -mi[1], mi[0]
            J[1, 0], J[2, 0], J[2, 1] = -mi[2], mi[1], -mi[0]
        J[0, P - 3], J[1, P - 2], J[2, P - 1] = 1.0, 1.0, 1.0
        e0, e1, e2 = mi[0] - q[i, 0], mi[1] - q[i, 1], mi[2] - q[i, 2]  # no temporary array
        ni = n[i]
        rp = ni[0] * e0 + ni[1] * e1 + ni[2] * e2
        for a in range(P):
            Jp[a] = ni[0] * J[0, a] + ni[1] * J[1, a] + ni[2] * J[2, a]
        wi = w[i]
        for a in range(P):
            g[a] += wi * (
                Jp[a] * rp + point_to_point * (J[0, a] * e0 + J[1, a] * e1 + J[2, a] * e2)
            )
            for b in range(P):
                JtJ = J[0, a] * J[0, b] + J[1, a] * J[1, b] + J[2, a] * J[2, b]
                H[a, b] += wi * (Jp[a] * Jp[b] + point_to_point * JtJ)
    trace = 0.0
    for a in range(P):
        trace += H[a, a]
    for a in range(P):
        H[a, a] += 1e-9 * max(trace, 1e-12)
    delta = -np.linalg.solve(H, g)
    dR = _rodrigues(delta[0] * axis if has_axis else delta[:3].copy())
    return dR, delta[P - 3 :].copy()


@numba.njit(cache=True, nogil=True)
def _icp(R, t, full_src, full_normals, full_trees, coarse_src, coarse_normals, coarse_trees,
         f_points, f_axes, f_starts, t_normals, t_flatness, axis, has_axis,
         iterations, kernel_start, kernel_final, cos_max, k_coarse, k_final, converged,
         point_to_point):  # fmt: skip
    kernel = max(kernel_start, kernel_final)
    size = max(len(full_src), len(coarse_src))
    m, q, n, w = np.empty((size, 3)), np.empty((size, 3)), np.empty((size, 3)), np.empty(size)
    R, t = R.copy(), t.copy()
    last_full = np.full((len(full_src), 2), -1, dtype=np.int64)
    last_coarse = np.full((len(coarse_src), 2), -1, dtype=np.int64)
    for _ in range(iterations):
        final = kernel <= kernel_final
        src, normals, trees = (full_src, full_normals, full_trees) if final else (coarse_src, coarse_normals, coarse_trees)  # fmt: skip
        k = k_final if final else k_coarse
        count = _correspondences(src, normals, trees, R, t, f_points, f_axes, f_starts,
                                 t_normals, t_flatness, kernel, cos_max, k, m, q, n, w,
                                 last_full if final else last_coarse)  # fmt: skip
        if count < (2 if has_axis else 3):
            break
        dR, dt = _gauss_newton_step(m, q, n, w, count, axis, has_axis, point_to_point)
        R, t = dR @ R, dR @ t + dt
        step = 0.0
        D, s = dR - np.eye(3), np.empty(3)
        for i in range(count):
            _move(D, dt, m[i], s)
            step += np.sqrt(s[0] * s[0] + s[1] * s[1] + s[2] * s[2])
        if step / count < converged * kernel:
            if kernel <= kernel_final:
                break
            kernel = max(kernel_final, 0.5 * kernel)
    return R, t


def icp(T: np.ndarray, full: tuple, coarse: tuple, targets: Targets, axis: np.ndarray | None,
        settings: IcpSettings) -> np.ndarray:  # fmt: skip
    """Robust ICP from the 4x4 pose T.  `full` and `coarse` are (points, normals, tree_of_row)
    of the local points (coarse: the lighter view used while the kernel is above its final
    value).  Graduated: the kernel starts at `kernel_start` and halves whenever an iteration
    moves the points by less than `converged` of it on average; stops once that happens at
    `kernel`.  With `axis`, updates rotate about it only (4-DoF)."""
    f = targets.forest
    R, t = _icp(
        np.ascontiguousarray(T[:3, :3]), np.ascontiguousarray(T[:3, 3]), *full, *coarse,
        f.points, f.axes, f.starts, targets.normals, targets.flatness,
        np.zeros(3) if axis is None else np.ascontiguousarray(axis, dtype=float),
        axis is not None, *settings,
    )  # fmt: skip
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = R, t
    return out


@numba.njit(cache=True, nogil=True)
def _fitness(R, t, src, tree_of_row, f_points, f_axes, f_starts, radius):
    """(inliers, sum of their squared distances, sum of the smooth scores) of `src` moved by
    (R, t), each point against its partner tree."""
    best_d2 = np.empty(1)
    best_j = np.empty(1, dtype=np.int64)
    stack, gaps = scratch()
    r2 = radius * radius
    moved = np.empty(3)
    inliers, squares, smooth = 0, 0.0, 0.0
    for r in range(len(src)):
        _move(R, t, src[r], moved)
        tree = tree_of_row[r]
        if knn_within(f_points, f_axes, f_starts[tree], f_starts[tree + 1], moved, 1, r2,
                      best_d2, best_j, stack, gaps):  # fmt: skip
            inliers += 1
            squares += best_d2[0]
            smooth += 1.0 - best_d2[0] / r2
    return inliers, squares, smooth


def fitness(T: np.ndarray, src: np.ndarray, tree_of_row: np.ndarray, forest: Forest,
            radius: float) -> tuple[float, float, float]:  # fmt: skip
    """Inlier share, inlier RMS distance and the smooth score (mean of 1 - (d/r)^2, truncated)
    of the local points `src` moved by T against their partner trees."""
    inliers, squares, smooth = _fitness(
        np.ascontiguousarray(T[:3, :3]), np.ascontiguousarray(T[:3, 3]), src, tree_of_row,
        forest.points, forest.axes, forest.starts, float(radius),
    )  # fmt: skip
    rmse = float(np.sqrt(squares / inliers)) if inliers else 0.0
    return inliers / len(src), rmse, smooth / len(src)


@numba.njit(cache=True, nogil=True)
def thinned_rows(sizes, input_rows, limit):
    """The local points one problem uses, as rows of its clouds' concatenated tree-ordered
    points (`sizes` points each; `input_rows` maps each cloud's input order to its tree
    order), and the cloud of each row: every point, or with `limit` > 0 below their number
    every (total / limit)-th point of each cloud in input order (which keeps its spread)."""
    total = len(input_rows)
    thin = 0 < limit < total
    counts = np.empty(len(sizes), dtype=np.int64)
    for o in range(len(sizes)):
        counts[o] = np.int64(np.ceil(sizes[o] * limit / total)) if thin else sizes[o]
    rows = np.empty(counts.sum(), dtype=np.int64)
    owner = np.empty(len(rows), dtype=np.int64)
    at, first = 0, 0
    for o in range(len(sizes)):
        for k in range(counts[o]):
            rows[at] = first + input_rows[first + (np.int64(k * total / limit) if thin else k)]
            owner[at] = o
            at += 1
        first += sizes[o]
    return rows, owner


@numba.njit(cache=True, nogil=True)
def _rotation_scores(rotations, pivot_l, pivot_g, src, tree_of_row, f_points, f_axes, f_starts,
                     f_boxes, radius):  # fmt: skip
    best_d2 = np.empty(1)
    best_j = np.empty(1, dtype=np.int64)
    stack, gaps = scratch()
    r2 = radius * radius
    scores = np.zeros(len(rotations))
    centred = src - pivot_l
    p = np.empty(3)
    for a in range(len(rotations)):
        total = 0.0
        for r in range(len(src)):
            _move(rotations[a], pivot_g, centred[r], p)
            # most rotations put most points far from their partner: the box answers first
            if knn_in_tree(f_points, f_axes, f_starts, f_boxes, tree_of_row[r], p, 1, r2,
                           best_d2, best_j, stack, gaps):  # fmt: skip
                total += 1.0 - best_d2[0] / r2
        scores[a] = total / len(src)
    return scores


def rotation_scores(rotations: np.ndarray, pivots: tuple, src: np.ndarray,
                    tree_of_row: np.ndarray, forest: Forest, radius: float) -> np.ndarray:  # fmt: skip
    """Smooth fitness (mean of 1 - (d/r)^2, truncated) of each rotation (K, 3, 3) about the
    matched pivots (local, global) of the local points `src`."""
    return _rotation_scores(
        np.ascontiguousarray(rotations, dtype=float), np.asarray(pivots[0], dtype=float),
        np.asarray(pivots[1], dtype=float), src, tree_of_row, *forest.arrays, float(radius),
    )  # fmt: skip
