"""What a localization returns: `Result` (status, pose, ranked `Hypothesis` list, `Step` records).

Shared by the Localizer and every baseline, so that callers, the CLI, the evaluation and the
JSON output see one model.  `Status` is the decision's vocabulary (see `decision.py`).  Results
are written as JSON by `Result.to_json` and read back by `saved_result` (every field checked:
the CLI's `view`, `export` and `update-map --result`); no file access here.
"""

from __future__ import annotations

import json
import reprlib
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any, ClassVar, Literal

import numpy as np

from semloc.changes import Changes
from semloc.maps import MAX_COORDINATE
from semloc.transforms import as_pose

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
    outside_prior: bool | None = None  # its pose is outside the position prior (None: no prior)
    missing: int | None = None  # map objects its pose puts in the recent looks that no
    # detection accounts for (None: no coverage given)
    expected: int | None = None  # map objects its pose puts in the recent looks
    refined: bool = True  # False: its pose is the closed form's (or search's), not robust ICP's
    _refiner: Callable[[Hypothesis], None] | None = field(default=None, repr=False, compare=False)

    def refine(self) -> Hypothesis:
        """Refine the pose of an unrefined hypothesis now (robust ICP, as the best one's):
        pose, fitness, rmse, residual, method, features and evidence are updated in place, its
        rank and confidence are not (they were weighed against the others); itself returned.
        A hypothesis that cannot be refined (refined already, read from JSON) is unchanged."""
        if not self.refined and self._refiner is not None:
            self._refiner(self)
        return self

    def to_dict(self) -> dict[str, Any]:
        return (
            {
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
            | ({} if self.outside_prior is None else {"outside_prior": self.outside_prior})
            | ({} if self.missing is None else {"missing": self.missing, "expected": self.expected})
            | ({} if self.refined else {"refined": False})
        )


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


@dataclass(frozen=True)
class Look:
    """A "look there next" suggestion of an ambiguous answer (`semloc.next_look`): a map
    object, where it lies in the local frame under each top hypothesis (by rank), the ranks a
    look at their spot tells from the others, and the expected reduction of the ambiguity
    (bits)."""

    label: str
    global_id: str
    where: dict[int, np.ndarray]
    separates: list[int]
    gain: float

    def to_dict(self) -> dict[str, Any]:
        return {
            "label": self.label,
            "global_id": self.global_id,
            "where": {str(rank): np.round(p, 6).tolist() for rank, p in self.where.items()},
            "separates": list(self.separates),
            "gain": round(self.gain, 6),
        }

    @classmethod
    def from_dict(cls, data: object, index: int = 0) -> Look:
        """A suggestion of a result document; `ValueError` naming the field when malformed."""
        try:
            assert isinstance(data, dict) and isinstance(data["where"], dict)
            where = {int(rank): as_point(p) for rank, p in data["where"].items()}
            separates = [int(r) for r in data["separates"]]
            assert isinstance(data["label"], str) and isinstance(data["global_id"], str)
            gain = float(data["gain"])
            assert np.isfinite(gain)
        except (AssertionError, KeyError, TypeError, ValueError):
            raise ValueError(f"'next_look[{index}]' is not a suggestion: {_brief(data)}") from None
        return cls(data["label"], data["global_id"], where, separates, gain)


def as_point(value: object) -> np.ndarray:
    """A finite [x, y, z] (`ValueError` otherwise)."""
    point = np.asarray(value, dtype=float)
    if point.shape != (3,) or not np.all(np.isfinite(point)):
        raise ValueError("not a finite [x, y, z]")
    return point


@dataclass(frozen=True)
class Support:
    """How recent the evidence of an answer's pose is: its local objects' pairs, the span of
    their `seen` keyframes, how many updates and metres of odometry ago the oldest of them was
    last detected (metres: 0 without robot positions), and whether the place is tracked."""

    pairs: int
    seen: tuple[int, int]
    updates_ago: int
    metres: float
    tracked: bool = False
    changed: int = 0
    """Objects judged since a tracked claim began that a plausible move explains (0 unless
    tracked)."""
    contradicting: int = 0
    """Objects judged since a tracked claim began that contradict it (0 unless tracked)."""
    missing: int | None = None
    """Map objects the pose puts in the recent looks that no detection accounts for (None: no
    coverage given, so no negative evidence)."""
    expected: int | None = None
    """Map objects the pose puts in the recent looks (None: no coverage given)."""
    missing_ids: tuple[str, ...] | None = None
    """The ids of the map objects counted in `missing`, as the answer's pose places the looks
    (at most `MISSING_IDS_KEPT`, in the map's order; None: no coverage given)."""

    MISSING_IDS_KEPT: ClassVar[int] = 50
    """The most ids an answer lists (a look that misses more says so by `missing` alone)."""

    def to_dict(self) -> dict[str, Any]:
        return {
            "pairs": self.pairs,
            "seen": [int(k) for k in self.seen],
            "updates_ago": int(self.updates_ago),
            "metres": round(self.metres, 3),
            "tracked": self.tracked,
            "changed": self.changed,
            "contradicting": self.contradicting,
            "missing": self.missing,
            "expected": self.expected,
            "missing_ids": None if self.missing_ids is None else list(self.missing_ids),
        }

    @classmethod
    def from_dict(cls, data: object) -> Support | None:
        """The support of a result document (None when absent); `ValueError` when malformed."""
        if data is None:
            return None
        try:
            assert isinstance(data, dict)
            seen = data["seen"]
            missing, expected = data.get("missing"), data.get("expected")
            ids = data.get("missing_ids")
            assert ids is None or (isinstance(ids, list) and all(isinstance(i, str) for i in ids))
            return cls(int(data["pairs"]), (int(seen[0]), int(seen[1])),
                       int(data["updates_ago"]), float(data["metres"]), bool(data["tracked"]),
                       int(data.get("changed", 0)), int(data.get("contradicting", 0)),
                       None if missing is None else int(missing),
                       None if expected is None else int(expected),
                       None if ids is None else tuple(ids))  # fmt: skip
        except (AssertionError, KeyError, IndexError, TypeError, ValueError):
            raise ValueError(f"'support' is not a support record: {_brief(data)}") from None


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
    support: Support | None = None
    """How recent the evidence for the pose is (None without a pose)."""
    suggest: Callable[[], list[Look]] | None = field(default=None, repr=False, compare=False)
    """Computes `next_look` on first use (only an `ambiguous` answer has one)."""

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

    @cached_property
    def next_look(self) -> list[Look]:
        """Where to look next to tell the top hypotheses apart, best first (`semloc.next_look`;
        empty unless `ambiguous`)."""
        if self.status != "ambiguous" or self.suggest is None:
            return []
        return self.suggest()

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

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Result:
        """A Result from its JSON document (`to_dict`, e.g. a `semloc serve` answer), the
        inverse of `to_dict` up to its rounding; `ValueError` naming a field not as written."""
        if not isinstance(data, dict):
            raise ValueError("a result must be an object")
        saved = saved_result(data)
        raws = data.get("hypotheses") or []
        hypotheses = [_hypothesis_from(raw, pose, pairs, i)
                      for i, ((pose, pairs), raw) in enumerate(zip(saved.hypotheses, raws))]  # fmt: skip
        try:
            steps = [Step(**s) for s in data.get("steps") or []]
        except TypeError as exc:
            raise ValueError(f"'steps' are not steps ({exc})") from None
        changes = Changes.from_dict(data.get("changes") or {})
        looks = [Look.from_dict(x, i) for i, x in enumerate(_list_field(data.get("next_look"),
                                                                         "next_look"))]  # fmt: skip
        return cls(
            saved.status or "failed", saved.pose, hypotheses, steps,
            dict(data.get("timing_ms") or {}), str(data.get("reason") or ""),
            explain=lambda: changes, support=Support.from_dict(data.get("support")),
            suggest=lambda: looks,
        )  # fmt: skip

    def to_json(self, **extra: Any) -> str:
        """The JSON text of `to_dict()` (and `extra` keys), as every writer of a result writes
        it: indented, NaN and infinities refused (`ValueError`)."""
        return json.dumps({**self.to_dict(), **extra}, indent=1, allow_nan=False) + "\n"

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
            "support": None if self.support is None else self.support.to_dict(),
            "next_look": [look.to_dict() for look in self.next_look],
        }


