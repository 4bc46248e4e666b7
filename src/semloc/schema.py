"""The answer's JSON: one pydantic model per part, the single source of its shape.

Every writer of an answer builds it through these models (`Result.to_dict`, the CLI's
`localize --format json`, the demos' and `align`'s `result.json`, the lines of `bag localize
--jsonl`, `/semloc/status`, the service's answers) and every reader parses it through them
(`Result.from_dict`); the service's OpenAPI answer models are these models.  The core's
`Result` and its parts stay dataclasses holding numpy arrays; this module holds no numpy and
knows nothing of them (`results.py` and `changes.py` convert).

Conventions, the same in every part:

- `pairs` is always a list of `{"global", "local"}` pairs; a count is named `n_...`
  (`n_pairs`, `n_missing`, ...), never like a list.
- Numbers are written rounded (poses to 9 decimals, scores and distances to 6, milliseconds
  and metres to 3): the rounding is the type's (`Rounded6`, `Pose`, ...), so parsing a
  written answer and writing it again gives the same text.
- A field in a model's `OMITTED_IF_NONE` is left out when it is None (it only applies with
  a prior, with coverage, over a run, with a ground truth...); every other field is always
  written, null when it has no value, and required in the schema of what is written (the
  OpenAPI's).  Reading is lenient where an older or a hand-written answer may lack a field (a
  default: a result file for `semloc view --result` needs only `status`, and of each
  hypothesis its `pairs`), never about a field's type.
- Answers allow keys these models do not know (a newer writer may add some); `problems`
  says what keeps a document from being exactly what semloc writes (unknown or absent keys,
  values not as written), for the tests that check each writer against this schema.
"""

from __future__ import annotations

import re
from typing import Annotated, Any, ClassVar, Literal

from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    PlainSerializer,
    SerializerFunctionWrapHandler,
    ValidationError,
    ValidationInfo,
    model_serializer,
    model_validator,
)

from semloc.maps import MAX_COORDINATE
from semloc.priors import Prior as PositionPrior
from semloc.transforms import as_pose

Status = Literal["localized", "ambiguous", "failed"]


def _rounded(digits: int) -> PlainSerializer:
    return PlainSerializer(lambda v: round(v, digits), return_type=float)


Finite = Field(allow_inf_nan=False)
Rounded3 = Annotated[float, Finite, _rounded(3)]
Rounded6 = Annotated[float, Finite, _rounded(6)]


def _as_id(value: Any) -> Any:
    """Ids are strings; an integer id (a map file's) is taken as its decimal string."""
    return str(value) if isinstance(value, int) and not isinstance(value, bool) else value


Id = Annotated[str, BeforeValidator(_as_id)]
Coordinate = Annotated[float, Field(ge=-MAX_COORDINATE, le=MAX_COORDINATE)]
Vector3 = Annotated[list[Coordinate], Field(min_length=3, max_length=3)]


def _listed(value: Any) -> Any:
    """A numpy array (the core's) as nested lists."""
    return value.tolist() if hasattr(value, "tolist") else value


def _rigid(rows: list[list[float]], info: ValidationInfo) -> list[list[float]]:
    """A pose read from a document is a rigid transform (one the core built is: not checked
    again, see `PARSING`)."""
    if not (info.context or {}).get("parsing"):
        return rows
    pose = as_pose(rows)
    if abs(pose[:3, 3]).max() > MAX_COORDINATE:
        raise ValueError(f"the translation is beyond ±{MAX_COORDINATE:g} m (the input limit)")
    return rows


Matrix4 = Annotated[
    list[Annotated[list[float], Field(min_length=4, max_length=4)]],
    Field(
        min_length=4,
        max_length=4,
        description="T_global_local, 4 rows of 4 numbers: p_global = R @ p_local + t.",
    ),
    BeforeValidator(_listed),
]
"""A 4 x 4 matrix (a request's pose: its rules are checked where it is read)."""
Pose = Annotated[
    Matrix4,
    AfterValidator(_rigid),
    PlainSerializer(lambda rows: [[round(x, 9) for x in row] for row in rows]),
]
"""An answer's pose: a rigid transform within the maps' coordinate limit, written to 9
decimals."""
Point = Annotated[
    Vector3, BeforeValidator(_listed), PlainSerializer(lambda p: [round(x, 6) for x in p])
]


