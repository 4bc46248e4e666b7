"""Verification of an association set: which of its pairs agree on one pose, and the evidence.

A set whose pairwise distances are consistent can still hold one wrong pair (a spurious or
mislabelled object admitted by the distance tolerance); its least-squares pose is then pulled
far off while the residual stays small.  `consensus` tests every minimal sample of the set's
pairs (2 pairs in 4-DoF, 3 in 6-DoF; at most `max_samples` of them, seeded), keeps the pose
that the most pairs agree with (ties: the smallest truncated squared error, MSAC), refits on
those inliers and reports which pairs they are.  A set whose least-squares pose already puts
every pair well within tolerance (half of it) is accepted whole without sampling: the sampled
search finds that pose again there, while near the tolerance it may rightly drop a pair; `consensus_many` does all of this for many sets in a few
batched arrays.

`MapSupport` asks what the pose says about the local objects outside the set: those that land
near a map object they could be join the hypothesis (guided matching: `support`), those with
no map object of their kind anywhere near are `conflicts`.  `Evidence` is what a hypothesis
has for it after pose recovery: agreeing pairs, rejected pairs, the residual of its centres,
point fitness, support and conflicts.  Pure numpy.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from itertools import combinations

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from semloc.pose import align_positions_batch


class VerificationConfig(BaseModel):
    """Tolerances of the in-set consensus and of the map evidence."""

    model_config = ConfigDict(extra="forbid")

    inlier_tolerance: float = Field(
        0.4,
        gt=0,
        description="A pair agrees with a pose when its aligned centres are this close (m).",
    )
    max_samples: int = Field(
        200, ge=1, description="Minimal samples tried per set (all of them when fewer)."
    )
    conflict_radius: float = Field(
        1.5, gt=0, description="An unmatched local object contradicts a pose when no map object "
        "it could be lies within this distance (m) of where it lands.",
    )  # fmt: skip


@dataclass(frozen=True)
class Consensus:
    """The pairs of a set that agree on one pose, that pose and the RMS residual of the inliers."""

    inliers: np.ndarray  # bool per pair
    pose: np.ndarray | None
    residual: float


def consensus(
    local_xyz: np.ndarray,
    global_xyz: np.ndarray,
    up_local: np.ndarray | None,
    up_global: np.ndarray | None,
    config: VerificationConfig,
    seed: int = 0,
) -> Consensus:
    """The largest subset of the pairs (rows) that one rigid pose explains within tolerance.

    With no more pairs than a minimal sample, nothing can be tested: all pairs are inliers."""
    problem = (np.asarray(local_xyz, float), np.asarray(global_xyz, float))
    return consensus_many([problem], up_local, up_global, config, seed)[0]


LOCAL_OPTIMISATIONS = 5
"""The best minimal samples whose inliers are refit until they settle (the best result wins)."""

_SETTLE_ROUNDS = 3
_WHOLE = 0.5
"""A set whose least-squares pose puts every pair within this share of the tolerance is kept
whole without sampling; near the tolerance the sampled search may rightly drop a pair."""


def consensus_many(
    problems: list[tuple[np.ndarray, np.ndarray]],
    up_local: np.ndarray | None,
    up_global: np.ndarray | None,
    config: VerificationConfig,
    seed: int = 0,
) -> list[Consensus]:
    """`consensus` of many sets at once, (local_xyz, global_xyz) each: the same answers, with
    the minimal samples, their errors and the refits of all sets in a few batched arrays.

    Sets of different sizes are padded: padded pairs weigh 0 in every fit and never count as
    inliers.  Each set's samples are drawn as `consensus` draws them (same seed)."""
    sizes = [len(l_xyz) for l_xyz, _ in problems]
    offsets = np.cumsum([0, *sizes])
    pairs = [np.repeat(np.arange(o, o + n)[:, None], 2, axis=1) for o, n in zip(offsets, sizes)]
    local_xyz = np.concatenate([np.reshape(l_xyz, (-1, 3)) for l_xyz, _ in problems] or [[]])
    global_xyz = np.concatenate([np.reshape(g_xyz, (-1, 3)) for _, g_xyz in problems] or [[]])
    return consensus_indexed(pairs, local_xyz, global_xyz, up_local, up_global, config, seed)


