"""Closed-form rigid alignment of matched centres, compiled (numba): one set or many.

`fit` solves the weighted least-squares pose of one small set of matched positions:
4-DoF (a yaw about +z and a translation; the positions are given in z-up frames) or 6-DoF
(Kabsch/Umeyama without scale).  It also returns how spread the positions are (the smaller
of both sides: horizontal RMS spread in 4-DoF, RMS distance off the best-fit line in 6-DoF),
so that callers can tell a determined pose (spread above a tolerance) from noise.
`fit_many` does this for padded batches.  Callers (`pose.align_positions`,
`verification.consensus`) rotate the frames to z-up and back; here everything is plain arrays.
"""

from __future__ import annotations

import numpy as np
from numba import njit

DEGENERATE = 1e-9
"""Spread (m) at or below which positions are mathematically degenerate (no pose)."""


@njit(cache=True, nogil=True)
def fit(src, dst, w, yaw_only):
    """Weighted pose of one set, `dst ≈ R @ src + t`: (R (3, 3), t (3,), spread).

    `src`, `dst` (m, 3) and weights `w` (m,) with a positive sum (rows of weight 0 are
    ignored).  The spread is the smaller of the two sides' (see the module docstring)."""
    R, t = np.empty((3, 3)), np.empty(3)
    spread = fit_into(src, dst, w, yaw_only, R, t)
    return R, t, spread


@njit(cache=True, nogil=True)
def fit_into(src, dst, w, yaw_only, R, t):
    """`fit` writing the pose into `R` and `t`; returns the spread (no allocation in 4-DoF)."""
    total = 0.0
    for i in range(len(w)):
        total += w[i]
    cs0 = cs1 = cs2 = cd0 = cd1 = cd2 = 0.0
    for i in range(len(w)):
        wi = w[i] / total
        cs0 += wi * src[i, 0]
        cs1 += wi * src[i, 1]
        cs2 += wi * src[i, 2]
        cd0 += wi * dst[i, 0]
        cd1 += wi * dst[i, 1]
        cd2 += wi * dst[i, 2]
    cs, cd = (cs0, cs1, cs2), (cd0, cd1, cd2)
    if yaw_only:
        sin = cos = 0.0
        for i in range(len(w)):
            wi = w[i] / total
            a0, a1 = src[i, 0] - cs0, src[i, 1] - cs1
            b0, b1 = dst[i, 0] - cd0, dst[i, 1] - cd1
            sin += wi * (a0 * b1 - a1 * b0)
            cos += wi * (a0 * b0 + a1 * b1)
        theta = np.arctan2(sin, cos)
        c, s = np.cos(theta), np.sin(theta)
        R[0, 0], R[0, 1], R[0, 2] = c, -s, 0.0
        R[1, 0], R[1, 1], R[1, 2] = s, c, 0.0
        R[2, 0], R[2, 1], R[2, 2] = 0.0, 0.0, 1.0
    else:
        U, _, Vt = np.linalg.svd(_cross_covariance(src, cs, dst, cd, w, total))
        V = Vt.T.copy()
        sign = np.sign(np.linalg.det(V @ U.T))
        V[:, 2] *= 1.0 if sign == 0 else sign
        R[:, :] = V @ U.T
    for k in range(3):
        t[k] = cd[k] - (R[k, 0] * cs0 + R[k, 1] * cs1 + R[k, 2] * cs2)
    return min(_spread(src, w, total, cs, yaw_only), _spread(dst, w, total, cd, yaw_only))


@njit(cache=True, nogil=True)
def _spread(xyz, w, total, centre, yaw_only):
    if yaw_only:
        horizontal = 0.0
        for i in range(len(w)):
            dx, dy = xyz[i, 0] - centre[0], xyz[i, 1] - centre[1]
            horizontal += (dx * dx + dy * dy) * (w[i] / total)
        return np.sqrt(max(horizontal, 0.0))
    values = np.linalg.eigvalsh(_cross_covariance(xyz, centre, xyz, centre, w, total))
    # the eigenvalues carry rounding noise of order eps·λ_max (collinear points would
    # otherwise keep a spread of ~1e-8 on some CPUs): below it, a direction has no spread
    noise = 1e-14 * max(values[2], 0.0)
    return np.sqrt(max(values[0] - noise, 0.0) + max(values[1] - noise, 0.0))


@njit(cache=True, nogil=True)
def _cross_covariance(a, a_centre, b, b_centre, w, total):
    """Σ_i w_i / total · (a_i - a_centre)(b_i - b_centre)ᵀ, (3, 3)."""
    out = np.zeros((3, 3))
    for i in range(len(w)):
        wi = w[i] / total
        for r in range(3):
            for q in range(3):
                out[r, q] += (a[i, r] - a_centre[r]) * (b[i, q] - b_centre[q]) * wi
    return out


@njit(cache=True, nogil=True)
def fit_many(src, dst, w, yaw_only):
    """`fit` of S padded sets, (S, m, 3) positions and (S, m) weights: poses (S, 4, 4) and
    spreads (S,)."""
    poses = np.zeros((len(src), 4, 4))
    spreads = np.empty(len(src))
    R, t = np.empty((3, 3)), np.empty(3)
    for s in range(len(src)):
        spreads[s] = fit_into(src[s], dst[s], w[s], yaw_only, R, t)
        poses[s, :3, :3] = R
        poses[s, :3, 3] = t
        poses[s, 3, 3] = 1.0
    return poses, spreads
