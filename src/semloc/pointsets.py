"""Point-set utilities shared by every stage: voxel keys, voxel-centroid downsampling, the
axes along which a set of positions spreads most and the order sweeps over them follow, and
points sampled on a box's surface.

Pure computation on numpy arrays (the voxel sums in one compiled pass); used by the front-end
(fusion), the simulator, the dataset importers and pose recovery, so that "downsample with
voxel v" means the same everywhere.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

_OFFSET = 1 << 20  # keys cover +-1,048 km at 1 mm voxels; plenty for indoor maps


def voxel_keys(points: np.ndarray, voxel_size: float) -> np.ndarray:
    """One int64 key per point: its voxel (x, y, z indices packed 21 bits each)."""
    idx = np.floor(np.asarray(points, float) / voxel_size).astype(np.int64) + _OFFSET
    return (idx[:, 0] << 42) | (idx[:, 1] << 21) | idx[:, 2]


def voxel_accumulate(
    points: np.ndarray, voxel_size: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unique voxel keys of `points` (ascending, as `voxel_keys`) with the per-voxel point
    sums (K, 3), summed in input order, and counts (K,)."""
    return _voxel_sums(np.ascontiguousarray(points, dtype=float).reshape(-1, 3), voxel_size)


@njit(cache=True, nogil=True)
def _voxel_sums(points: np.ndarray, voxel_size: float):
    """`voxel_accumulate` in one compiled pass: the points sorted stably by key, so that each
    voxel's points are summed in input order (as `np.bincount` sums its weights)."""
    n = len(points)
    keys = np.empty(n, dtype=np.int64)
    for i in range(n):
        x = np.int64(np.floor(points[i, 0] / voxel_size)) + _OFFSET
        y = np.int64(np.floor(points[i, 1] / voxel_size)) + _OFFSET
        z = np.int64(np.floor(points[i, 2] / voxel_size)) + _OFFSET
        keys[i] = (x << 42) | (y << 21) | z
    order = np.argsort(keys, kind="mergesort")
    n_unique = 0
    for i in range(n):
        n_unique += i == 0 or keys[order[i]] != keys[order[i - 1]]
    unique = np.empty(n_unique, dtype=np.int64)
    sums = np.zeros((n_unique, 3))
    counts = np.zeros(n_unique)
    u = -1
    for i in range(n):
        j = order[i]
        if i == 0 or keys[j] != keys[order[i - 1]]:
            u += 1
            unique[u] = keys[j]
        for c in range(3):
            sums[u, c] += points[j, c]
        counts[u] += 1.0
    return unique, sums, counts


def voxel_downsample(points: np.ndarray, voxel_size: float) -> np.ndarray:
    """The centroid of the points in each occupied voxel (order: by voxel key); 0 keeps all."""
    points = np.asarray(points, float).reshape(-1, 3)
    if len(points) == 0 or voxel_size <= 0:
        return points
    _, sums, counts = voxel_accumulate(points, voxel_size)
    return sums / counts[:, None]


def axes_by_spread(points: np.ndarray) -> np.ndarray:
    """The coordinate axes ordered by the points' extent along them, largest first (equal
    extents: lower axis first); (0, 1, 2) for no points.  Sweeps over a map sort along the
    first."""
    points = np.asarray(points, float).reshape(-1, 3)
    spread = np.ptp(points, axis=0) if len(points) else np.zeros(3)
    return np.argsort(-spread, kind="stable")


class SweepOrder(NamedTuple):
    """How sweeps over a set of positions run: along their longest axis (`axis`), screening
    across the second longest (`cross_axis`); `rank` is each position's dense rank along
    `axis` (equal coordinates, equal rank) and `n_ranks` the number of distinct ranks."""

    axis: int
    cross_axis: int
    rank: np.ndarray
    n_ranks: int

    @classmethod
    def of(cls, positions: np.ndarray) -> SweepOrder:
        positions = np.asarray(positions, float).reshape(-1, 3)
        axis, cross_axis, _ = axes_by_spread(positions).tolist()
        _, rank = np.unique(positions[:, axis], return_inverse=True)
        rank = rank.ravel().astype(np.int64)
        return cls(axis, cross_axis, rank, int(rank.max(initial=-1)) + 1)


def sample_box_surface(
    centre: np.ndarray,
    size: np.ndarray,
    rotation: np.ndarray,
    count: int,
    rng: np.random.Generator,
) -> np.ndarray:
    """`count` points uniformly on the six faces of a box (area-weighted)."""
    size = np.maximum(np.asarray(size, dtype=float), 0.0)
    areas = np.array([size[1] * size[2], size[0] * size[2], size[0] * size[1]]).repeat(2)
    weights = areas / areas.sum() if areas.sum() > 0 else np.full(6, 1 / 6)
    faces = rng.choice(6, size=count, p=weights)
    q = rng.uniform(-0.5, 0.5, size=(count, 3))
    axis = faces // 2
    q[np.arange(count), axis] = np.where(faces % 2 == 0, -0.5, 0.5)
    return (q * size) @ np.asarray(rotation).T + centre
