"""Compiled inner loops of the alignment (`alignment.py`; numba, cached on disk).

`guided_passes` grows one place over all of B: per radius, guided matching (each object of B
with the nearest object of A it may be, mutual nearest within the radius) and the robust
refit of the pose on those pairs (weighted closed form, `refits` rounds); `mutual_nearest`
is the matching alone.  Positions are given in the z-up frames of `pose.z_up_rotations`
when the pose is 4-DoF (`yaw_only`), so the closed form (`closed_form.fit_into`) and the
distances work on plain arrays; the caller turns poses between those frames and back.
The rules are documented in `alignment.py`.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from semloc.closed_form import DEGENERATE, fit_into


@njit(cache=True, nogil=True)
def _squared(R, t, b, a) -> float:
    """|R b + t - a|²."""
    total = 0.0
    for c in range(3):
        d = R[c, 0] * b[0] + R[c, 1] * b[1] + R[c, 2] * b[2] + t[c] - a[c]
        total += d * d
    return total


@njit(cache=True, nogil=True)
def mutual_nearest(R, t, radius, cand_a, cand_b, cand_a_xyz, cand_b_xyz, n_a, n_b):
    """(A index, B index) rows, ascending by A index: for each object of B its nearest
    candidate of A under (R, t) within `radius` (ties: the earlier candidate), kept when it
    is also the nearest of those for its object of A (ties: the lower B index)."""
    best_of_b = np.full(n_b, -1, dtype=np.int64)
    best_b_d2 = np.full(n_b, np.inf)
    limit = radius * radius
    for c in range(len(cand_a)):
        d2 = _squared(R, t, cand_b_xyz[c], cand_a_xyz[c])
        b = cand_b[c]
        if d2 < limit and d2 < best_b_d2[b]:
            best_b_d2[b], best_of_b[b] = d2, c
    best_of_a = np.full(n_a, -1, dtype=np.int64)
    for b in range(n_b):  # ascending B: a tie keeps the lower B index
        c = best_of_b[b]
        if c >= 0:
            a = cand_a[c]
            if best_of_a[a] < 0 or best_b_d2[b] < best_b_d2[cand_b[best_of_a[a]]]:
                best_of_a[a] = c
    count = 0
    for a in range(n_a):
        count += best_of_a[a] >= 0
    pairs = np.empty((count, 2), dtype=np.int64)
    at = 0
    for a in range(n_a):
        if best_of_a[a] >= 0:
            pairs[at, 0], pairs[at, 1] = a, cand_b[best_of_a[a]]
            at += 1
    return pairs


@njit(cache=True, nogil=True)
def _refit(R, t, pairs, a_xyz, b_xyz, radius, refits, yaw_only, R_out, t_out) -> bool:
    """The robust refit of (R, t) on `pairs` into (R_out, t_out): `refits` rounds of the
    weighted closed form, each pair weighted (1 - (d / radius)²)² by its distance d under the
    previous pose; stops when fewer than 2 pairs keep a weight.  False when a round's pose
    is not determined (the caller keeps the pose before the refit)."""
    n = len(pairs)
    src, dst, w = np.empty((n, 3)), np.empty((n, 3)), np.empty(n)
    for i in range(n):
        src[i], dst[i] = b_xyz[pairs[i, 1]], a_xyz[pairs[i, 0]]
    R_out[:, :], t_out[:] = R, t
    R_new, t_new = np.empty((3, 3)), np.empty(3)
    for _ in range(refits):
        kept = 0
        for i in range(n):
            u = max(1.0 - _squared(R_out, t_out, src[i], dst[i]) / (radius * radius), 0.0)
            w[i] = u * u
            kept += w[i] > 0
        if kept < 2:
            break
        if fit_into(src, dst, w, yaw_only, R_new, t_new) <= DEGENERATE:
            return False
        R_out[:, :], t_out[:] = R_new, t_new
    return True


@njit(cache=True, nogil=True)
def guided_passes(R, t, radii, refits, yaw_only, fit_radius, cand_a, cand_b, cand_a_xyz,
                  cand_b_xyz, a_xyz, b_xyz):  # fmt: skip
    """One schedule of guided matching from (R, t): per radius (wide to narrow) the mutual
    nearest pairs, then the robust refit on them; stops at a pass with < 2 pairs or an
    undetermined refit (keeping the last pose).  The pose, the pairs and their score: each
    pair counts 1 - (d / fit_radius)² by its centres' distance d, nothing beyond."""
    R, t = R.copy(), t.copy()
    pairs = np.zeros((0, 2), dtype=np.int64)
    R_next, t_next = np.empty((3, 3)), np.empty(3)
    for radius in radii:
        found = mutual_nearest(
            R, t, radius, cand_a, cand_b, cand_a_xyz, cand_b_xyz, len(a_xyz), len(b_xyz)
        )
        if len(found) < 2:
            break
        pairs = found
        if not _refit(R, t, pairs, a_xyz, b_xyz, radius, refits, yaw_only, R_next, t_next):
            break
        R, t = R_next.copy(), t_next.copy()
    score = 0.0
    for i in range(len(pairs)):
        d2 = _squared(R, t, b_xyz[pairs[i, 1]], a_xyz[pairs[i, 0]])
        score += max(1.0 - d2 / (fit_radius * fit_radius), 0.0)
    return R, t, pairs, score