# Reading a saved result back ----------------------------------------------------------------
@dataclass(frozen=True)
class SavedResult:
    """A result read back (the JSON of `Result.to_json`, or a ground-truth file): the pose, the
    status, each ranked hypothesis's pose and pairs, and the moved objects of `changes` (a
    ground-truth file gives only a pose)."""

    pose: np.ndarray | None
    status: str | None = None
    hypotheses: tuple[tuple[np.ndarray | None, list[tuple[str, str]]], ...] = ()
    moved: tuple[tuple[str, str], ...] = ()  # (global id, local id) of `changes.moved`

    @property
    def pairs(self) -> list[tuple[str, str]]:
        """(global id, local id) pairs of the best hypothesis."""
        return self.hypotheses[0][1] if self.hypotheses else []


def saved_result(data: dict[str, Any]) -> SavedResult:
    """A parsed result document (or a ground-truth document, `T_global_local`), every field
    checked: `ValueError` naming the field and what it must be."""
    key = "pose" if "pose" in data else "T_global_local"
    pose = None if data.get(key) is None else saved_pose(data[key], key)
    status = data.get("status")
    if status is not None and status not in STATUSES:
        raise ValueError(f"'status' must be one of {', '.join(STATUSES)}, got {_brief(status)}")
    hypotheses = _list_field(data.get("hypotheses"), "hypotheses")
    return SavedResult(
        pose,
        status,
        tuple(_hypothesis(h, i) for i, h in enumerate(hypotheses)),
        _moved(data.get("changes")),
    )


