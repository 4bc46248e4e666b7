"""Geometry shared by the importers and `crop`: voxel filtering, upright boxes, surface sampling.

All functions take and return numpy arrays; nothing here knows a file format.  A box is
`(centre, size, rotation)` with `p = rotation @ q + centre` for `q` in the box frame and the box
spanning `[-size/2, size/2]` there (the native map format's `position`, `size`, `rotation`).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from semloc.pointsets import sample_box_surface  # noqa: F401 (the importers' surface sampling)


def up_basis(up: np.ndarray | None) -> np.ndarray:
    """A rotation whose third column is the unit `up` (z when `up` is None)."""
    z = np.array([0.0, 0.0, 1.0]) if up is None else np.asarray(up, float) / np.linalg.norm(up)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = helper - z * (helper @ z)
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


def upright_box(
    points: np.ndarray, up: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Gravity-aligned oriented box of a point set: the minimum-area rectangle of the points
    projected on the ground plane (its long side is the box's first axis), height along `up`.
    Returns (centre, size, rotation)."""
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    basis = up_basis(up)
    major = _footprint_axis((points @ basis)[:, :2])
    yaw = np.array([[major[0], -major[1], 0.0], [major[1], major[0], 0.0], [0.0, 0.0, 1.0]])
    rotation = basis @ yaw
    in_box = points @ rotation
    low, high = in_box.min(axis=0), in_box.max(axis=0)
    return rotation @ ((low + high) / 2), high - low, rotation


def _footprint_axis(xy: np.ndarray) -> np.ndarray:
    """Unit direction of the long side of the minimum-area rectangle around 2-D points."""
    candidates = [np.array([1.0, 0.0])]
    try:
        hull = xy[ConvexHull(xy).vertices]
        edges = np.roll(hull, -1, axis=0) - hull
        lengths = np.linalg.norm(edges, axis=1)
        candidates += list(edges[lengths > 1e-12] / lengths[lengths > 1e-12, None])
    except (QhullError, ValueError):
        hull = xy
    best, best_area = candidates[0], np.inf
    for axis in candidates:
        normal = np.array([-axis[1], axis[0]])
        extent_a, extent_n = np.ptp(hull @ axis), np.ptp(hull @ normal)
        if extent_a * extent_n < best_area - 1e-12:
            best_area = extent_a * extent_n
            best = axis if extent_a >= extent_n else normal
    if best[0] < -1e-12 or (abs(best[0]) <= 1e-12 and best[1] < 0):
        best = -best
    return best


def sample_triangles(
    vertices: np.ndarray, faces: np.ndarray, count: int, rng: np.random.Generator
) -> np.ndarray:
    """`count` points uniformly on a triangle mesh (area-weighted)."""
    tri = np.asarray(vertices, dtype=float)[np.asarray(faces)]
    areas = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1) / 2
    if len(tri) == 0 or areas.sum() <= 0:
        return np.zeros((0, 3))
    chosen = rng.choice(len(tri), size=count, p=areas / areas.sum())
    u, v = rng.random(count), rng.random(count)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    a, b, c = tri[chosen, 0], tri[chosen, 1], tri[chosen, 2]
    return a + u[:, None] * (b - a) + v[:, None] * (c - a)


def quaternion_matrix(w: float, x: float, y: float, z: float) -> np.ndarray:
    """Rotation matrix of a (not necessarily unit) quaternion w + xi + yj + zk."""
    q = np.array([w, x, y, z], dtype=float)
    norm = np.linalg.norm(q)
    if not np.isfinite(norm) or norm < 1e-12:
        raise ValueError("quaternion has zero or non-finite norm")
    w, x, y, z = q / norm
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def nearest_rotation(matrix: np.ndarray) -> np.ndarray:
    """The proper rotation closest to `matrix` (polar decomposition by SVD)."""
    u, _, vt = np.linalg.svd(np.asarray(matrix, dtype=float))
    r = u @ vt
    if np.linalg.det(r) < 0:
        u[:, -1] = -u[:, -1]
        r = u @ vt
    return r
