"""Verification of an association set: which of its pairs agree on one pose, and the evidence.

A set whose pairwise distances are consistent can still hold one wrong pair (a spurious or
mislabelled object admitted by the distance tolerance); its least-squares pose is then pulled
far off while the residual stays small.  `consensus` tests every minimal sample of the set's
pairs (2 pairs in 4-DoF, 3 in 6-DoF; at most `max_samples` of them, seeded), keeps the pose
that the most pairs agree with (ties: the smallest truncated squared error, MSAC), refits on
those inliers and reports which pairs they are.  A set whose least-squares pose already puts
every pair well within tolerance (half of it) is accepted whole without sampling: the sampled
search finds that pose again there, while near the tolerance it may rightly drop a pair.
`consensus_many` does all of this for many sets in one compiled pass (numba), the minimal
samples fitted by `closed_form.fit`.

`verify_sets` runs the whole verification of the Localizer's screened sets at once: the
consensus, the guided matching on the map and the consensus of the grown sets, giving each
set's `Verified` pairs, rejected pairs, pose, residual, support and conflicts.

`MapSupport` asks what the pose says about the local objects outside the set: those that land
near a map object they could be join the hypothesis (guided matching: `support`), those with
no map object of their kind anywhere near are `conflicts`.  `Evidence` is what a hypothesis
has for it after pose recovery: agreeing pairs, rejected pairs, the residual of its centres,
point fitness, support and conflicts.  Pure computation on numpy arrays.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from itertools import combinations
from typing import NamedTuple

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from semloc._verification_fast import consensus_kernel, guided_matches
from semloc.pointsets import axes_by_spread
from semloc.pose import from_z_up, z_up_rotations


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
    found = consensus_rows(rows, sizes, local_xyz, global_xyz, up_local, up_global, config, seed)
    return found.listed(sizes)


class Consensuses(NamedTuple):
    """The consensus of many sets as arrays, one row per set (pairs padded to the widest)."""

    inliers: np.ndarray  # (S, M) bool, False past a set's size
    poses: np.ndarray  # (S, 4, 4), where `has_pose`
    has_pose: np.ndarray  # (S,) bool
    residual: np.ndarray  # (S,), inf without a pose

    def agreeing(self, sizes: np.ndarray) -> np.ndarray:
        """Whether each pair is an inlier, one value per pair of the sets (`sizes` each, one
        set after the other, as `consensus_rows` takes them)."""
        return self.inliers[np.arange(self.inliers.shape[1]) < np.asarray(sizes)[:, None]]

    def listed(self, sizes: np.ndarray) -> list[Consensus]:
        """One `Consensus` per set (`sizes` pairs each)."""
        return [
            Consensus(self.inliers[i, :n].copy(), self.poses[i] if self.has_pose[i] else None,
                      float(self.residual[i]))
            for i, n in enumerate(sizes.tolist())
        ]  # fmt: skip


def consensus_rows(
    pairs: np.ndarray,
    sizes: np.ndarray,
    local_xyz: np.ndarray,
    global_xyz: np.ndarray,
    up_local: np.ndarray | None,
    up_global: np.ndarray | None,
    config: VerificationConfig,
    seed: int = 0,
) -> Consensuses:
    """`consensus_indexed` of sets whose (global index, local index) rows come one set after
    the other in `pairs` (`sizes` rows each), as arrays: no per-set Python objects."""
    sizes = np.asarray(sizes, dtype=np.int64)
    if not len(sizes):
        return Consensuses(
            np.zeros((0, 1), bool), np.zeros((0, 4, 4)), np.zeros(0, bool), np.zeros(0)
        )
    owner = np.repeat(np.arange(len(sizes)), sizes)
    slot = np.arange(len(pairs)) - np.repeat(np.cumsum(sizes) - sizes, sizes)
    src, dst = np.zeros((2, len(sizes), max(sizes.max(initial=0), 1), 3))
    src[owner, slot] = np.asarray(local_xyz, float)[pairs[:, 1]]
    dst[owner, slot] = np.asarray(global_xyz, float)[pairs[:, 0]]
    return _consensus_padded(src, dst, sizes, up_local, up_global, config, seed)


def _consensus_padded(src, dst, sizes, up_local, up_global, config, seed) -> Consensuses:
    """`consensus_many` of padded (P, M, 3) positions whose first `sizes` rows are real."""
    yaw_only = up_local is not None and up_global is not None
    minimal = 2 if yaw_only else 3
    if yaw_only:  # in z-up frames the 4-DoF pose is a yaw; distances do not change
        A_l, A_g = z_up_rotations(up_local, up_global)
        src, dst = src @ A_l.T, dst @ A_g.T
    tables = [_samples(int(m), minimal, config.max_samples, seed) for m in range(sizes.max() + 1)]
    counts = np.array([len(t) if m > minimal else 0 for m, t in enumerate(tables)])
    rows = np.concatenate([t for m, t in enumerate(tables) if m > minimal] or [[]])
    poses, has_pose, inliers, residual = consensus_kernel(
        np.ascontiguousarray(src), np.ascontiguousarray(dst), sizes.astype(np.int64),
        rows.astype(np.int64).reshape(-1, minimal), np.cumsum(counts) - counts, counts, yaw_only,
        config.inlier_tolerance, _WHOLE, LOCAL_OPTIMISATIONS, _SETTLE_ROUNDS,
    )  # fmt: skip
    if yaw_only:
        poses = from_z_up(poses, A_l, A_g)
    return Consensuses(inliers, poses, has_pose, residual)


@lru_cache(maxsize=256)
def _samples(m: int, size: int, limit: int, seed: int) -> np.ndarray:
    """Index tuples of all `size`-subsets of range(m), or `limit` of them drawn with `seed`
    (cached: callers must not change the array)."""
    every = np.array(list(combinations(range(m), size)))
    if len(every) <= limit:
        return every
    rng = np.random.default_rng(seed)
    return every[np.sort(rng.choice(len(every), size=limit, replace=False))]


class MapSupport:
    """Where the local objects land under a pose, against the map objects each could be.

    `candidates[j]` are the global indices local object j could match (its label, its
    descriptor gate; sorted), `global_xyz` the map's positions.  `extend(pose, local_xyz,
    pairs)` adds to `pairs` the local objects outside them that land within `inlier_tolerance`
    of a free candidate (nearest first, one-to-one: guided matching) and counts the conflicts:
    local objects left with no candidate within `conflict_radius`.

    Each local object's candidates are kept sorted along the map's longest axis (`axis`: given,
    e.g. the map's `sweep_order.axis`, or found from `global_xyz`), so that the ones near where
    it lands are a range; `assign(j, candidates)` sets them when an object is new or
    re-detected (a Localizer keeps one MapSupport across its updates)."""

    def __init__(
        self,
        candidates: list[np.ndarray],
        global_xyz: np.ndarray,
        config: VerificationConfig,
        *,
        axis: int | None = None,
    ) -> None:
        self._global_xyz = np.ascontiguousarray(np.asarray(global_xyz, float).reshape(-1, 3))
        self._axis = int(axes_by_spread(self._global_xyz)[0]) if axis is None else int(axis)
        self._sorted: list[tuple[np.ndarray, np.ndarray]] = []  # per object: globals, columns
        self._packed: tuple[np.ndarray, ...] | None = None
        self.config = config
        for j, indices in enumerate(candidates):
            self.assign(j, indices)

    def assign(self, j: int, candidates: np.ndarray) -> None:
        """Local object j (the next new one, or a re-detected one) may match `candidates`."""
        candidates = np.asarray(candidates, dtype=np.int64)
        columns = np.argsort(self._global_xyz[candidates, self._axis], kind="stable")
        entry = (candidates[columns], columns)
        if j == len(self._sorted):
            self._sorted.append(entry)
        else:
            self._sorted[j] = entry
        self._packed = None

    def _pack(self) -> tuple[np.ndarray, ...]:
        """All objects' sorted candidates as one CSR: starts, global indices, columns, axis."""
        if self._packed is None:
            sizes = [len(g) for g, _ in self._sorted]
            starts = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
            globals_ = np.concatenate([g for g, _ in self._sorted] + [np.zeros(0, np.int64)])
            columns = np.concatenate([c for _, c in self._sorted] + [np.zeros(0, np.int64)])
            along = np.ascontiguousarray(self._global_xyz[globals_, self._axis])
            self._packed = (starts, globals_, columns, along)
        return self._packed

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
        if not pairs:
            return []
        sizes = np.array([len(p) for p in pairs], dtype=np.int64)
        flat = np.array([pair for set_pairs in pairs for pair in set_pairs], dtype=np.int64)
        added, added_start, conflicts = self.extend_rows(poses, local_xyz, flat, sizes)
        found, bounds = added.tolist(), added_start.tolist()
        out = []
        for s, set_pairs in enumerate(pairs):
            if len({l for _, l in set_pairs}) == len(local_xyz):  # no local object outside
                out.append((list(set_pairs), 0, 0))
                continue
            new = [tuple(p) for p in found[bounds[s] : bounds[s + 1]]]
            grown = sorted([*set_pairs, *new], key=lambda p: p[1])
            out.append((grown, len(new), int(conflicts[s])))
        return out

    def extend_rows(
        self, poses: np.ndarray, local_xyz: np.ndarray, pairs: np.ndarray, sizes: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Guided matching of many sets whose (global index, local index) rows come one set
        after the other in `pairs` (`sizes` rows each), under (S, 4, 4) `poses`: the pairs the
        sets gain, nearest first, as one (A, 2) array with each set's start (S + 1), and each
        set's conflicts (no shortcut for a set holding every local object: it gains nothing
        and has no conflicts anyway)."""
        local_xyz = np.asarray(local_xyz, float).reshape(-1, 3)
        poses = np.asarray(poses, float).reshape(-1, 4, 4)
        aligned = local_xyz @ np.swapaxes(poses[:, :3, :3], 1, 2) + poses[:, None, :3, 3]
        sizes = np.asarray(sizes, dtype=np.int64)
        cfg = self.config
        return guided_matches(
            np.ascontiguousarray(aligned), np.asarray(pairs, np.int64).reshape(-1, 2),
            np.cumsum(sizes) - sizes, sizes, *self._pack(), self._global_xyz, self._axis,
            cfg.inlier_tolerance, cfg.conflict_radius,
        )  # fmt: skip


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
    weight: float | None = None  # the inlier pairs' summed semantic weight (None: all 1)

    def features(self) -> dict[str, float]:
        """The named features of the confidence model (`semloc.decision.FEATURES`); `n_pairs`
        counts each pair by its semantic weight (`semloc.semantics.pair_weight`): an exact
        match outweighs a parent class, which outweighs a confusable one."""
        pairs = self.pairs if self.weight is None else min(self.weight, self.pairs)
        return {
            "n_pairs": float(min(pairs, 12)),
            "rejected_share": self.rejected / max(self.pairs + self.rejected, 1),
            "residual": float(min(self.residual, 1.0)),
            "fitness": float(self.fitness),
            "n_support": float(min(self.support, 12)),
            "conflict_share": self.conflicts / max(self.n_local, 1),
        }


@dataclass
class Verified:
    """A screened association set after the consensus: inlier and rejected (global index,
    local index) pairs, the inliers' closed-form pose and residual, and its map evidence."""

    score: float  # the set's clustering score
    pairs: list[tuple[int, int]]
    rejected: list[tuple[int, int]]
    pose: np.ndarray | None
    residual: float
    support: int
    conflicts: int


def verify_sets(
    set_pairs: np.ndarray, set_sizes: np.ndarray, scores: np.ndarray, local_xyz: np.ndarray,
    global_xyz: np.ndarray, ups: tuple[np.ndarray | None, np.ndarray | None],
    config: VerificationConfig, support: MapSupport,
) -> list[Verified]:  # fmt: skip
    """Each association set (its (global index, local index) rows `set_pairs`, `set_sizes`
    rows per set, one set after the other, its clustering score in `scores`) split by its
    consensus pose, grown by guided matching on the map (`support`; the grown pairs verified
    once more together), and that pose's evidence on the map.

    All sets go through each step at once, as rows with the set of each row (`owner`); only
    the result is turned into per-set lists."""
    n = len(set_sizes)
    if not n:
        return []
    up = (*ups, config)
    first = consensus_rows(set_pairs, set_sizes, local_xyz, global_xyz, *up)
    agree, owner = first.agreeing(set_sizes), _owners(set_sizes)
    kept, kept_owner = set_pairs[agree], owner[agree]
    rejected, rejected_owner = set_pairs[~agree], owner[~agree]
    kept_sizes = np.bincount(kept_owner, minlength=n)
    added, added_start, conflicts = support.extend_rows(first.poses, local_xyz, kept, kept_sizes)
    # a posed set with local objects outside it grows (its pairs then by local object)
    grows = first.has_pose & (kept_sizes < len(local_xyz))
    rows, owner, is_new = _grown(kept, kept_owner, added, _owners(np.diff(added_start)), grows)
    poses, residual = first.poses.copy(), first.residual.copy()
    regrown = grows & (np.bincount(owner[is_new], minlength=n) > 0)
    if regrown.any():  # the grown pairs verified together
        again = np.flatnonzero(regrown[owner])
        sizes = np.bincount(owner, minlength=n)[regrown]
        second = consensus_rows(rows[again], sizes, local_xyz, global_xyz, *up)
        settled = np.zeros(n, dtype=bool)
        settled[regrown] = second.has_pose
        poses[settled] = second.poses[second.has_pose]
        residual[settled] = second.residual[second.has_pose]
        disagree = again[~second.agreeing(sizes)]
        disagree = disagree[settled[owner[disagree]]]
        rejected = np.concatenate([rejected, rows[disagree]])
        rejected_owner = np.concatenate([rejected_owner, owner[disagree]])
        keep = np.ones(len(rows), dtype=bool)
        keep[disagree] = False
        rows, owner, is_new = rows[keep], owner[keep], is_new[keep]
    order = np.argsort(rejected_owner, kind="stable")  # a set's first rejections first
    pairs, rejected = _split(rows, owner, n), _split(rejected[order], rejected_owner[order], n)
    grown = np.bincount(owner[is_new], minlength=n).tolist()
    conflicts = np.where(grows, conflicts, 0).tolist()
    return [
        Verified(score, pairs[i], rejected[i], poses[i] if first.has_pose[i] else None,
                 float(residual[i]), grown[i], conflicts[i])
        for i, score in enumerate(np.asarray(scores).tolist())
    ]  # fmt: skip


def _owners(sizes: np.ndarray) -> np.ndarray:
    """The set of each row, for sets of `sizes` rows one after the other."""
    return np.repeat(np.arange(len(sizes)), sizes)


def _grown(kept, kept_owner, added, added_owner, grows) -> tuple[np.ndarray, ...]:
    """The kept rows of every set with the added rows of the sets that grow, set after set:
    a growing set's rows ordered by local object, the others' as they were; (rows, owner,
    whether each row was added)."""
    taken = grows[added_owner]
    rows = np.concatenate([kept, added[taken]])
    owner = np.concatenate([kept_owner, added_owner[taken]])
    is_new = np.arange(len(rows)) >= len(kept)
    order = np.lexsort((np.where(grows[owner], rows[:, 1], np.arange(len(rows))), owner))
    return rows[order], owner[order], is_new[order]


def _split(rows: np.ndarray, owner: np.ndarray, n: int) -> list[list[tuple[int, int]]]:
    """Rows grouped set after set (`owner` ascending) as n lists of int pairs."""
    sizes = np.bincount(owner, minlength=n)
    listed, ends = rows.tolist(), np.cumsum(sizes).tolist()
    return [list(map(tuple, listed[end - size : end])) for end, size in zip(ends, sizes.tolist())]