PARSING = {"parsing": True}
"""The validation context of a document read (`model_validate(data, context=PARSING)`): its
poses are checked to be rigid transforms."""


class Part(BaseModel):
    """A part of an answer: unknown keys kept (see `problems`); what is always written is
    required in the schema of what is written."""

    model_config = ConfigDict(
        extra="allow",
        populate_by_name=True,
        json_schema_serialization_defaults_required=True,
        json_schema_extra=lambda schema, model: _optional_when_omitted(schema, model),
    )
    OMITTED_IF_NONE: ClassVar[frozenset[str]] = frozenset()


class Omitting(Part):
    """A part whose fields named in `OMITTED_IF_NONE` are left out when None (and are not
    required in the schema of what is written)."""

    @model_serializer(mode="wrap")
    def _omit_nones(self, handler: SerializerFunctionWrapHandler):
        data = handler(self)
        for name in self.OMITTED_IF_NONE:
            if name in data and data[name] is None:
                del data[name]
        return data


def _optional_when_omitted(schema: dict[str, Any], model: Any) -> None:
    omitted = getattr(model, "OMITTED_IF_NONE", frozenset())
    if "required" in schema:
        schema["required"] = [name for name in schema["required"] if name not in omitted]


class Pair(Part):
    """A map object and the local object it is taken to be."""

    global_: Id = Field(alias="global", description="The map object's id.")
    local: Id = Field(description="The local object's id.")


class Hypothesis(Omitting):
    """One candidate answer: an association set and the pose it implies."""

    OMITTED_IF_NONE = frozenset({"outside_prior", "n_missing", "n_expected", "refined"})
    rank: int = Field(1, ge=1, description="1 for the best (read: its place when absent).")
    score: Rounded6 = Field(0.0, description="The association set's clustering score.")
    pairs: list[Pair]
    pose: Pose | None = None
    fitness: Rounded6 | None = Field(None, description="Share of local points on the map.")
    rmse: Rounded6 | None = Field(None, description="RMS point distance after ICP (m).")
    residual: Rounded6 | None = Field(
        None, description="RMS distance (m) of aligned local centres to their partners."
    )
    method: str = Field("", description="How the pose was recovered.")
    confidence: Rounded6 | None = Field(
        None, description="Calibrated probability that the pose is right."
    )
    evidence: Rounded6 | None = Field(
        None, description="The confidence model's evidence logit (ranks hypotheses)."
    )
    features: dict[str, Rounded6] | None = Field(
        None, description="The confidence model's inputs by name (semloc.decision.FEATURES)."
    )
    rejected: list[Pair] = Field([], description="Pairs of the set that disagreed.")
    outside_prior: bool | None = Field(
        None, description="Its pose lies outside the prior (only with a prior)."
    )
    n_missing: int | None = Field(
        None,
        description="Map objects its pose puts in the recent looks that no detection accounts "
        "for (only with coverage).",
    )
    n_expected: int | None = Field(
        None, description="Map objects its pose puts in the recent looks (only with coverage)."
    )
    refined: Literal[False] | None = Field(
        None,
        description="false: its pose is the closed form's, not refined by robust ICP (it could "
        "not change the verdict; `Hypothesis.refine()` refines it on demand); absent: refined.",
    )


class Step(Part):
    """What one update did."""

    step: int
    n_local: int = Field(description="Local objects so far.")
    n_sets: int = Field(description="Association sets in the pool.")
    top_scores: list[Rounded6]
    ms: Rounded3
    status: Status | None = Field(
        None, description="Its answer's status (null: an update that only grew the sets)."
    )


class Moved(Omitting):
    """A map object seen elsewhere."""

    OMITTED_IF_NONE = frozenset({"evidence", "last_seen"})
    global_: Id = Field(alias="global")
    local: Id
    offset_m: Rounded6
    evidence: int | None = Field(None, description="Detections that saw it moved (a run).")
    last_seen: int | None = Field(None, description="The `seen` of the latest of them (a run).")


class Changes(Omitting):
    """What changed since the map was made, under the best hypothesis."""

    OMITTED_IF_NONE = frozenset({"evidence"})
    moved: list[Moved] = []
    new: list[Id] = Field([], description="Local ids.")
    missing: list[Id] = Field([], description="Global ids.")
    evidence: dict[str, dict[str, int]] | None = Field(
        None, description="Over a run: detections (new) and looks (missing) that said so, by id."
    )


