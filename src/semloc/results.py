"""What a localization returns: `Result` (status, pose, ranked `Hypothesis` list, `Step` records).

Shared by the Localizer and every baseline, so that callers, the CLI, the evaluation and the
JSON output see one model.  `Status` is the decision's vocabulary (see `decision.py`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any, Literal

import numpy as np

from semloc.changes import Changes

Status = Literal["localized", "ambiguous", "failed"]
STATUSES: tuple[Status, ...] = ("localized", "ambiguous", "failed")


@dataclass
class Hypothesis:
    """One candidate answer: an association set and the pose it implies."""

    rank: int
    score: float
    pairs: list[tuple[str, str]]  # (global id, local id)
    pose: np.ndarray | None
    fitness: float | None = None
    rmse: float | None = None
    residual: float | None = None  # RMS distance (m) of aligned local centres to their partners
    method: str = ""
    confidence: float | None = None  # calibrated probability that the pose is right
    evidence: float | None = None  # the confidence model's evidence logit (ranks hypotheses)
    features: dict[str, float] | None = None  # its inputs (semloc.decision.FEATURES)
    rejected: list[tuple[str, str]] = field(default_factory=list)  # pairs that disagreed

    def to_dict(self) -> dict[str, Any]:
        return {
            "rank": self.rank,
            "score": round(self.score, 6),
            "pairs": [{"global": g, "local": l} for g, l in self.pairs],
            "pose": None if self.pose is None else np.round(self.pose, 9).tolist(),
            "fitness": None if self.fitness is None else round(self.fitness, 6),
            "rmse": None if self.rmse is None else round(self.rmse, 6),
            "residual": None if self.residual is None else round(self.residual, 6),
            "method": self.method,
            "confidence": None if self.confidence is None else round(self.confidence, 6),
            "evidence": None if self.evidence is None else round(self.evidence, 6),
            "features": None
            if self.features is None
            else {k: round(v, 6) for k, v in self.features.items()},
            "rejected": [{"global": g, "local": l} for g, l in self.rejected],
        }


@dataclass
class Step:
    """What one update did: local objects so far, sets in the pool, top scores, time.

    `status` is None for an update that only grew the association sets (`answer=False`); its
    `top_scores` are then those of the best association sets rather than of the hypotheses.
    """

    step: int
    n_local: int
    n_sets: int
    top_scores: list[float]
    ms: float
    status: Status | None = "failed"

    def to_dict(self) -> dict[str, Any]:
        return {
            "step": self.step,
            "n_local": self.n_local,
            "n_sets": self.n_sets,
            "top_scores": [round(s, 6) for s in self.top_scores],
            "ms": round(self.ms, 3),
            "status": self.status,
        }


@dataclass
class Result:
    """The answer after an update: status, best pose, ranked hypotheses and per-step records.

    `reason` says why an answer is `ambiguous` or `failed` (empty when `localized`); the pose
    of an `ambiguous` result is the best candidate's, not a trusted answer: `pose_is_answer`
    says which (the JSON carries it too)."""

    status: Status
    pose: np.ndarray | None
    hypotheses: list[Hypothesis]
    steps: list[Step] = field(default_factory=list)
    timing_ms: dict[str, float] = field(default_factory=dict)
    reason: str = ""
    explain: Callable[[], Changes] | None = field(default=None, repr=False, compare=False)
    """Computes `changes` on first use (streaming updates whose changes nobody reads skip it)."""

    @classmethod
    def of(
        cls,
        status: Status,
        hypotheses: list[Hypothesis],
        steps: list[Step],
        timing_ms: dict,
        reason: str = "",
        explain: Callable[[], Changes] | None = None,
    ) -> Result:
        """The result of an update: the pose is the best hypothesis's unless `failed`."""
        pose = hypotheses[0].pose if hypotheses and status != "failed" else None
        return cls(status, pose, hypotheses, list(steps), dict(timing_ms), reason, explain)

    @cached_property
    def changes(self) -> Changes:
        """What the best hypothesis implies changed since the map was made (`semloc.changes`;
        empty without an explanation)."""
        return Changes() if self.explain is None else self.explain()

    @property
    def best(self) -> Hypothesis | None:
        return self.hypotheses[0] if self.hypotheses else None

    @property
    def pose_is_answer(self) -> bool:
        """Whether `pose` is a trusted answer (`localized`), not only the best candidate's."""
        return self.status == "localized" and self.pose is not None

    @property
    def confidence(self) -> float | None:
        """The calibrated probability that the best hypothesis is right (None without one)."""
        return None if self.best is None else self.best.confidence

    def to_dict(self) -> dict[str, Any]:
        confidence = self.confidence
        return {
            "status": self.status,
            "reason": self.reason,
            "confidence": None if confidence is None else round(confidence, 6),
            "pose_is_answer": self.pose_is_answer,
            "pose": None if self.pose is None else np.round(self.pose, 9).tolist(),
            "hypotheses": [h.to_dict() for h in self.hypotheses],
            "steps": [s.to_dict() for s in self.steps],
            "timing_ms": {k: round(v, 3) for k, v in self.timing_ms.items()},
            "changes": self.changes.to_dict(),
        }