def consensus_indexed(
    pairs: list[np.ndarray],
    local_xyz: np.ndarray,
    global_xyz: np.ndarray,
    up_local: np.ndarray | None,
    up_global: np.ndarray | None,
    config: VerificationConfig,
    seed: int = 0,
) -> list[Consensus]:
    """`consensus_many` of sets given as (global index, local index) rows into the two
    position arrays (the sets padded in one gather)."""
    if not pairs:
        return []
    sizes = np.array([len(p) for p in pairs])
    rows = np.concatenate(pairs).reshape(-1, 2)
    owner = np.repeat(np.arange(len(pairs)), sizes)
    slot = np.arange(len(rows)) - np.repeat(np.cumsum(sizes) - sizes, sizes)
    src, dst = np.zeros((2, len(pairs), max(sizes.max(), 1), 3))
    valid = np.zeros(src.shape[:2], dtype=bool)
    src[owner, slot] = np.asarray(local_xyz, float)[rows[:, 1]]
    dst[owner, slot] = np.asarray(global_xyz, float)[rows[:, 0]]
    valid[owner, slot] = True
    return _consensus_padded(src, dst, valid, up_local, up_global, config, seed)


def _consensus_padded(src, dst, valid, up_local, up_global, config, seed) -> list[Consensus]:
    """`consensus_many` of padded (P, M, 3) positions with their `valid` rows."""
    minimal = 2 if up_local is not None and up_global is not None else 3
    sizes = valid.sum(axis=1)
    out: list[Consensus | None] = [None] * len(src)
    small = np.flatnonzero(sizes <= minimal)
    if len(small):
        poses, ok = align_positions_batch(
            src[small], dst[small], up_local, up_global, valid[small].astype(float)
        )
        rms = _rms_of(_errors_of(poses, src[small], dst[small], valid[small]), valid[small])
        for k, i in enumerate(small):
            pose, residual = (poses[k], float(rms[k])) if ok[k] else (None, float("inf"))
            out[i] = Consensus(valid[i][: sizes[i]], pose, residual)
    tested = np.flatnonzero(sizes > minimal)
    if len(tested):  # a set that one least-squares pose explains whole needs no sampling
        poses, ok = align_positions_batch(
            src[tested], dst[tested], up_local, up_global, valid[tested].astype(float)
        )
        errors = _errors_of(poses, src[tested], dst[tested], valid[tested])
        whole = ok & np.all((errors < _WHOLE * config.inlier_tolerance) | ~valid[tested], axis=1)
        rms = _rms_of(errors, valid[tested])
        for k in np.flatnonzero(whole):
            i = tested[k]
            out[i] = Consensus(valid[i][: sizes[i]].copy(), poses[k], float(rms[k]))
        tested = tested[~whole]
    if len(tested):
        for i, found in zip(tested, _tested(src[tested], dst[tested], valid[tested], sizes[tested],
                                             minimal, up_local, up_global, config, seed)):  # fmt: skip
            out[i] = found
    return out  # type: ignore[return-value]


def _tested(src, dst, valid, sizes, minimal, up_local, up_global, config, seed) -> list[Consensus]:
    """The consensus of sets with more pairs than a minimal sample (see `consensus`)."""
    tol = config.inlier_tolerance
    drawn = [_samples(int(m), minimal, config.max_samples, seed) for m in sizes]
    owner = np.repeat(np.arange(len(sizes)), [len(d) for d in drawn])
    picks = np.concatenate(drawn)
    poses, determined = align_positions_batch(
        src[owner[:, None], picks], dst[owner[:, None], picks], up_local, up_global
    )
    errors = _errors_of(poses, src[owner], dst[owner], valid[owner])  # (S, M)
    counts = (errors < tol).sum(axis=1)
    # per set, its determined samples best first: most inliers, then the smallest MSAC cost
    order = np.lexsort((_cost(errors, tol), -counts, owner))
    order = order[determined[order]]
    first = np.searchsorted(owner[order], np.arange(len(sizes)))
    rank = np.arange(len(order)) - first[owner[order]]
    starts = order[rank < LOCAL_OPTIMISATIONS]  # grouped by set, in the order they are tried
    of = owner[starts]
    inliers, pose = _settle_many(
        errors[starts] < tol, poses[starts], src[of], dst[of], valid[of], up_local, up_global, tol
    )
    final = _errors_of(pose, src[of], dst[of], valid[of])
    count, cost = inliers.sum(axis=1), _cost(final, tol)
    # per set, the start with the most inliers, then the smallest cost; the first tried wins
    ranked = np.lexsort((np.arange(len(of)), cost, -count, of))
    firsts = np.flatnonzero(np.diff(of[ranked], prepend=-1) != 0)
    best_of = np.full(len(sizes), -1)
    best_of[of[ranked[firsts]]] = ranked[firsts]
    rms = _rms_of(final, inliers)
    results: list[Consensus] = []
    for i, best in enumerate(best_of.tolist()):
        if best < 0:  # no minimal sample determines a pose
            results.append(Consensus(valid[i][: sizes[i]].copy(), None, float("inf")))
            continue
        kept = inliers[best][: sizes[i]]
        if count[best] < 2:  # no two pairs agree: the set is not one place
            results.append(Consensus(kept, None, float("inf")))
        else:
            results.append(Consensus(kept, pose[best], float(rms[best])))
    return results


