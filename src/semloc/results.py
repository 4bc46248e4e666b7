"""What a localization returns: `Result` (status, pose, ranked `Hypothesis` list, `Step` records).

Shared by the Localizer and every baseline, so that callers, the CLI, the evaluation and the
JSON output see one model.  `Status` is the decision's vocabulary (see `decision.py`).  Their
JSON is `semloc.schema`'s: written by `Result.to_dict` / `to_json`, read back by
`Result.from_dict` and `saved_result` (the CLI's `view`, `export` and `update-map --result`),
every field checked by the schema; no file access here.
"""

from __future__ import annotations

import json
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any, ClassVar, TypeVar

import numpy as np
from pydantic import ValidationError

from semloc import schema
from semloc.association import LabelResolution
from semloc.changes import Changes
from semloc.maps import MAX_COORDINATE
from semloc.priors import Prior
from semloc.transforms import as_pose

Status = schema.Status


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
    n_missing: int | None = None  # map objects its pose puts in the recent looks that no
    # detection accounts for (None: no coverage given)
    n_expected: int | None = None  # map objects its pose puts in the recent looks
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

    def to_model(self) -> schema.Hypothesis:
        return schema.Hypothesis(
            rank=self.rank, score=self.score, pairs=_pairs_model(self.pairs), pose=self.pose,
            fitness=self.fitness, rmse=self.rmse, residual=self.residual, method=self.method,
            confidence=self.confidence, evidence=self.evidence, features=self.features,
            rejected=_pairs_model(self.rejected), outside_prior=self.outside_prior,
            n_missing=self.n_missing, n_expected=self.n_expected,
            refined=None if self.refined else False,
        )  # fmt: skip

    @classmethod
    def of_model(cls, m: schema.Hypothesis) -> Hypothesis:
        return cls(
            m.rank, m.score, _pairs_of(m.pairs), _pose_of(m.pose), m.fitness, m.rmse,
            m.residual, m.method, m.confidence, m.evidence, m.features, _pairs_of(m.rejected),
            m.outside_prior, m.n_missing, m.n_expected, m.refined is not False,
        )  # fmt: skip

    def to_dict(self) -> dict[str, Any]:
        return self.to_model().model_dump(by_alias=True)


def _pairs_model(pairs: list[tuple[str, str]]) -> list[schema.Pair]:
    return [schema.Pair(global_=g, local=l) for g, l in pairs]


def _pairs_of(pairs: list[schema.Pair]) -> list[tuple[str, str]]:
    return [(p.global_, p.local) for p in pairs]


def _pose_of(rows: list[list[float]] | None) -> np.ndarray | None:
    return None if rows is None else np.array(rows, dtype=float)


@dataclass
class Step:
    """What one update did: local objects so far, sets in the pool, top scores, time.

    `status` is None for an update that only grew the association sets (`Localizer.add`); its
    `top_scores` are then those of the best association sets rather than of the hypotheses.
    """

    step: int
    n_local: int
    n_sets: int
    top_scores: list[float]
    ms: float
    status: Status | None = "failed"

    def to_model(self) -> schema.Step:
        return schema.Step(step=self.step, n_local=self.n_local, n_sets=self.n_sets,
                           top_scores=list(self.top_scores), ms=self.ms, status=self.status)  # fmt: skip

    @classmethod
    def of_model(cls, m: schema.Step) -> Step:
        return cls(m.step, m.n_local, m.n_sets, list(m.top_scores), m.ms, m.status)

    def to_dict(self) -> dict[str, Any]:
        return self.to_model().model_dump()


class UpdateLog:
    """The latest updates' `Step`s (at most `kept`) and the run's summed time per stage
    (ms), as answers carry them."""

    STAGES: ClassVar[tuple[str, ...]] = ("association", "clustering", "pose")

    def __init__(self, kept: int) -> None:
        self.steps: deque[Step] = deque(maxlen=kept)
        self.n_steps = 0
        self.timing = dict.fromkeys((*self.STAGES, "total"), 0.0)

    def add(self, scores: list[float], seconds: float, status: Status | None, n_local: int,
            n_sets: int) -> None:  # fmt: skip
        """One update's step: its answer's (or best sets') scores, time, status, sizes."""
        self.steps.append(Step(self.n_steps, n_local, n_sets, sorted(scores, reverse=True),
                               seconds * 1e3, status))  # fmt: skip
        self.n_steps += 1

    def spent(self, association: float, clustering: float, pose: float) -> None:
        """Seconds one update spent per stage."""
        for key, seconds in zip(self.STAGES, (association, clustering, pose)):
            self.timing[key] += seconds * 1e3
        self.timing["total"] += (association + clustering + pose) * 1e3

    def state(self) -> dict[str, Any]:
        return {"steps": [s.to_dict() for s in self.steps], "n_steps": self.n_steps,
                "timing": dict(self.timing)}  # fmt: skip

    def restore(self, state: dict[str, Any]) -> None:
        self.steps.extend(Step(**s) for s in state["steps"])
        self.n_steps = int(state["n_steps"])
        self.timing.update({k: float(v) for k, v in state["timing"].items()})


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

    def to_model(self) -> schema.NextLook:
        return schema.NextLook(
            label=self.label, global_id=self.global_id,
            where={str(rank): p for rank, p in self.where.items()},
            separates=[int(r) for r in self.separates], gain=self.gain,
        )  # fmt: skip

    @classmethod
    def of_model(cls, m: schema.NextLook) -> Look:
        where = {int(rank): np.array(p, dtype=float) for rank, p in m.where.items()}
        return cls(m.label, m.global_id, where, list(m.separates), m.gain)

    def to_dict(self) -> dict[str, Any]:
        return self.to_model().model_dump()


