"""Compiled inner loops of the verification (`verification.py`; numba, cached on disk).

`consensus_kernel` tests the minimal samples of many association sets in one pass (MSAC:
the most agreeing pairs, ties by the smallest truncated squared error), settles each best
start by refitting on its inliers and stores the poses; `guided_matches` files the local
objects outside a set that land near a map object they could be, closest first.  The rules
they implement are documented in `verification.py`.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from semloc.closed_form import DEGENERATE, fit, fit_into


@njit(cache=True, nogil=True)
def consensus_kernel(
    src, dst, sizes, sample_rows, sample_start, sample_count, yaw_only, tol, whole, starts, rounds
):
    """The consensus of each padded set (see `consensus`): poses (P, 4, 4), whether each has
    one, inliers (P, M) and the inliers' RMS residual (inf without a pose).

    A set of at most a minimal sample is fitted whole; a set whose least-squares pose puts
    every pair within `whole` x `tol` is kept whole; otherwise each minimal sample of its size
    (`sample_rows[sample_start[m]:][:sample_count[m]]`) is fitted, the `starts` best determined
    ones (most inliers, then the smallest MSAC cost, then drawing order) are refit on their
    inliers until these settle (at most `rounds` refits; a refit is taken when it is
    determined and keeps 2 inliers), and the start with the most inliers, then the smallest
    cost, wins (the first tried on ties).  Fewer than 2 agreeing pairs: no pose."""
    n_sets, width = src.shape[0], src.shape[1]
    minimal = sample_rows.shape[1]
    poses = np.zeros((n_sets, 4, 4))
    has_pose = np.zeros(n_sets, dtype=np.bool_)
    inliers = np.zeros((n_sets, width), dtype=np.bool_)
    residual = np.full(n_sets, np.inf)
    for i in range(n_sets):
        n = sizes[i]
        s, d = src[i, :n], dst[i, :n]
        R, t, spread = fit(s, d, np.ones(n), yaw_only)
        errors = errors_into(R, t, s, d, np.empty(n))
        if n <= minimal or (spread > DEGENERATE and np.all(errors < whole * tol)):
            inliers[i, :n] = True
            if spread > DEGENERATE:
                store(poses[i], R, t)
                has_pose[i] = True
                residual[i] = rms(errors, inliers[i, :n])
            continue
        first, count = sample_start[n], sample_count[n]
        inl, R, t, found = best_start(
            s, d, sample_rows[first : first + count], yaw_only, tol, starts, rounds
        )
        if not found:  # no minimal sample determines a pose
            inliers[i, :n] = True
            continue
        inliers[i, :n] = inl
        if inl.sum() >= 2:  # else no two pairs agree: the set is not one place
            store(poses[i], R, t)
            has_pose[i] = True
            residual[i] = rms(errors_into(R, t, s, d, np.empty(n)), inl)
    return poses, has_pose, inliers, residual


@njit(cache=True, nogil=True)
def best_start(s, d, samples, yaw_only, tol, starts, rounds):
    """The settled start with the most inliers (then least cost): (inliers, R, t, found)."""
    n, minimal = len(s), samples.shape[1]
    count = np.full(len(samples), -1)  # -1: undetermined
    cost = np.zeros(len(samples))
    sample_s, sample_d, ones = np.empty((minimal, 3)), np.empty((minimal, 3)), np.ones(minimal)
    R, t, errors = np.empty((3, 3)), np.empty(3), np.empty(n)
    for j in range(len(samples)):
        for k in range(minimal):
            sample_s[k], sample_d[k] = s[samples[j, k]], d[samples[j, k]]
        if fit_into(sample_s, sample_d, ones, yaw_only, R, t) > DEGENERATE:
            errors_into(R, t, s, d, errors)
            count[j] = np.sum(errors < tol)
            cost[j] = msac(errors, tol)
    order = np.argsort(cost, kind="mergesort")  # ties: drawing order
    order = order[np.argsort(-count[order], kind="mergesort")]
    best_inl, best_R, best_t = np.zeros(n, dtype=np.bool_), np.eye(3), np.zeros(3)
    best_count, best_cost, found = -1, np.inf, False
    for j in order[:starts]:
        if count[j] < 0:
            break
        for k in range(minimal):
            sample_s[k], sample_d[k] = s[samples[j, k]], d[samples[j, k]]
        fit_into(sample_s, sample_d, ones, yaw_only, R, t)
        errors_into(R, t, s, d, errors)
        inl = settle(s, d, errors < tol, R, t, yaw_only, tol, rounds)
        c, e = inl.sum(), msac(errors_into(R, t, s, d, errors), tol)
        if c > best_count or (c == best_count and e < best_cost):
            best_inl, best_count, best_cost, found = inl, c, e, True
            best_R[:, :], best_t[:] = R, t
    return best_inl, best_R, best_t, found


@njit(cache=True, nogil=True)
def settle(s, d, inl, R, t, yaw_only, tol, rounds):
    """Refit on the inliers and recompute them until they no longer change; the pose is
    updated in `R`, `t`, the settled inliers returned."""
    R2, t2, errors = np.empty((3, 3)), np.empty(3), np.empty(len(s))
    for _ in range(rounds):
        if inl.sum() < 2:
            break
        spread = fit_into(s, d, inl.astype(np.float64), yaw_only, R2, t2)
        again = errors_into(R2, t2, s, d, errors) < tol
        moves = spread > DEGENERATE and again.sum() >= 2
        settled = np.all(again == inl)
        if moves:
            inl = again
            R[:, :], t[:] = R2, t2
        if not moves or settled:
            break
    return inl


@njit(cache=True, nogil=True)
def errors_into(R, t, s, d, out):
    """Distance of each aligned local centre `R @ s_i + t` to its partner `d_i`, into `out`."""
    for i in range(len(s)):
        e = 0.0
        for k in range(3):
            v = R[k, 0] * s[i, 0] + R[k, 1] * s[i, 1] + R[k, 2] * s[i, 2] + t[k] - d[i, k]
            e += v * v
        out[i] = np.sqrt(e)
    return out


@njit(cache=True, nogil=True)
def msac(errors, tol):
    """Squared errors truncated at the tolerance, summed."""
    total = 0.0
    for e in errors:
        total += min(e, tol) ** 2
    return total


@njit(cache=True, nogil=True)
def rms(errors, mask):
    total, count = 0.0, 0
    for i in range(len(errors)):
        if mask[i]:
            total += errors[i] ** 2
            count += 1
    return np.sqrt(total / count) if count else np.inf


@njit(cache=True, nogil=True)
def store(pose, R, t):
    pose[:3, :3] = R
    pose[:3, 3] = t
    pose[3, 3] = 1.0


@njit(cache=True, nogil=True)
def guided_matches(
    aligned, pairs, pair_start, pair_count, starts, globals_, columns, along, global_xyz, axis,
    tolerance, conflict_radius,
):  # fmt: skip
    """Guided matching of every set (see `MapSupport`): the (global, local) pairs each set
    gains, nearest first (ties: local, then candidate column), as one array with each set's
    start, and each set's conflicts.  A local object's candidates (CSR `starts`, sorted
    `along` the axis) are scanned only within the larger radius along the axis; gaps are
    measured exactly inside it."""
    n_sets, n_local = aligned.shape[0], aligned.shape[1]
    reach = max(tolerance, conflict_radius) + 1e-9  # beyond it along the axis: farther still
    inside = np.full(n_local, -1, dtype=np.int64)
    used_global = np.full(max(len(global_xyz), 1), -1, dtype=np.int64)
    conflicts = np.zeros(n_sets, dtype=np.int64)
    added = np.empty((n_sets * n_local, 2), dtype=np.int64)  # at most one per local object
    added_start = np.zeros(n_sets + 1, dtype=np.int64)
    gap = np.empty(len(globals_))  # at most every candidate of one set's outside objects
    entry = np.empty((len(globals_), 3), dtype=np.int64)  # local, column, global
    n_added = 0
    for s in range(n_sets):
        for k in range(pair_start[s], pair_start[s] + pair_count[s]):
            used_global[pairs[k, 0]] = s
            inside[pairs[k, 1]] = s
        n_entries = 0
        for r in range(n_local):
            if inside[r] == s:
                continue
            m = aligned[s, r]
            lo, hi = starts[r], starts[r + 1]
            p = lo + np.searchsorted(along[lo:hi], m[axis] - reach)
            near = False
            while p < hi and along[p] <= m[axis] + reach:
                g = globals_[p]
                dx = global_xyz[g, 0] - m[0]
                dy = global_xyz[g, 1] - m[1]
                dz = global_xyz[g, 2] - m[2]
                d = np.sqrt(dx * dx + dy * dy + dz * dz)
                near |= d < conflict_radius
                if d < tolerance:
                    gap[n_entries] = d
                    entry[n_entries, 0] = r
                    entry[n_entries, 1] = columns[p]
                    entry[n_entries, 2] = g
                    n_entries += 1
                p += 1
            conflicts[s] += not near
        for e in by_gap_then_entry(gap[:n_entries], entry[:n_entries]):
            r, g = entry[e, 0], entry[e, 2]
            if used_global[g] != s and inside[r] != s:
                added[n_added, 0] = g
                added[n_added, 1] = r
                n_added += 1
                used_global[g] = s
                inside[r] = s
        added_start[s + 1] = n_added
    return added[:n_added], added_start, conflicts


@njit(cache=True, nogil=True)
def by_gap_then_entry(gap, entry):
    """Positions of the entries ordered by gap, then local, then candidate column."""
    order = np.arange(len(gap))
    for i in range(1, len(order)):  # insertion sort: a handful of entries
        j, e = i, order[i]
        while j > 0 and before(gap, entry, e, order[j - 1]):
            order[j] = order[j - 1]
            j -= 1
        order[j] = e
    return order


@njit(cache=True, nogil=True, inline="always")
def before(gap, entry, a, b):
    if gap[a] != gap[b]:
        return gap[a] < gap[b]
    if entry[a, 0] != entry[b, 0]:
        return entry[a, 0] < entry[b, 0]
    return entry[a, 1] < entry[b, 1]