def _settle_many(inliers, poses, src, dst, valid, up_local, up_global, tol):
    """Refit each start on its inliers and recompute them, until they no longer change
    (`_SETTLE_ROUNDS` rounds); a start stops where its refit is undetermined or keeps fewer
    than 2 inliers (it keeps its last pose and inliers)."""
    inliers, poses = inliers.copy(), poses.copy()
    active = np.ones(len(inliers), dtype=bool)
    for _ in range(_SETTLE_ROUNDS):
        active &= inliers.sum(axis=1) >= 2  # fewer cannot determine a pose
        rows = np.flatnonzero(active)
        if not len(rows):
            break
        refit, determined = align_positions_batch(
            src[rows], dst[rows], up_local, up_global, inliers[rows].astype(float)
        )
        again = _errors_of(refit, src[rows], dst[rows], valid[rows]) < tol
        moves = determined & (again.sum(axis=1) >= 2)
        settled = np.all(again == inliers[rows], axis=1)
        take = rows[moves]
        poses[take], inliers[take] = refit[moves], again[moves]
        active[rows[~moves | settled]] = False
    return inliers, poses


def _errors_of(poses, src, dst, valid) -> np.ndarray:
    """Distance of every aligned local centre to its partner, pose k on set k: (S, M); padded
    pairs are infinitely far."""
    aligned = src @ np.swapaxes(poses[:, :3, :3], 1, 2) + poses[:, None, :3, 3]
    return np.where(valid, np.linalg.norm(aligned - dst, axis=2), np.inf)


def _cost(errors: np.ndarray, tol: float) -> np.ndarray:
    """MSAC cost per pose: squared errors truncated at the tolerance, summed over the real
    pairs (padded pairs, at infinity, add nothing)."""
    return np.sum(np.where(np.isfinite(errors), np.minimum(errors, tol) ** 2, 0.0), axis=-1)


@lru_cache(maxsize=256)
def _samples(m: int, size: int, limit: int, seed: int) -> np.ndarray:
    """Index tuples of all `size`-subsets of range(m), or `limit` of them drawn with `seed`
    (cached: callers must not change the array)."""
    every = np.array(list(combinations(range(m), size)))
    if len(every) <= limit:
        return every
    rng = np.random.default_rng(seed)
    return every[np.sort(rng.choice(len(every), size=limit, replace=False))]


