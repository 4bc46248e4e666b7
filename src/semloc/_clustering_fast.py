"""Compiled inner loops of the hierarchical clustering (`clustering.py`; numba, cached on disk).

`clustering.py` reads as the paper's Sec. III-B; the passes it runs per update live here:
candidate keys (splitmix64 of two counters, set keys are their wrapping sums), the pool's row
bookkeeping (`held`, `rows_of`, `stacked`, `renumbered`, `row_sizes`), one clustering
iteration over the frontier (`merges_of_frontier`), the compatibility graph of new live
candidates (`compatible_among` for few pairs, `compatible_sweep` along the map's longest axis),
and the lookup of unions already in the pool (`find_by_keys`).  Every kernel works on plain
arrays; the rules they implement are documented in `clustering.py`.

The merge rule itself lives here, once: `agreement` (h, and h_ε with a tolerance), `gate`
(h_ε > γ) and `gate_window` (the global distances the gate may pass for a local one).  The
clustering's kernels call them; `clustering.MergeCriterion` applies them to arrays, and place
retrieval (`places.py`) looks up the distances within `gate_window`.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True, inline="always")
def mix(x: np.uint64) -> np.uint64:
    """A bijective 64-bit mixer (splitmix64's finaliser)."""
    x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return x ^ (x >> np.uint64(31))


@njit(cache=True, nogil=True)
def candidate_keys(candidates: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two independent 64-bit keys per candidate index (set keys are their wrapping sums)."""
    key = np.empty(len(candidates), dtype=np.uint64)
    key2 = np.empty(len(candidates), dtype=np.uint64)
    for i in range(len(candidates)):
        base = np.uint64(candidates[i]) * np.uint64(2)
        key[i] = mix(base + np.uint64(1))
        key2[i] = mix(base + np.uint64(2))
    return key, key2


@njit(cache=True, nogil=True)
def held(members: np.ndarray, n: int) -> np.ndarray:
    """Which of n candidates are members of some set (rows -1 padded)."""
    out = np.zeros(n, dtype=np.bool_)
    for r in range(members.shape[0]):
        for k in range(members.shape[1]):
            if members[r, k] >= 0:
                out[members[r, k]] = True
    return out


@njit(cache=True, nogil=True)
def rows_of(table: np.ndarray, owner: np.ndarray, which: np.ndarray) -> np.ndarray:
    """table[owner[which]]: the rows (e.g. positions) of the given candidates' objects."""
    out = np.empty((len(which), table.shape[1]))
    for i in range(len(which)):
        row = owner[which[i]]
        for c in range(table.shape[1]):
            out[i, c] = table[row, c]
    return out


@njit(cache=True, nogil=True)
def stacked(top: np.ndarray, bottom: np.ndarray) -> np.ndarray:
    """The rows of `top` then those of `bottom`, -1 padded to the wider of the two."""
    out = np.full((len(top) + len(bottom), max(top.shape[1], bottom.shape[1])), -1, np.int64)
    out[: len(top), : top.shape[1]] = top
    out[len(top) :, : bottom.shape[1]] = bottom
    return out


@njit(cache=True, nogil=True)
def renumbered(members: np.ndarray, index: np.ndarray) -> np.ndarray:
    """`index[m]` for each member m (-1 padding stays -1)."""
    out = np.empty(members.shape, dtype=np.int64)
    for r in range(members.shape[0]):
        for k in range(members.shape[1]):
            m = members[r, k]
            out[r, k] = index[m] if m >= 0 else -1
    return out


@njit(cache=True, nogil=True)
def row_sizes(members: np.ndarray) -> np.ndarray:
    """The number of members (entries >= 0) of each row."""
    out = np.zeros(members.shape[0], dtype=np.int64)
    for r in range(members.shape[0]):
        for k in range(members.shape[1]):
            out[r] += members[r, k] >= 0
    return out


@njit(cache=True, nogil=True)
def merges_of_frontier(
    frontier,
    in_frontier,
    members,
    size,
    score,
    indptr,
    indices,
    global_xyz,
    local_xyz,
    cand_key,
    cand_key2,
    set_key,
    set_key2,
    floor,
    min_distance,
    upper_bound,
    grouped,
    capacity,
):
    """The merges (A, B) of one iteration with A in the frontier: which sets merged, and per
    distinct union (by its first key; with `grouped`, else per merge) one merge's rows, the
    largest merge score v_A + v_B + Σ h over the new cross pairs, and the two keys; then
    whether two unions shared a first key but not the second (then call again ungrouped);
    last, whether `capacity` unions were too few (then call again with more: `clustering._with_room`).
    A merge whose score bound cannot beat its union's best so far is not scored.

    `members` are the pool's sets in live-candidate indices (-1 padded), `indptr`/`indices`
    the compatibility graph over the live candidates.  E(A), the candidates compatible with
    every member of A, is found by counting over the members' neighbourhoods; B qualifies
    when B∖A ⊆ E(A) and B∖A ≠ ∅ ≠ A∖B (then all new cross pairs are compatible), and only
    sets meeting E(A) are looked at (an inverted index candidate -> sets).  Two frontier
    sets are tried from the lower row only; merges whose score bound cannot reach `floor`
    are skipped.
    """
    n_sets, width = members.shape
    n_live = len(indptr) - 1
    # every set is filed under one pivot, its member held by the fewest sets: a set inside
    # M(A) has its pivot in M(A), so only the lists of M(A)'s candidates are looked at
    held = np.zeros(n_live, dtype=np.int64)
    for r in range(n_sets):
        for k in range(size[r]):
            held[members[r, k]] += 1
    pivot = np.empty(n_sets, dtype=np.int64)
    count = np.zeros(n_live + 1, dtype=np.int64)
    for r in range(n_sets):
        best = members[r, 0]
        for k in range(1, size[r]):
            m = members[r, k]
            if held[m] < held[best]:
                best = m
        pivot[r] = best
        count[best + 1] += 1
    starts = np.cumsum(count)
    fill = starts[:-1].copy()
    filed = np.empty(n_sets, dtype=np.int64)
    for r in range(n_sets):
        filed[fill[pivot[r]]] = r
        fill[pivot[r]] += 1
    # a 64-bit signature per set (one bit per member, from its key): B ⊆ M(A) needs
    # sig(B) ⊆ sig(M(A)), a cheap first screen
    bit = np.empty(n_live, dtype=np.uint64)
    for c in range(n_live):
        bit[c] = np.uint64(1) << (cand_key[c] >> np.uint64(58))
    sig = np.zeros(n_sets, dtype=np.uint64)
    for r in range(n_sets):
        for k in range(size[r]):
            sig[r] |= bit[members[r, k]]
    hits = np.zeros(n_live, dtype=np.int64)
    touched = np.empty(n_live, dtype=np.int64)
    ext = np.empty(n_live, dtype=np.int64)
    ext_stamp = np.full(n_live, -1, dtype=np.int64)
    ext_at = np.zeros(n_live, dtype=np.int64)
    own_stamp = np.full(n_live, -1, dtype=np.int64)
    own_at = np.zeros(n_live, dtype=np.int64)
    h = np.empty(1024)
    h_known = np.zeros(n_live, dtype=np.bool_)
    new_at = np.empty(width, dtype=np.int64)
    kept = np.zeros(width, dtype=np.bool_)
    merged = np.zeros(n_sets, dtype=np.bool_)
    out_a = np.empty(capacity, dtype=np.int64)
    out_b = np.empty(capacity, dtype=np.int64)
    out_score = np.empty(capacity)
    out_key = np.empty(capacity, dtype=np.uint64)
    out_key2 = np.empty(capacity, dtype=np.uint64)
    n_out = 0
    table = np.full(2 * capacity, -1, dtype=np.int64)  # first key -> union (open addressing)
    for a in frontier:
        n_a = size[a]
        n_touched = 0
        for k in range(n_a):
            m = members[a, k]
            for p in range(indptr[m], indptr[m + 1]):
                c = indices[p]
                if hits[c] == 0:
                    touched[n_touched] = c
                    n_touched += 1
                hits[c] += 1
        n_ext = 0
        for t in range(n_touched):
            c = touched[t]
            if hits[c] == n_a:  # members of A are compatible with the |A| - 1 others only
                ext_stamp[c] = a
                ext_at[c] = n_ext
                ext[n_ext] = c
                n_ext += 1
            hits[c] = 0
        if n_ext == 0:
            continue
        outside = sig[a]
        for j in range(n_ext):
            outside |= bit[ext[j]]
        outside = ~outside
        for k in range(n_a):
            own_stamp[members[a, k]] = a
            own_at[members[a, k]] = k
        if n_a * n_ext > len(h):
            h = np.empty(2 * n_a * n_ext)
        for j in range(n_ext):
            h_known[j] = False
        for j in range(n_a + n_ext):
            x = members[a, j] if j < n_a else ext[j - n_a]
            for p in range(starts[x], starts[x + 1]):
                b = filed[p]
                if b == a or (in_frontier[b] and b < a) or sig[b] & outside:
                    continue
                n_new, shared, ok = 0, 0, True
                key = set_key[a]
                key2 = set_key2[a]
                for k in range(n_a):
                    kept[k] = False
                for k in range(size[b]):
                    m = members[b, k]
                    if ext_stamp[m] == a:
                        new_at[n_new] = ext_at[m]
                        n_new += 1
                        key += cand_key[m]
                        key2 += cand_key2[m]
                    elif own_stamp[m] == a:
                        kept[own_at[m]] = True
                        shared += 1
                    else:
                        ok = False
                        break
                if not ok or shared >= n_a or n_new == 0:
                    continue
                base = score[a] + score[b]
                bound = base + upper_bound * (n_a - shared) * n_new
                if bound < floor:
                    continue
                merged[a] = True
                merged[b] = True
                g = n_out
                if grouped:
                    at = np.int64(key & np.uint64(len(table) - 1))
                    while table[at] >= 0 and out_key[table[at]] != key:
                        at = (at + 1) & (len(table) - 1)
                    if table[at] >= 0:
                        g = table[at]
                        if out_key2[g] != key2:
                            return (
                                merged,
                                out_a[:0],
                                out_b[:0],
                                out_score[:0],
                                out_key[:0],
                                out_key2[:0],
                                True,
                                False,
                            )
                if g == n_out:  # a new union (or, ungrouped, a new merge)
                    if n_out == capacity:  # no room: the caller calls again with more
                        return merged, out_a[:0], out_b[:0], out_score[:0], out_key[:0], out_key2[:0], False, True  # fmt: skip
                    if grouped:
                        table[at] = g
                    out_a[g] = a
                    out_b[g] = b
                    out_score[g] = -np.inf
                    out_key[g] = key
                    out_key2[g] = key2
                    n_out += 1
                elif bound <= out_score[g]:
                    continue
                cross = 0.0
                for q in range(n_new):
                    j = new_at[q]
                    if not h_known[j]:  # h(a_k, e_j), the paper's ratio, when first needed
                        for k in range(n_a):
                            h[k * n_ext + j] = ratio(
                                global_xyz, local_xyz, members[a, k], ext[j], min_distance
                            )
                        h_known[j] = True
                for k in range(n_a):
                    if not kept[k]:
                        for q in range(n_new):
                            cross += h[k * n_ext + new_at[q]]
                out_score[g] = max(out_score[g], base + cross)
    return (
        merged,
        out_a[:n_out],
        out_b[:n_out],
        out_score[:n_out],
        out_key[:n_out],
        out_key2[:n_out],
        False,
        False,
    )


@njit(cache=True, nogil=True)
def ratio(global_xyz, local_xyz, i, j, min_distance):
    """The paper's h of live candidates i and j: `agreement` with no tolerance."""
    return agreement(distance(global_xyz, i, j), distance(local_xyz, i, j), 0.0, min_distance)


@njit(cache=True, nogil=True)
def union_rows(members, size, rows_a, rows_b):
    """The members of A ∪ B for each merge, ascending and -1 padded (rows are ascending)."""
    n = len(rows_a)
    width = 1
    for i in range(n):
        width = max(width, size[rows_a[i]] + size[rows_b[i]])
    out = np.full((n, width), -1, dtype=np.int64)
    longest = 1
    for i in range(n):
        a, b = rows_a[i], rows_b[i]
        p, q, k = 0, 0, 0
        while p < size[a] or q < size[b]:
            x = members[a, p] if p < size[a] else np.iinfo(np.int64).max
            y = members[b, q] if q < size[b] else np.iinfo(np.int64).max
            if x <= y:
                out[i, k] = x
                p += 1
                if x == y:
                    q += 1
            else:
                out[i, k] = y
                q += 1
            k += 1
        longest = max(longest, k)
    return out[:, :longest]


@njit(cache=True, nogil=True)
def compatible_among(added, covered, cand_g, cand_l, global_xyz, local_distance, tolerance,
                      gamma, min_distance, capacity):  # fmt: skip
    """The compatible pairs (a, b), a in `added`, b in `covered` or later in `added` (2 x E):
    other local and global objects, and the gate of `MergeCriterion.compatible`; then whether
    `capacity` pairs were too few (the pairs are then incomplete, see `clustering._with_room`)."""
    out = np.empty((2, capacity), dtype=np.int64)
    n = 0
    for i in range(len(added)):
        x = added[i]
        for k in range(len(covered) + len(added) - i - 1):
            y = covered[k] if k < len(covered) else added[i + 1 + k - len(covered)]
            if cand_l[x] == cand_l[y] or cand_g[x] == cand_g[y]:
                continue
            gx, gy = cand_g[x], cand_g[y]
            d_global = distance(global_xyz, gx, gy)
            d_local = local_distance[cand_l[x], cand_l[y]]
            if not gate(d_global, d_local, tolerance, gamma, min_distance):
                continue
            if n == capacity:  # no room: the caller calls again with more
                return out[:, :0], True
            out[0, n] = x
            out[1, n] = y
            n += 1
    return out[:, :n], False


@njit(cache=True, nogil=True)
def distance(xyz, i, j):
    """Euclidean distance of rows i and j of xyz."""
    return np.sqrt(
        (xyz[i, 0] - xyz[j, 0]) ** 2 + (xyz[i, 1] - xyz[j, 1]) ** 2 + (xyz[i, 2] - xyz[j, 2]) ** 2
    )


# ---------------------------------------------------------------------------------------------
# The merge rule: `agreement` and `gate` are the rule itself, `gate_window` the global
# distances it may pass; `clustering.MergeCriterion` and `merge_metric` apply them element-wise
# (`agreements`, `gates`, `gate_windows`), the clustering's sweep and place retrieval look up
# the distances within `gate_window`.  tests/core/test_merge_rule.py checks that they agree.
@njit(cache=True, nogil=True)
def agreement(d_global, d_local, tolerance, min_distance):
    """h_ε of a global and a local distance: 1 − max(0, |d^A − d^B| − ε) / max(d^A, d^B), and
    1 when both are below `min_distance` (or zero); with ε = 0 it is the paper's h, at most 1
    (`MergeCriterion.UPPER_BOUND`)."""
    d_max = max(d_global, d_local)
    if d_max < min_distance or d_max <= 0:
        return 1.0
    excess = max(abs(d_global - d_local) - tolerance, 0.0)
    return 1.0 - excess / d_max


@njit(cache=True, nogil=True)
def gate(d_global, d_local, tolerance, gamma, min_distance):
    """Whether two candidates at these distances may share a set: h_ε > γ."""
    return agreement(d_global, d_local, tolerance, min_distance) > gamma


@njit(cache=True, nogil=True)
def gate_window(d_local, tolerance, gamma, min_distance):
    """The global distances `gate` may pass for `d_local` lie within (lowest, highest):
    γ·d^B − ε to (d^B + ε) / γ (h_ε > γ solved for d^A below and above d^B), from 0 to at
    least `min_distance` when d^B is below it."""
    highest = max((d_local + tolerance) / gamma, min_distance)
    lowest = 0.0 if d_local < min_distance else max(gamma * d_local - tolerance, 0.0)
    return lowest, highest


@njit(cache=True, nogil=True)
def agreements(d_global, d_local, tolerance, min_distance):
    """`agreement` of each element of two flat arrays of equal length."""
    out = np.empty(len(d_global))
    for i in range(len(d_global)):
        out[i] = agreement(d_global[i], d_local[i], tolerance, min_distance)
    return out


@njit(cache=True, nogil=True)
def gates(d_global, d_local, tolerance, gamma, min_distance):
    """`gate` of each element of two flat arrays of equal length."""
    out = np.empty(len(d_global), dtype=np.bool_)
    for i in range(len(d_global)):
        out[i] = gate(d_global[i], d_local[i], tolerance, gamma, min_distance)
    return out


@njit(cache=True, nogil=True)
def gate_windows(d_local, tolerance, gamma, min_distance):
    """`gate_window` of each element of a flat array: the lowest and the highest distances."""
    lowest = np.empty(len(d_local))
    highest = np.empty(len(d_local))
    for i in range(len(d_local)):
        lowest[i], highest[i] = gate_window(d_local[i], tolerance, gamma, min_distance)
    return lowest, highest


@njit(cache=True, nogil=True)
def compatible_sweep(
    added,
    covered,
    cand_g,
    cand_l,
    global_xyz,
    local_distance,
    reach,
    tolerance,
    gamma,
    min_distance,
    axis,
    cross_axis,
    rank,
    n_ranks,
    window_entries,
    capacity,
):
    """`compatible_among` for many candidates: per local object, its candidates sorted along
    the map's longest axis `axis` (by `rank`, the global objects' dense rank along it); a
    candidate of `la` is tested only against those of `lb` within `reach[la, lb]` along it and
    along the second longest axis `cross_axis` (necessary conditions of the gate; the second
    is read from a copy in sweep order, so most misses cost no distance).  Where each window
    starts is found for all candidates of `la` at once, walking them in sweep order along
    those of `lb` (a merge, not a binary search per candidate), unless that table would have
    more than `window_entries` entries (many objects added at once: then binary searches).
    Returns as `compatible_among` does."""
    n_local = len(local_distance)
    everyone = np.concatenate((covered, added))
    slot = np.zeros(n_ranks + 1, dtype=np.int64)  # counting sort by rank: stable, as mergesort
    for c in everyone:
        slot[rank[cand_g[c]] + 1] += 1
    for i in range(n_ranks):
        slot[i + 1] += slot[i]
    order = np.empty(len(everyone), dtype=np.int64)
    for k in range(len(everyone)):
        r = rank[cand_g[everyone[k]]]
        order[slot[r]] = k
        slot[r] += 1
    count = np.zeros(n_local + 1, dtype=np.int64)
    for c in everyone:
        count[cand_l[c] + 1] += 1
    starts = np.cumsum(count)
    fill = starts[:-1].copy()
    by_local = np.empty(len(everyone), dtype=np.int64)
    for k in order:
        c = everyone[k]
        by_local[fill[cand_l[c]]] = c
        fill[cand_l[c]] += 1
    sorted_x = global_xyz[cand_g[by_local], axis]
    sorted_cross = global_xyz[cand_g[by_local], cross_axis]
    added_at = np.full(len(cand_g), -1, dtype=np.int64)
    for i in range(len(added)):
        added_at[added[i]] = i
    merged = len(added) * n_local <= window_entries
    window = np.empty((0, 0), dtype=np.int64)
    if merged:
        window = window_starts(
            added, cand_g, cand_l, global_xyz, reach, axis, order, starts, sorted_x
        )
    out = np.empty((2, capacity), dtype=np.int64)
    n = 0
    for i in range(len(added)):
        x = added[i]
        la, gx = cand_l[x], cand_g[x]
        for lb in range(n_local):
            if lb == la or starts[lb] == starts[lb + 1]:
                continue
            r = reach[la, lb]
            lo, hi = starts[lb], starts[lb + 1]
            if merged:
                p = window[i, lb]
            else:
                p = lo + np.searchsorted(sorted_x[lo:hi], global_xyz[gx, axis] - r)
            while p < hi and sorted_x[p] <= global_xyz[gx, axis] + r:
                p += 1
                if abs(sorted_cross[p - 1] - global_xyz[gx, cross_axis]) > r:
                    continue
                y = by_local[p - 1]
                if added_at[y] >= 0 and added_at[y] <= i:  # pairs within `added` once
                    continue
                gy = cand_g[y]
                if gx == gy:
                    continue
                d_global = distance(global_xyz, gx, gy)
                if not gate(d_global, local_distance[la, lb], tolerance, gamma, min_distance):
                    continue
                if n == capacity:  # no room: the caller calls again with more
                    return out[:, :0], True
                out[0, n] = x
                out[1, n] = y
                n += 1
    return out[:, :n], False


@njit(cache=True, nogil=True)
def window_starts(added, cand_g, cand_l, global_xyz, reach, axis, order, starts, sorted_x):
    """For each added candidate i (of local object la) and local object lb: the first row p of
    lb's candidates in sweep order (rows starts[lb]..starts[lb + 1] of `sorted_x`) with
    sorted_x[p] >= its coordinate along `axis` less reach[la, lb], i.e. the binary search's
    answer.  `order` is the sweep order of covered + added (added last), so each local
    object's added candidates are walked in ascending coordinate, and the row only advances."""
    n_local = len(starts) - 1
    n_covered = len(order) - len(added)
    count = np.zeros(n_local + 1, dtype=np.int64)
    for i in range(len(added)):
        count[cand_l[added[i]] + 1] += 1
    first = np.cumsum(count)
    fill = first[:-1].copy()
    in_order = np.empty(len(added), dtype=np.int64)  # per local object, in sweep order
    for k in order:
        if k >= n_covered:
            la = cand_l[added[k - n_covered]]
            in_order[fill[la]] = k - n_covered
            fill[la] += 1
    window = np.empty((len(added), n_local), dtype=np.int64)
    for la in range(n_local):
        for lb in range(n_local):
            if lb == la:
                continue
            p, hi = starts[lb], starts[lb + 1]
            for q in range(first[la], first[la + 1]):
                i = in_order[q]
                at = global_xyz[cand_g[added[i]], axis] - reach[la, lb]
                while p < hi and sorted_x[p] < at:
                    p += 1
                window[i, lb] = p
    return window


@njit(cache=True, nogil=True)
def find_by_keys(pool_key, pool_key2, pool_members, key, key2, members):
    """The pool row with each given first key (-1: none), and whether that is exact: the
    pool's first keys are distinct and every hit has the same second key and members."""
    n = len(pool_key)
    slots = 1
    while slots < 2 * n:
        slots *= 2
    mask = np.uint64(slots - 1)
    table = np.full(slots, -1, dtype=np.int64)
    rows = np.full(len(key), -1, dtype=np.int64)
    for r in range(n):
        at = np.int64(pool_key[r] & mask)
        while table[at] >= 0:
            if pool_key[table[at]] == pool_key[r]:
                return rows, False
            at = (at + 1) & (slots - 1)
        table[at] = r
    width = min(members.shape[1], pool_members.shape[1])
    for i in range(len(key)):
        at = np.int64(key[i] & mask)
        while table[at] >= 0 and pool_key[table[at]] != key[i]:
            at = (at + 1) & (slots - 1)
        r = table[at]
        if r < 0:
            continue
        if pool_key2[r] != key2[i]:
            return rows, False
        for k in range(width):
            if pool_members[r, k] != members[i, k]:
                return rows, False
        for k in range(width, members.shape[1]):
            if members[i, k] >= 0:
                return rows, False
        for k in range(width, pool_members.shape[1]):
            if pool_members[r, k] >= 0:
                return rows, False
        rows[i] = r
    return rows, True


@njit(cache=True, nogil=True)
def kept_edges(edges, is_covered, new_edges):
    """The edges (2 x E) between covered candidates, then `new_edges`, in order."""
    kept = 0
    for i in range(edges.shape[1]):
        kept += is_covered[edges[0, i]] and is_covered[edges[1, i]]
    out = np.empty((2, kept + new_edges.shape[1]), dtype=np.int64)
    e = 0
    for i in range(edges.shape[1]):
        if is_covered[edges[0, i]] and is_covered[edges[1, i]]:
            out[:, e] = edges[:, i]
            e += 1
    out[:, kept:] = new_edges
    return out


@njit(cache=True, nogil=True)
def symmetric_csr(edges, index, n):
    """CSR rows (indptr, indices) over n nodes of the graph with edges (2 x E) between
    candidates, both ways; `index` maps a candidate to its node."""
    count = np.zeros(n + 1, dtype=np.int64)
    for i in range(edges.shape[1]):
        count[index[edges[0, i]] + 1] += 1
        count[index[edges[1, i]] + 1] += 1
    indptr = np.cumsum(count)
    fill = indptr[:-1].copy()
    indices = np.empty(2 * edges.shape[1], dtype=np.int64)
    for i in range(edges.shape[1]):
        u, v = index[edges[0, i]], index[edges[1, i]]
        indices[fill[u]] = v
        fill[u] += 1
        indices[fill[v]] = u
        fill[v] += 1
    return indptr, indices