def _hypothesis_from(
    raw: dict[str, Any], pose: np.ndarray | None, pairs: list[tuple[str, str]], index: int
) -> Hypothesis:
    """A hypothesis of a result document (pose and pairs checked by `saved_result`)."""

    def number(key: str) -> float | None:
        value = raw.get(key)
        if value is not None and (isinstance(value, bool) or not isinstance(value, (int, float))):
            raise ValueError(f"'hypotheses[{index}].{key}' must be a number, got {_brief(value)}")
        return None if value is None else float(value)

    rejected = [(str(p.get("global")), str(p.get("local"))) for p in raw.get("rejected") or []
                if isinstance(p, dict)]  # fmt: skip
    features = raw.get("features")
    outside = raw.get("outside_prior")
    return Hypothesis(
        rank=int(number("rank") or index + 1), score=number("score") or 0.0, pairs=pairs,
        pose=pose, fitness=number("fitness"), rmse=number("rmse"), residual=number("residual"),
        method=str(raw.get("method") or ""), confidence=number("confidence"),
        evidence=number("evidence"), rejected=rejected,
        features=dict(features) if isinstance(features, dict) else None,
        outside_prior=outside if isinstance(outside, bool) else None,
        missing=_count(number("missing")), expected=_count(number("expected")),
        refined=raw.get("refined") is not False,
    )  # fmt: skip


def _count(value: float | None) -> int | None:
    return None if value is None else int(value)


def saved_pose(value: object, what: str = "pose") -> np.ndarray:
    """A 4x4 pose of a saved document, its translation within the maps' coordinate limit;
    `ValueError` naming `what` and the problem."""
    pose = as_pose(value, what)
    if np.abs(pose[:3, 3]).max() > MAX_COORDINATE:
        raise ValueError(f"{what} has a translation beyond ±{MAX_COORDINATE:g} m (the input limit)")
    return pose


def _moved(changes: object) -> tuple[tuple[str, str], ...]:
    """The (global id, local id) pairs of a result's `changes.moved` (none without changes)."""
    if changes is None:
        return ()
    if not isinstance(changes, dict):
        raise ValueError(f"'changes' must be an object, got {_brief(changes)}")
    moved = []
    for j, entry in enumerate(_list_field(changes.get("moved"), "changes.moved")):
        ids = (entry.get("global"), entry.get("local")) if isinstance(entry, dict) else (None,)
        if len(ids) != 2 or not all(
            isinstance(i, (str, int)) and not isinstance(i, bool) for i in ids
        ):
            raise ValueError(f"'changes.moved[{j}]' must be {MOVED_SHAPE}, got {_brief(entry)}")
        moved.append((str(ids[0]), str(ids[1])))
    return tuple(moved)


def _hypothesis(value: object, index: int) -> tuple[np.ndarray | None, list[tuple[str, str]]]:
    where = f"hypotheses[{index}]"
    if not isinstance(value, dict):
        raise ValueError(f"'{where}' must be an object, got {_brief(value)}")
    raw = value.get("pose")
    pose = None if raw is None else saved_pose(raw, f"{where}.pose")
    pairs = []
    for j, pair in enumerate(_list_field(value.get("pairs"), f"{where}.pairs")):
        ids = (pair.get("global"), pair.get("local")) if isinstance(pair, dict) else (None, None)
        if not all(isinstance(i, (str, int)) and not isinstance(i, bool) for i in ids):
            raise ValueError(f"'{where}.pairs[{j}]' must be {PAIR_SHAPE}, got {_brief(pair)}")
        pairs.append((str(ids[0]), str(ids[1])))
    return pose, pairs


PAIR_SHAPE = '{"global": ID, "local": ID}'
MOVED_SHAPE = '{"global": ID, "local": ID, "offset_m": NUMBER}'


def _list_field(value: object, where: str) -> list:
    """`value` if a list (None: empty), else one line naming the field."""
    if value is None:
        return []
    if not isinstance(value, list):
        raise ValueError(f"'{where}' must be a list, got {_brief(value)}")
    return value


def _brief(value: object) -> str:
    return reprlib.repr(value)[:60]