def _rms_of(errors: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """RMS of each row of `errors` over its `mask`ed entries (inf where none is)."""
    count = mask.sum(axis=1)
    squares = np.where(mask, errors, 0.0) ** 2
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(count > 0, np.sqrt(squares.sum(axis=1) / np.maximum(count, 1)), np.inf)


_CHUNK_ENTRIES = 200_000
"""`MapSupport.extend_many` measures at most this many (local object, candidate) gaps at once."""


class MapSupport:
    """Where the local objects land under a pose, against the map objects each could be.

    `candidates[j]` are the global indices local object j could match (its label, its
    descriptor gate), `global_xyz` the map's positions.  `extend(pose, local_xyz, pairs)` adds
    to `pairs` the local objects outside them that land within `inlier_tolerance` of a free
    candidate (nearest first, one-to-one: guided matching) and counts the conflicts: local
    objects left with no candidate within `conflict_radius`."""

    def __init__(
        self, candidates: list[np.ndarray], global_xyz: np.ndarray, config: VerificationConfig
    ) -> None:
        width = max([len(c) for c in candidates] + [1])
        self._index = np.full((len(candidates), width), -1)
        for j, indices in enumerate(candidates):
            self._index[j, : len(indices)] = indices
        positions = np.full((*self._index.shape, 3), np.inf)  # no candidate: infinitely far
        known = self._index >= 0
        positions[known] = np.asarray(global_xyz, float).reshape(-1, 3)[self._index[known]]
        self._x, self._y, self._z = (np.ascontiguousarray(positions[..., k]) for k in range(3))
        self.config = config

    def extend(
        self, pose: np.ndarray, local_xyz: np.ndarray, pairs: list[tuple[int, int]]
    ) -> tuple[list[tuple[int, int]], int, int]:
        """(pairs with the guided matches added, how many were added, conflicts)."""
        return self.extend_many(pose[None], local_xyz, [pairs])[0]

    def extend_many(
        self, poses: np.ndarray, local_xyz: np.ndarray, pairs: list[list[tuple[int, int]]]
    ) -> list[tuple[list[tuple[int, int]], int, int]]:
        """`extend` of many sets at once: (S, 4, 4) poses, one list of pairs per set."""
        local_xyz = np.asarray(local_xyz, float).reshape(-1, 3)
        n_local, width = len(local_xyz), self._index.shape[1]
        chunk = max(1, _CHUNK_ENTRIES // max(n_local * width, 1))
        out: list[tuple[list[tuple[int, int]], int, int]] = []
        for start in range(0, len(pairs), chunk):
            part = pairs[start : start + chunk]
            out += self._extend_chunk(poses[start : start + chunk], local_xyz, part)
        return out

    def _extend_chunk(self, poses, local_xyz, pairs):
        used = np.zeros((len(pairs), len(local_xyz)), dtype=bool)
        owner = [s for s, set_pairs in enumerate(pairs) for _ in set_pairs]
        used[owner, [l for set_pairs in pairs for _, l in set_pairs]] = True
        aligned = local_xyz @ np.swapaxes(poses[:, :3, :3], 1, 2) + poses[:, None, :3, 3]
        sets, locals_ = np.nonzero(~used)  # only the local objects outside each set
        moved = aligned[sets, locals_]
        dx = self._x[locals_] - moved[:, None, 0]  # (F, width), per coordinate: fast and exact
        dy = self._y[locals_] - moved[:, None, 1]
        dz = self._z[locals_] - moved[:, None, 2]
        gaps = np.sqrt(dx * dx + dy * dy + dz * dz)
        far = gaps.min(axis=1) >= self.config.conflict_radius
        conflicts = np.bincount(sets[far], minlength=len(pairs)).tolist()
        close = gaps < self.config.inlier_tolerance
        bounds = np.searchsorted(sets, np.arange(len(pairs) + 1))
        out = []
        for s, set_pairs in enumerate(pairs):
            lo, hi = bounds[s], bounds[s + 1]
            if lo == hi:  # no local object outside the set
                out.append((list(set_pairs), 0, 0))
                continue
            added = list(set_pairs)
            if close[lo:hi].any():
                self._match(gaps[lo:hi], close[lo:hi], locals_[lo:hi], set_pairs, added)
            out.append(
                (sorted(added, key=lambda p: p[1]), len(added) - len(set_pairs), conflicts[s])
            )
        return out

    def _match(self, gaps, close, locals_, pairs, added) -> None:
        """Greedy one-to-one guided matching, nearest first (ties: local, then candidate order);
        row i of `gaps` / `close` is local object `locals_[i]`."""
        used_local = {l for _, l in pairs}
        used_global = {g for g, _ in pairs}
        rows, cols = np.nonzero(close)
        order = np.argsort(gaps[rows, cols], kind="stable")
        for i, c in zip(rows[order].tolist(), cols[order].tolist()):
            r = int(locals_[i])
            g = int(self._index[r, c])
            if g not in used_global and r not in used_local:
                added.append((g, r))
                used_global.add(g)
                used_local.add(r)


@dataclass(frozen=True)
class Evidence:
    """What speaks for a hypothesis after pose recovery (the confidence model's inputs)."""

    pairs: int  # inlier pairs
    rejected: int  # pairs of the set that disagreed with the pose
    residual: float  # RMS distance (m) of the aligned inlier centres
    fitness: float  # point fitness (or centre fitness without points), 0..1
    support: int  # pairs found by the pose (guided matching), not by the clustering
    conflicts: int  # local objects left with no map object they could be anywhere near
    n_local: int  # local objects in all

    def features(self) -> dict[str, float]:
        """The named features of the confidence model (`semloc.decision.FEATURES`)."""
        return {
            "pairs": float(min(self.pairs, 12)),
            "rejected_share": self.rejected / max(self.pairs + self.rejected, 1),
            "residual": float(min(self.residual, 1.0)),
            "fitness": float(self.fitness),
            "support": float(min(self.support, 12)),
            "conflict_share": self.conflicts / max(self.n_local, 1),
        }
