"""Verification of an association set: which of its pairs agree on one pose, and the evidence.

A set whose pairwise distances are consistent can still hold one wrong pair (a spurious or
mislabelled object admitted by the distance tolerance); its least-squares pose is then pulled
far off while the residual stays small.  `consensus` tests every minimal sample of the set's
pairs (2 pairs in 4-DoF, 3 in 6-DoF; at most `max_samples` of them, seeded), keeps the pose
that the most pairs agree with (ties: the smallest truncated squared error, MSAC), refits on
those inliers and reports which pairs they are.

`MapSupport` asks what the pose says about the local objects outside the set: those that land
near a map object they could be join the hypothesis (guided matching: `support`), those with
no map object of their kind anywhere near are `conflicts`.  `Evidence` is what a hypothesis
has for it after pose recovery: agreeing pairs, rejected pairs, the residual of its centres,
point fitness, support and conflicts.  Pure numpy.
"""

from __future__ import annotations

from dataclasses import dataclass
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
    local_xyz, global_xyz = np.asarray(local_xyz, float), np.asarray(global_xyz, float)
    m = len(local_xyz)
    minimal = 2 if up_local is not None and up_global is not None else 3
    everything = np.ones(m, dtype=bool)
    if m <= minimal:
        pose = _fit(local_xyz, global_xyz, everything, up_local, up_global)
        return Consensus(everything, pose, _rms(pose, local_xyz, global_xyz, everything))
    samples = _samples(m, minimal, config.max_samples, seed)
    poses, determined = align_positions_batch(
        local_xyz[samples], global_xyz[samples], up_local, up_global
    )
    if not determined.any():
        return Consensus(everything, None, float("inf"))
    poses = poses[determined]
    tol = config.inlier_tolerance
    errors = _errors(poses, local_xyz, global_xyz)  # (S, m)
    order = np.lexsort((_cost(errors, tol), -(errors < tol).sum(axis=1)))
    best: tuple[int, float, np.ndarray, np.ndarray] | None = None
    for start in order[:LOCAL_OPTIMISATIONS]:
        inliers, pose = _settle(errors[start] < tol, poses[start], local_xyz, global_xyz,
                                up_local, up_global, tol)  # fmt: skip
        error = _errors(pose[None], local_xyz, global_xyz)
        key = (int(inliers.sum()), -float(_cost(error, tol)[0]))
        if best is None or key > best[:2]:
            best = (*key, inliers, pose)
    assert best is not None
    _, _, inliers, pose = best
    if inliers.sum() < 2:  # no two pairs agree: the set is not one place
        return Consensus(inliers, None, float("inf"))
    return Consensus(inliers, pose, _rms(pose, local_xyz, global_xyz, inliers))


LOCAL_OPTIMISATIONS = 5
"""The best minimal samples whose inliers are refit until they settle (the best result wins)."""


def _cost(errors: np.ndarray, tol: float) -> np.ndarray:
    """MSAC cost per pose: squared errors truncated at the tolerance, summed over pairs."""
    return np.sum(np.minimum(errors, tol) ** 2, axis=-1)


def _settle(inliers, pose, local_xyz, global_xyz, up_local, up_global, tol):
    """Refit on the inliers and recompute them, until they no longer change (3 rounds)."""
    for _ in range(3):
        refit = _fit(local_xyz, global_xyz, inliers, up_local, up_global)
        if refit is None:
            break
        again = _errors(refit[None], local_xyz, global_xyz)[0] < tol
        if again.sum() < 2:
            break
        settled = np.array_equal(again, inliers)
        pose, inliers = refit, again
        if settled:
            break
    return inliers, pose


def least_squares(
    local_xyz: np.ndarray, global_xyz: np.ndarray, up_local, up_global
) -> tuple[np.ndarray | None, float]:
    """The closed-form pose of all pairs and their RMS residual (None, inf if undetermined)."""
    everything = np.ones(len(local_xyz), dtype=bool)
    pose = _fit(local_xyz, global_xyz, everything, up_local, up_global)
    return pose, _rms(pose, local_xyz, global_xyz, everything)


def _samples(m: int, size: int, limit: int, seed: int) -> np.ndarray:
    """Index tuples of all `size`-subsets of range(m), or `limit` of them drawn with `seed`."""
    every = np.array(list(combinations(range(m), size)))
    if len(every) <= limit:
        return every
    rng = np.random.default_rng(seed)
    return every[np.sort(rng.choice(len(every), size=limit, replace=False))]


def _errors(poses: np.ndarray, local_xyz: np.ndarray, global_xyz: np.ndarray) -> np.ndarray:
    """Distance of every aligned local centre to its partner under each pose: (S, m)."""
    aligned = local_xyz @ np.swapaxes(poses[:, :3, :3], 1, 2) + poses[:, None, :3, 3]
    return np.linalg.norm(aligned - global_xyz, axis=2)


def _fit(local_xyz, global_xyz, mask, up_local, up_global) -> np.ndarray | None:
    poses, determined = align_positions_batch(
        local_xyz[mask][None], global_xyz[mask][None], up_local, up_global
    )
    return poses[0] if determined[0] else None


def _rms(pose, local_xyz, global_xyz, mask) -> float:
    if pose is None or not mask.any():
        return float("inf")
    errors = _errors(pose[None], local_xyz[mask], global_xyz[mask])[0]
    return float(np.sqrt(np.mean(errors**2)))


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
        self._positions = np.full((*self._index.shape, 3), np.nan)
        known = self._index >= 0
        self._positions[known] = np.asarray(global_xyz, float).reshape(-1, 3)[self._index[known]]
        self.config = config

    def extend(
        self, pose: np.ndarray, local_xyz: np.ndarray, pairs: list[tuple[int, int]]
    ) -> tuple[list[tuple[int, int]], int, int]:
        """(pairs with the guided matches added, how many were added, conflicts)."""
        used_local = {l for _, l in pairs}
        used_global = {g for g, _ in pairs}
        free = np.array([j for j in range(len(local_xyz)) if j not in used_local], dtype=int)
        if len(free) == 0:
            return list(pairs), 0, 0
        aligned = local_xyz[free] @ pose[:3, :3].T + pose[:3, 3]
        gaps = np.linalg.norm(self._positions[free] - aligned[:, None], axis=2)
        gaps = np.where(np.isnan(gaps), np.inf, gaps)
        conflicts = int(np.sum(gaps.min(axis=1) >= self.config.conflict_radius))
        added = list(pairs)
        rows, cols = np.nonzero(gaps < self.config.inlier_tolerance)
        for r, c in sorted(zip(rows, cols), key=lambda rc: gaps[rc]):
            g, l = int(self._index[free[r], c]), int(free[r])
            if g not in used_global and l not in used_local:
                added.append((g, l))
                used_global.add(g)
                used_local.add(l)
        return sorted(added, key=lambda p: p[1]), len(added) - len(pairs), conflicts


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