@dataclass(frozen=True)
class Support:
    """How recent the evidence of an answer's pose is: its local objects' pairs (`n_pairs`),
    the span of their `seen` keyframes, how many updates and metres of odometry ago the oldest
    of them was last detected (metres: 0 without robot positions), and whether the place is
    tracked."""

    n_pairs: int
    seen: tuple[int, int]
    updates_ago: int
    metres: float
    tracked: bool = False
    n_changed: int = 0
    """Objects judged since a tracked claim began that a plausible move explains (0 unless
    tracked)."""
    n_contradicting: int = 0
    """Objects judged since a tracked claim began that contradict it (0 unless tracked)."""
    n_missing: int | None = None
    """Map objects the pose puts in the recent looks that no detection accounts for (None: no
    coverage given, so no negative evidence)."""
    n_expected: int | None = None
    """Map objects the pose puts in the recent looks (None: no coverage given)."""
    missing_ids: tuple[str, ...] | None = None
    """The ids of the map objects counted in `n_missing`, as the answer's pose places the
    looks (at most `MISSING_IDS_KEPT`, in the map's order; None: no coverage given)."""

    MISSING_IDS_KEPT: ClassVar[int] = 50
    """The most ids an answer lists (a look that misses more says so by `n_missing` alone)."""

    def to_model(self) -> schema.Support:
        return schema.Support(
            n_pairs=self.n_pairs, seen=[int(k) for k in self.seen],
            updates_ago=int(self.updates_ago), metres=self.metres, tracked=self.tracked,
            n_changed=self.n_changed, n_contradicting=self.n_contradicting,
            n_missing=self.n_missing, n_expected=self.n_expected,
            missing_ids=None if self.missing_ids is None else list(self.missing_ids),
        )  # fmt: skip

    @classmethod
    def of_model(cls, m: schema.Support) -> Support:
        ids = None if m.missing_ids is None else tuple(m.missing_ids)
        return cls(m.n_pairs, (m.seen[0], m.seen[1]), m.updates_ago, m.metres, m.tracked,
                   m.n_changed, m.n_contradicting, m.n_missing, m.n_expected, ids)  # fmt: skip

    def to_dict(self) -> dict[str, Any]:
        return self.to_model().model_dump()


AnswerModel = TypeVar("AnswerModel", bound=schema.Answer)