class Support(Part):
    """How recent the evidence for the pose is."""

    n_pairs: int = Field(description="The best hypothesis's pairs in the window.")
    seen: Annotated[list[int], Field(min_length=2, max_length=2)] = Field(
        description="The span of `seen` of its local objects."
    )
    updates_ago: int = Field(description="Updates since its oldest object was detected.")
    metres: Rounded3 = Field(description="Metres of travel since then (0 without positions).")
    tracked: bool = Field(description="The place was found earlier and is followed since.")
    n_changed: int = Field(0, description="Objects of the tracked claim a plausible move explains.")
    n_contradicting: int = Field(0, description="Objects that contradict the tracked claim.")
    n_missing: int | None = Field(
        None,
        description="Map objects the pose puts in the recent looks that no detection accounts "
        "for (null: no coverage given, no negative evidence).",
    )
    n_expected: int | None = Field(
        None, description="Map objects the pose puts in the recent looks (null: no coverage)."
    )
    missing_ids: list[Id] | None = Field(
        None,
        description="The ids of the map objects counted in `n_missing`, as the answer's pose "
        "places the looks (at most 50, in the map's order; null: no coverage).",
    )


class NextLook(Part):
    """Where to look to tell the top hypotheses of an ambiguous answer apart."""

    label: str
    global_id: Id
    where: dict[str, Point] = Field(
        description="Rank -> [x, y, z]: where the map object lies in the local frame if that "
        "hypothesis is right."
    )
    separates: list[int] = Field(description="The ranks a look at their spot tells apart.")
    gain: Rounded6 = Field(description="Expected reduction of the ambiguity (bits).")


class LabelMatch(Part):
    """How one local label was read against the map's labels."""

    resolved: str = Field(
        description="exact, synonym, parent, child, similar, embedding or unmatched."
    )
    map_labels: list[str] = Field(description="The map labels it may be, most similar first.")


class Prior(Omitting):
    """A position prior (`semloc.Prior`): the local frame's origin lies within `radius` metres
    of `position` in the map's frame; optionally its height within `floor` and its heading
    within `heading_tolerance` degrees of `heading`."""

    model_config = ConfigDict(extra="forbid")
    OMITTED_IF_NONE = frozenset({"floor", "heading", "heading_tolerance"})
    position: Vector3 = Field(description="Where the local frame's origin lies (map frame, m).")
    radius: float = Field(gt=0, description="Metres around `position`.")
    floor: Annotated[list[Coordinate], Field(min_length=2, max_length=2)] | None = Field(
        None, description="[z_min, z_max]: the origin's height band (map frame, z up)."
    )
    heading: float | None = Field(
        None, description="Degrees: the local x axis about the map's z axis, from +x, CCW."
    )
    heading_tolerance: float | None = Field(
        None, gt=0, le=180, description="Degrees around `heading` (default 30; needs a heading)."
    )

    @model_validator(mode="after")
    def _a_prior(self) -> Prior:
        self.prior()  # its rules, in one place
        return self

    def prior(self) -> PositionPrior:
        return PositionPrior.from_dict(self.model_dump(exclude_none=True))


class GroundTruth(Part):
    """The answer against a known pose (`semloc localize --gt`)."""

    rotation_deg: float | None = Field(description="Rotation error (null: no pose).")
    translation_m: float | None = Field(description="Translation error (null: no pose).")
    success: bool = Field(description="Within 15° and 0.5 m.")
    rank_of_first_correct: int | None = Field(
        description="The first hypothesis within them (null: none)."
    )


