"""Verification of an association set: which of its pairs agree on one pose, and the evidence.

A set whose pairwise distances are consistent can still hold one wrong pair (a spurious or
mislabelled object admitted by the distance tolerance); its least-squares pose is then pulled
far off while the residual stays small.  `consensus` tests every minimal sample of the set's
pairs (2 pairs in 4-DoF, 3 in 6-DoF; at most `max_samples` of them, seeded), keeps the pose
that the most pairs agree with (ties: the smallest truncated squared error, MSAC), refits on
those inliers and reports which pairs they are.

`Evidence` is what a hypothesis has for it after pose recovery: inlier pairs, rejected pairs,
the residual of its centres, point fitness, and what its pose says about the local objects
outside the set: `support` (aligned, they land near a map object they could be) and
`conflicts` (no map object of their kind anywhere near).  `MapSupport` computes the latter
for many poses at once.  Pure numpy.
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
    support_radius: float = Field(
        0.5, gt=0, description="An unmatched local object supports a pose when it lands this "
        "close (m) to a map object it could be.",
    )  # fmt: skip
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
    errors = _errors(poses, local_xyz, global_xyz)  # (S, m)
    tol = config.inlier_tolerance
    count = (errors < tol).sum(axis=1)
    cost = np.minimum(errors, tol) ** 2
    best = int(np.lexsort((cost.sum(axis=1), -count))[0])
    inliers, pose = errors[best] < tol, poses[best]
    for _ in range(2):  # refit on the inliers; the inlier set may settle once more
        refit = _fit(local_xyz, global_xyz, inliers, up_local, up_global)
        if refit is None:
            break
        again = _errors(refit[None], local_xyz, global_xyz)[0] < tol
        if again.sum() < inliers.sum():
            break
        pose, settled, inliers = refit, np.array_equal(again, inliers), again
        if settled:
            break
    return Consensus(inliers, pose, _rms(pose, local_xyz, global_xyz, inliers))


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

    `candidates[j]` are the global positions local object j could match (its label, its
    descriptor gate); `counts(poses, matched)` says, per pose, how many of the local objects
    not in `matched` land within `support_radius` of a candidate (support) and how many have
    none within `conflict_radius` (conflicts)."""

    def __init__(self, candidates: list[np.ndarray], config: VerificationConfig) -> None:
        width = max([len(c) for c in candidates] + [1])
        self._positions = np.full((len(candidates), width, 3), np.nan)
        for j, positions in enumerate(candidates):
            self._positions[j, : len(positions)] = positions
        self.config = config

    def counts(
        self, pose: np.ndarray, local_xyz: np.ndarray, matched: np.ndarray
    ) -> tuple[int, int]:
        """(support, conflicts) of the local objects whose index is not in `matched`."""
        free = np.setdiff1d(np.arange(len(local_xyz)), matched)
        if len(free) == 0:
            return 0, 0
        aligned = local_xyz[free] @ pose[:3, :3].T + pose[:3, 3]
        gaps = np.linalg.norm(self._positions[free] - aligned[:, None], axis=2)
        nearest = np.min(np.where(np.isnan(gaps), np.inf, gaps), axis=1)
        support = int(np.sum(nearest < self.config.support_radius))
        conflicts = int(np.sum(nearest >= self.config.conflict_radius))
        return support, conflicts


@dataclass(frozen=True)
class Evidence:
    """What speaks for a hypothesis after pose recovery (the confidence model's inputs)."""

    pairs: int  # inlier pairs
    rejected: int  # pairs of the set that disagreed with the pose
    residual: float  # RMS distance (m) of the aligned inlier centres
    fitness: float  # point fitness (or centre fitness without points), 0..1
    support: int  # unmatched local objects landing near a map object they could be
    conflicts: int  # unmatched local objects with no such map object anywhere near
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