@dataclass
class Result:
    """The answer after an update: status, best pose, ranked hypotheses and per-step records.

    `reason` says why an answer is `ambiguous` or `failed` (empty when `localized`); the pose
    of an `ambiguous` result is the best candidate's, not a trusted answer: `pose_is_answer`
    says which (the JSON carries it too).  Its JSON is `semloc.schema.Answer` (`to_dict`,
    `to_json`, `from_dict`)."""

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
    read_labels: Callable[[], dict[str, LabelResolution]] | None = field(
        default=None, repr=False, compare=False
    )
    """Computes `labels` on first use."""
    prior: Prior | None = None
    """The position prior the answer was made under (None: none)."""

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

    @cached_property
    def labels(self) -> dict[str, LabelResolution]:
        """How each label of the local objects was read against the map's labels (sorted by
        label; empty when nobody said)."""
        return {} if self.read_labels is None else self.read_labels()

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

    def to_model(
        self,
        model: type[AnswerModel] = schema.Answer,  # type: ignore[assignment]
        last_steps: int | None = None,
        **fields: Any,
    ) -> AnswerModel:
        """The answer as `model` (`schema.Answer` or a writer's kind of it, whose own fields
        are `fields`); `last_steps`: only that many of the latest steps (a stream writes each
        update's step on its own line).  A ValidationError (a ValueError) for a non-finite
        number."""
        unknown = set(fields) - set(model.model_fields)
        if unknown:
            raise TypeError(f"{model.__name__} has no field {', '.join(sorted(unknown))}")
        steps = (
            self.steps if last_steps is None else self.steps[max(0, len(self.steps) - last_steps) :]
        )
        return model(
            status=self.status, reason=self.reason, confidence=self.confidence,
            pose_is_answer=self.pose_is_answer, pose=self.pose,
            hypotheses=[h.to_model() for h in self.hypotheses],
            steps=[s.to_model() for s in steps], timing_ms=dict(self.timing_ms),
            changes=self.changes.to_model(),
            support=None if self.support is None else self.support.to_model(),
            next_look=[look.to_model() for look in self.next_look],
            labels={label: schema.LabelMatch(resolved=found.resolved,
                                             map_labels=list(found.map_labels))
                    for label, found in self.labels.items()},
            prior=None if self.prior is None else schema.Prior.model_validate(self.prior.to_dict()),
            **fields,
        )  # fmt: skip

    def to_dict(self, model: type[schema.Answer] = schema.Answer, last_steps: int | None = None,
                **fields: Any) -> dict[str, Any]:  # fmt: skip
        """The answer's JSON document (see `to_model`)."""
        return self.to_model(model, last_steps, **fields).model_dump(by_alias=True)

    def to_json(self, model: type[schema.Answer] = schema.Answer, last_steps: int | None = None,
                **fields: Any) -> str:  # fmt: skip
        """The JSON text of `to_dict`, as every writer of a result writes it: indented, one
        newline at the end."""
        return answer_text(self.to_dict(model, last_steps, **fields))

    @classmethod
    def from_dict(cls, data: Any) -> Result:
        """A Result from its JSON document (`to_dict`, e.g. a `semloc serve` answer), the
        inverse of `to_dict` up to its rounding; `ValueError` naming a field not as written."""
        return cls.of_model(parse_answer(data))

    @classmethod
    def of_model(cls, m: schema.Answer) -> Result:
        changes = Changes.of_model(m.changes)
        looks = [Look.of_model(look) for look in m.next_look]
        labels = {label: LabelResolution(found.resolved, tuple(found.map_labels))
                  for label, found in m.labels.items()}  # fmt: skip
        return cls(
            m.status, _pose_of(m.pose), [Hypothesis.of_model(h) for h in m.hypotheses],
            [Step.of_model(s) for s in m.steps], dict(m.timing_ms), m.reason,
            explain=lambda: changes,
            support=None if m.support is None else Support.of_model(m.support),
            suggest=lambda: looks, read_labels=lambda: labels,
            prior=None if m.prior is None else m.prior.prior(),
        )  # fmt: skip


def parse_answer(data: Any, model: type[AnswerModel] = schema.Answer) -> AnswerModel:  # type: ignore[assignment]
    """An answer document parsed as `model`; `ValueError` naming the first field not as
    written."""
    if not isinstance(data, dict):
        raise ValueError("a result must be an object")
    try:
        return model.model_validate(data, context=schema.PARSING)
    except ValidationError as exc:
        raise ValueError(schema.field_error(exc)) from None


def answer_text(document: dict[str, Any]) -> str:
    """The text of an answer document: indented JSON, NaN and infinities refused
    (`ValueError`), one newline at the end."""
    return json.dumps(document, indent=1, allow_nan=False) + "\n"


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
    """A result document (`schema.Answer` as `Result.to_json` writes it; an older or a shorter
    one needs only `status`, and of each hypothesis its `pairs`), or a document of a pose
    alone (no `status`: `pose`, or a ground truth's `T_global_local`), every field checked:
    `ValueError` naming the field and what is wrong."""
    if "status" not in data:
        key = "pose" if "pose" in data else "T_global_local"
        pose = data.get(key)
        return SavedResult(None if pose is None else saved_pose(pose, key))
    answer = parse_answer(data)
    return SavedResult(
        _pose_of(answer.pose),
        answer.status,
        tuple((_pose_of(h.pose), _pairs_of(h.pairs)) for h in answer.hypotheses),
        tuple((m.global_, m.local) for m in answer.changes.moved),
    )


def saved_pose(value: object, what: str = "pose") -> np.ndarray:
    """A 4x4 pose of a saved document, its translation within the maps' coordinate limit;
    `ValueError` naming `what` and the problem."""
    pose = as_pose(value, what)
    if np.abs(pose[:3, 3]).max() > MAX_COORDINATE:
        raise ValueError(f"{what} has a translation beyond ±{MAX_COORDINATE:g} m (the input limit)")
    return pose