class Answer(Omitting):
    """A localization answer: the JSON of `semloc localize --format json` (`Result.to_dict`)."""

    OMITTED_IF_NONE = frozenset({"ground_truth", "warm_up_ms"})
    status: Status
    reason: str = Field("", description="Why it is ambiguous or failed (empty: localized).")
    confidence: Rounded6 | None = Field(
        None, description="The best hypothesis's calibrated probability of being right."
    )
    pose_is_answer: bool = Field(
        False, description="Whether `pose` is a trusted answer (localized), not a best guess."
    )
    pose: Pose | None = Field(None, description="The best hypothesis's pose (null: failed).")
    hypotheses: list[Hypothesis] = Field([], description="Ranked, best first.")
    steps: list[Step] = Field([], description="The latest updates.")
    timing_ms: dict[str, Rounded3] = {}
    changes: Changes = Field(default_factory=Changes)
    support: Support | None = Field(None, description="Null without a pose.")
    next_look: list[NextLook] = Field(
        [], description="Where to look next, best first (only an ambiguous answer)."
    )
    labels: dict[str, LabelMatch] = Field(
        {}, description="How each local label was read against the map's labels."
    )
    prior: Prior | None = Field(None, description="The position prior applied (null: none).")
    ground_truth: GroundTruth | None = Field(None, description="Only with a ground truth.")
    warm_up_ms: Rounded3 | None = Field(
        None, description="Start-up time before the first update (the CLI's)."
    )

    @model_validator(mode="after")
    def _ranked(self) -> Answer:
        for place, hypothesis in enumerate(self.hypotheses, start=1):
            if "rank" not in hypothesis.model_fields_set:  # (a shorter document)
                hypothesis.rank = place
        return self


class ServiceAnswer(Answer):
    """An answer of `semloc serve`: the answer with the map version it used."""

    map_version: int = Field(ge=1)


class LocalizeAnswer(ServiceAnswer):
    """The answer to a one-shot localization."""

    localization_id: str = Field(description="Names the local objects kept for a change report.")


class SessionAnswer(ServiceAnswer):
    """The answer after a session's update."""

    session_id: str
    update: int = Field(ge=1, description="This update's number in the session.")
    stamp: float = Field(description="The update's stamp, echoed.")


class StatusAnswer(Answer):
    """`/semloc/status` (a ROS 2 node, `semloc bag localize`): the answer at a stamp."""

    stamp: float = Field(description="The detections' stamp (s).")
    n_local: int = Field(description="Local objects so far.")


class BagLine(Part):
    """A line of `semloc bag localize --jsonl`."""

    stamp: float = Field(description="The detections' stamp (s).")
    result: Answer = Field(description="The answer (its steps: this update's only).")


def problems(document: Any, model: type[Part] = Answer) -> list[str]:
    """What keeps `document` from being a `model` exactly as semloc writes it (empty: none):
    a field not as the model says, a key no model declares, a field the writer must write
    and did not, or a value not written as the schema writes it (e.g. not rounded)."""
    try:
        parsed = model.model_validate(document, context=PARSING)
    except ValidationError as exc:
        return [field_error(exc)]
    found = _strays(parsed, "")
    if not found and parsed.model_dump(by_alias=True) != document:
        found.append("not written as the schema writes it")
    return found


def _strays(model: BaseModel, where: str) -> list[str]:
    """The unknown keys and the absent fields of a parsed part and its parts, by path."""
    found = [f"unknown key '{where}{key}'" for key in model.model_extra or {}]
    omitted = getattr(model, "OMITTED_IF_NONE", frozenset())
    for name, info in type(model).model_fields.items():
        key = info.alias or name
        if name not in model.model_fields_set and name not in omitted:
            found.append(f"missing key '{where}{key}'")
        found += _strays_in(getattr(model, name), f"{where}{key}")
    return found


def _strays_in(value: Any, where: str) -> list[str]:
    if isinstance(value, BaseModel):
        return _strays(value, f"{where}.")
    if isinstance(value, list):
        return [k for i, item in enumerate(value) for k in _strays_in(item, f"{where}[{i}]")]
    if isinstance(value, dict):
        return [k for key, item in value.items() for k in _strays_in(item, f"{where}.{key}")]
    return []


def field_error(exc: Exception, where: str = "") -> str:
    """A pydantic ValidationError as one line naming the first field not as the schema says
    ("'hypotheses[1].pairs' must be a valid list"); `where`: the path of what was validated."""
    errors = getattr(exc, "errors", None)
    if errors is None:
        return str(exc)
    first = errors()[0]
    for part in first["loc"]:
        where += f"[{part}]" if isinstance(part, int) else f"{'.' if where else ''}{part}"
    message = re.sub(r"a valid dictionary or instance of \w+", "an object", first["msg"])
    message = message.removeprefix("Value error, ").replace("Input should be", "must be", 1)
    message = "is required" if message == "Field required" else message
    if not where:
        return message
    joined = message.startswith(("must be", "is required"))
    return f"'{where}' {message}" if joined else f"'{where}': {message}"
