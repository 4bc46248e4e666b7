"""Compiled inner loop of the twins' search (`twins.py`; numba, cached on disk).

`placed` counts, per candidate motion, the members it puts on a map object of their label,
looking the map up in a uniform grid (`Grid`) instead of a KD-tree, and giving a motion up
once the members left cannot bring it to the share a twin needs.  Where the grid's answer
could differ from the KD-tree's by rounding (an object at the tolerance's edge, objects as
near as the fourth nearest), the member is left `unsure` for the caller to look up exactly.
"""

from __future__ import annotations

import numpy as np
from numba import njit

EDGE = 1e-9
"""Within this share of the squared tolerance, two squared distances are left unsure."""


class Grid:
    """The map's objects by cell of a uniform grid of cells at least `reach` m wide (wider
    when the map's box would need more than about 8 cells per object)."""

    def __init__(self, positions: np.ndarray, reach: float) -> None:
        self.origin = positions.min(axis=0) if len(positions) else np.zeros(3)
        extent = (positions.max(axis=0) - self.origin) if len(positions) else np.zeros(3)
        size = reach
        while np.prod(np.floor(extent / size) + 1) > 8 * len(positions) + 64:
            size *= 2
        self.size = float(size)
        self.dims = (np.floor(extent / size) + 1).astype(np.int64)
        cell = _cell_of(np.floor((positions - self.origin) / size).astype(np.int64), self.dims)
        self.objects = np.argsort(cell, kind="stable").astype(np.int64)
        self.starts = np.searchsorted(cell[self.objects], np.arange(np.prod(self.dims) + 1))


def _cell_of(cells: np.ndarray, dims: np.ndarray) -> np.ndarray:
    return (cells[:, 0] * dims[1] + cells[:, 1]) * dims[2] + cells[:, 2]


HIT, MISS, UNSURE = 1, 0, 2


@njit(cache=True, nogil=True)
def placed(p, p2, sin, cos, K, KK, at, member_codes, order, need, tolerance, nearest, positions,
           codes, origin, size, dims, starts, objects):  # fmt: skip
    """counts[m]: how many members (at `at[k]`, of label `member_codes[k]`, looked at in
    `order`) motion m (the rotation I + sin[m] K + (1 - cos[m]) KK, taking `p` onto `p2[m]`:
    `twins.YawMotions`) puts within `tolerance` of a map object of their label among their
    `nearest` nearest (a member left unsure counts); a count under `need` may be short.
    unsure[m, k]: member k of motion m left for an exact look-up."""
    n_motions, n_members = len(p2), len(at)
    counts = np.zeros(n_motions, np.int64)
    unsure = np.zeros((n_motions, n_members), np.bool_)
    gaps, same = np.empty(len(positions)), np.empty(len(positions), np.bool_)
    R, t, point = np.empty((3, 3)), np.empty(3), np.empty(3)
    for m in range(n_motions):
        for i in range(3):
            for j in range(3):
                R[i, j] = (i == j) + sin[m] * K[i, j] + (1 - cos[m]) * KK[i, j]
        for i in range(3):
            t[i] = p2[m, i] - R[i, 0] * p[0] - R[i, 1] * p[1] - R[i, 2] * p[2]
        for s in range(n_members):
            if counts[m] + n_members - s < need:
                break
            k = order[s]
            for axis in range(3):
                point[axis] = t[axis]
                for j in range(3):
                    point[axis] += R[axis, j] * at[k, j]
            found = _near(point, member_codes[k], tolerance, nearest, positions, codes, origin,
                          size, dims, starts, objects, gaps, same)  # fmt: skip
            counts[m] += found != MISS
            unsure[m, k] = found == UNSURE
    return counts, unsure


@njit(cache=True, nogil=True)
def _near(point, code, tolerance, nearest, positions, codes, origin, size, dims, starts,
          objects, gaps, same):  # fmt: skip
    """Whether a map object of label `code` lies within `tolerance` of `point` among its
    `nearest` nearest: `HIT`, `MISS`, or `UNSURE` when rounding or equal distances could
    decide (`gaps`, `same`: room for the objects near `point`)."""
    bound = tolerance * tolerance
    slack = EDGE * bound  # (the rounding of this loop's and the KD-tree's distances; ties)
    reach = tolerance * (1 + EDGE)  # (the objects left unsure too, whatever the rounding)
    x0, x1 = _cells(point[0] - origin[0], reach, size, dims[0])
    y0, y1 = _cells(point[1] - origin[1], reach, size, dims[1])
    z0, z1 = _cells(point[2] - origin[2], reach, size, dims[2])
    found, edge, best = 0, False, np.inf
    for x in range(x0, x1 + 1):  # (none when the point's reach lies outside the grid)
        for y in range(y0, y1 + 1):
            for z in range(z0, z1 + 1):
                cell = (x * dims[1] + y) * dims[2] + z
                for e in range(starts[cell], starts[cell + 1]):
                    j = objects[e]
                    gap = 0.0
                    for axis in range(3):
                        gap += (positions[j, axis] - point[axis]) ** 2
                    if gap > bound + slack:
                        continue
                    edge |= gap >= bound - slack
                    gaps[found], same[found] = gap, codes[j] == code
                    if same[found]:
                        best = min(best, gap)
                    found += 1
    if edge:
        return UNSURE
    if best == np.inf:
        return MISS
    if found <= nearest:
        return HIT
    before, tied = 0, 0  # (objects surely nearer than the nearest of the label; as near)
    for i in range(found):
        before += gaps[i] < best - slack
        tied += gaps[i] <= best + slack
    return HIT if tied <= nearest else MISS if before >= nearest else UNSURE


@njit(cache=True, nogil=True)
def _cells(at, reach, size, dim):
    """The first and last cell (along one axis, `dim` cells of `size` from 0) within `reach`
    of `at`."""
    return max(int(np.floor((at - reach) / size)), 0), min(
        int(np.floor((at + reach) / size)), dim - 1
    )
