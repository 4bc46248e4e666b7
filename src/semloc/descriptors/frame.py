"""The gravity-aligned, yaw-normalized object frame shared by the shape descriptors.

`canonical(points)` moves an object's points (z = up) into a frame where the descriptors no
longer depend on where the object stands or which way it faces: the horizontal centroid goes to
the origin, the lowest point to z = 0, and the principal horizontal axis (PCA of x, y) to +x.
The sign of the principal axis is fixed by the third moment (the longer tail of the
distribution goes to +x; y follows as z x x), so a yaw rotation or a translation of the input
gives the same output up to floating-point rounding.  Points are thinned to one per `voxel` cell first (in
the canonical frame), so the result hardly depends on the point density.
"""

from __future__ import annotations

import numpy as np

DEFAULT_VOXEL = 0.03


def as_points(points: np.ndarray) -> np.ndarray:
    """`points` as a float (N, 3) array; ValueError on a wrong shape or non-finite values."""
    array = np.asarray(points, dtype=float)
    if array.ndim != 2 or array.shape[1] != 3:
        raise ValueError(f"points must have shape (N, 3), got {array.shape}")
    if len(array) < 3:
        raise ValueError(f"a descriptor needs at least 3 points, got {len(array)}")
    if not np.all(np.isfinite(array)):
        raise ValueError("points have non-finite values")
    return array


def yaw_frame(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(R, origin) with canonical = (points - origin) @ R.T; R rotates about z only."""
    origin = np.array([*points[:, :2].mean(axis=0), points[:, 2].min()])
    xy = points[:, :2] - origin[:2]
    _, vectors = np.linalg.eigh(xy.T @ xy / len(xy))
    ex = vectors[:, 1]  # direction of the largest horizontal spread
    if np.sum((xy @ ex) ** 3) < 0:
        ex = -ex
    R = np.eye(3)
    R[0, :2] = ex
    R[1, :2] = [-ex[1], ex[0]]  # y = z x x: a proper rotation about gravity
    return R, origin


def canonical(points: np.ndarray, voxel: float = DEFAULT_VOXEL) -> np.ndarray:
    """Points in the canonical object frame (see the module docstring), voxel-thinned."""
    points = as_points(points)
    R, origin = yaw_frame(points)
    local = (points - origin) @ R.T
    if voxel > 0:
        keys = np.floor(local / voxel).astype(np.int64)
        _, first = np.unique(keys, axis=0, return_index=True)
        local = local[np.sort(first)]
    return local
