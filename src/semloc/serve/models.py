"""The shapes of the HTTP API of `semloc serve`: one pydantic model per request body and answer.

These models are what `/openapi.json` declares, so that tools can test the service and
generate clients from it.  Request bodies are checked against them strictly (JSON types as
they are: no string for a number, no boolean for an integer) after semloc's own JSON reader
has refused NaN, duplicate keys and oversized input; a map's deeper rules (unique ids, proper
rotations, non-zero directions) are `semloc.io.map_from_dict`'s, which a JSON Schema cannot
state and the descriptions do.  Answers allow extra keys (later versions may add some).

The shapes follow docs/format.md (a semloc map); the answers of a localization are the one
answer schema's models (`semloc.schema`: the JSON of `semloc localize --format json` and what
the service adds), declared as they are written (what is always there is required).
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, model_validator

from semloc import schema
from semloc.coverage import Coverage
from semloc.maps import (
    MAX_COORDINATE,
    MAX_DESCRIPTOR_LENGTH,
    MAX_EMBEDDING_LENGTH,
    MAX_ID_LENGTH,
    MAX_LABEL_LENGTH,
    MAX_OBJECTS,
    MAX_SEEN,
)

SAFE_INTEGER = 2**53 - 1
"""Integers in requests stay within what every JSON reader holds exactly (I-JSON, RFC 7493)."""
ID_PATTERN = r"^[^\x00-\x1f\x7f-\x9f/]+$"
"""A map id: 1 to 200 characters, no control character and no '/'."""
TEXT_PATTERN = (
    r"[^\t\n\x0b\x0c\r\x1c-\x1f \x85\xa0\u1680\u2000-\u200a\u2028\u2029\u202f\u205f\u3000]"
)
"""A label holds at least one character that is not white space (Python's `str.strip`)."""


def _integral(value: Any) -> Any:
    """JSON Schema counts 3.0 as an integer: so does the service."""
    return int(value) if isinstance(value, float) and value.is_integer() else value


def Integer(low: int, high: int) -> Any:  # noqa: N802 (a type)
    """An integer from `low` to `high` (bounds before the conversion, or the schema loses
    them)."""
    return Annotated[int, Field(ge=low, le=high), BeforeValidator(_integral)]


Coordinate, Vector3 = schema.Coordinate, schema.Vector3
Direction = Annotated[
    list[Coordinate],
    Field(min_length=3, max_length=3, description="A direction (3 numbers, not all zero)."),
]
Unit = Annotated[float, Field(ge=-2.0, le=2.0)]
Pose = schema.Matrix4
MapId = Annotated[str, Field(min_length=1, max_length=MAX_ID_LENGTH, pattern=ID_PATTERN)]


class _Request(BaseModel):
    """A request body: JSON types as they are; unknown keys kept (and ignored)."""

    model_config = ConfigDict(strict=True, extra="allow")


class _Answer(BaseModel):
    """An answer: later versions may add keys."""

    model_config = ConfigDict(extra="allow")


# Maps ---------------------------------------------------------------------------------------
class MapObject(_Request):
    """One object of a semloc map (docs/format.md)."""

    id: Annotated[str, Field(min_length=1, max_length=MAX_ID_LENGTH)] | Integer(
        -SAFE_INTEGER, SAFE_INTEGER
    ) = Field(description="Unique within its map; an integer is taken as its decimal string.")
    label: str = Field(
        min_length=1, max_length=MAX_LABEL_LENGTH, pattern=TEXT_PATTERN, description="Its class."
    )
    position: Vector3 = Field(description="The object's centre (m).")
    size: (
        Annotated[
            list[Annotated[float, Field(ge=0, le=MAX_COORDINATE)]],
            Field(min_length=3, max_length=3),
        ]
        | None
    ) = Field(  # fmt: skip
        None, description="Extents of its box (m)."
    )
    rotation: (
        Annotated[
            list[Annotated[list[Unit], Field(min_length=3, max_length=3)]],
            Field(min_length=3, max_length=3),
        ]
        | None
    ) = Field(  # fmt: skip
        None, description="Orientation of its box: a proper rotation matrix, row-major."
    )
    points: list[Annotated[list[Coordinate], Field(min_length=3, max_length=3)]] | None = Field(
        None, description="Its points (m), inline."
    )
    descriptor: Annotated[list[float], Field(min_length=1, max_length=MAX_DESCRIPTOR_LENGTH)] | None = None  # fmt: skip
    embedding: (
        Annotated[list[float], Field(min_length=1, max_length=MAX_EMBEDDING_LENGTH)] | None
    ) = Field(  # fmt: skip
        None, description="A semantic feature vector (not all zero; one length per map)."
    )
    seen: Integer(0, MAX_SEEN) = Field(0, description="Keyframe of its first detection.")
    score: float | None = Field(None, description="Detection confidence.")


class SemlocMap(_Request):
    """A semloc map (docs/format.md); points travel inline (no `points_file`)."""

    format: Literal["semloc-map"]
    version: Annotated[Literal[1], BeforeValidator(_integral)]
    name: str = ""
    up: Direction | None = Field(None, description="Gravity-up in this map's frame.")
    objects: list[MapObject] = Field(
        max_length=MAX_OBJECTS, description="Ids unique within the map."
    )


class PriorBody(schema.Prior):
    """A position prior (`semloc.Prior`, as `Prior.to_dict` writes it), as a request takes it:
    JSON types as they are."""

    model_config = ConfigDict(strict=True, extra="forbid")


class CoverageBody(_Request):
    """What the sensor covered at this update (`semloc.Coverage`): its pose in the device's
    frame (+z is the viewing axis, as a camera), its range and field of view; the update's
    objects are every detection of that look."""

    model_config = ConfigDict(strict=True, extra="forbid")
    pose: Pose = Field(description="T_odom_sensor: a rigid transform, 4 rows of 4.")
    range_m: float = Field(gt=0, le=MAX_COORDINATE, description="How far the sensor sees (m).")
    fov_deg: (
        Annotated[list[Annotated[float, Field(gt=0, le=360)]], Field(min_length=2, max_length=2)]
        | None
    ) = Field(None, description="[horizontal, vertical] degrees; null: all around within range_m.")

    @model_validator(mode="after")
    def _a_coverage(self) -> CoverageBody:
        Coverage.from_dict(self.model_dump())  # its rules, in one place
        return self


class LocalizeRequest(SemlocMap):
    """The local map (a semloc map, replayed by `seen`) and, optionally, a position prior."""

    prior: PriorBody | None = Field(None, description="A position prior (none when absent).")


class MapVersion(_Answer):
    map_id: str
    version: int = Field(ge=1)


class VersionInfo(_Answer):
    version: int = Field(ge=1)
    created: str = Field(description="ISO 8601, UTC.")
    source: str = Field(description='"upload" or "changes (from version N)".')


# Answers of a localization: the one answer schema (semloc.schema) -------------------------
Pair, Hypothesis, Step, Moved, Changes = (schema.Pair, schema.Hypothesis, schema.Step,
                                          schema.Moved, schema.Changes)  # fmt: skip
LabelMatch, Support, NextLook, Answer = (schema.LabelMatch, schema.Support, schema.NextLook,
                                         schema.ServiceAnswer)  # fmt: skip
LocalizeAnswer, SessionAnswer = schema.LocalizeAnswer, schema.SessionAnswer


# Sessions -----------------------------------------------------------------------------------
class SessionCreate(_Request):
    """Optional: the device frame's up (without it, no gravity prior) and a position prior."""

    model_config = ConfigDict(strict=True, extra="forbid")
    up: Direction | None = None
    prior: PriorBody | None = Field(
        None,
        description="The session's position prior from its first update on (until an update "
        "changes it; absent or null: none).",
    )


class SessionCreated(_Answer):
    session_id: str = Field(description="A capability: only its owner may use it.")


class SessionUpdate(_Request):
    objects: list[MapObject] = Field(
        max_length=MAX_OBJECTS,
        description="New or re-detected objects (an id sent again replaces its object); "
        "ids unique within the update.",
    )
    stamp: float = Field(0.0, description="The device's time of the observation, echoed.")
    position: Vector3 | None = Field(
        None,
        description="The device in its own frame (metres); it measures the travel that bounds "
        "the session's window of objects.",
    )
    prior: PriorBody | None = Field(
        None,
        description="Sets the session's position prior from this update on (absent: the prior "
        "stays as it was; null: the session has no prior from now on).",
    )
    coverage: CoverageBody | None = Field(
        None,
        description="What the sensor covered at this update (absent or null: no negative "
        "evidence from it).",
    )


class BestPairs(_Answer):
    """The best hypothesis of an answer, by its pairs."""

    pairs: list[schema.Pair]


class LastAnswer(_Answer):
    """What a session's latest answer said, in short."""

    status: schema.Status
    pose: Pose | None
    map_version: int
    hypotheses: list[BestPairs] = Field(description="The best hypothesis (none: no hypothesis).")
    confidence: float | None = None
    stamp: float | None = None
    update: int | None = None
    run_changes: schema.Changes | None = Field(
        None, description="While the session tracks its place: the run's change report."
    )


class SessionInfo(_Answer):
    session_id: str | None = Field(description="Only for the caller's own sessions.")
    mine: bool
    map_version: int
    up: list[float] | None
    idle_s: float
    last: LastAnswer | None = Field(description="Its latest answer, in short (none yet: null).")


# Change reports -----------------------------------------------------------------------------
class ReportedPair(_Request):
    global_: str | Integer(-SAFE_INTEGER, SAFE_INTEGER) = Field(alias="global")
    local: str | Integer(-SAFE_INTEGER, SAFE_INTEGER)


class ReportedHypothesis(_Request):
    pairs: list[ReportedPair] = []


def _report_rules(schema: dict[str, Any]) -> None:
    """What a change report needs besides its fields' shapes: the local objects (one of
    `local`, `localization_id`, `session_id`) and a localized answer (or `accept_ambiguous`)."""
    for name in ("local", "localization_id", "session_id"):
        schema["properties"][name].pop("default", None)  # absent, never null
    schema["allOf"] = [
        {"anyOf": [{"required": [name]} for name in ("local", "localization_id", "session_id")]},
        {"anyOf": [{"properties": {"status": {"const": "localized"}}},
                   {"properties": {"accept_ambiguous": {"const": True}},
                    "required": ["accept_ambiguous"]}]},
    ]  # fmt: skip


class ChangeReport(_Request):
    """An answer of this map as it came (its `localization_id` or `session_id` names the local
    objects the server kept), or with `local`; only a `localized` answer is applied unless
    `accept_ambiguous`."""

    model_config = ConfigDict(strict=True, extra="allow", json_schema_extra=_report_rules)

    status: Literal["localized", "ambiguous", "failed"]
    map_version: Integer(1, SAFE_INTEGER) = Field(description="The version the answer used.")
    pose: Pose = Field(description="A rigid transform (proper rotation, last row 0 0 0 1).")
    hypotheses: list[ReportedHypothesis] = []
    local: SemlocMap = Field(None, description="The local objects (a semloc map).")  # type: ignore[assignment]
    localization_id: str = Field(None, description="Of a one-shot localization's answer.")  # type: ignore[assignment]
    session_id: str = Field(None, description="Of a session's latest answer.")  # type: ignore[assignment]
    accept_ambiguous: bool = False

    @model_validator(mode="after")
    def _needs_local_objects_and_a_localized_answer(self) -> ChangeReport:
        given = self.model_fields_set
        if not given & {"local", "localization_id", "session_id"}:
            raise ValueError(
                "the local objects are needed: 'local' (a semloc map), or the answer's "
                "'localization_id' or 'session_id'"
            )
        if self.status != "localized" and not self.accept_ambiguous:
            raise ValueError(
                f"status {self.status!r}: only a localized answer's changes are applied (or "
                "set accept_ambiguous)"
            )
        return self


class ChangeResult(_Answer):
    version: int = Field(description="The map's version after the report.")
    changed: bool = Field(description="Whether the report wrote that version.")


# Service ------------------------------------------------------------------------------------
class Health(_Answer):
    status: Literal["ok"]
    version: str
    store: str
    tokens: bool


class Ready(_Answer):
    status: Literal["ready"]


class Error(BaseModel):
    """Every refusal: a short `error` and a `detail` (text, or a list of problems)."""

    error: str
    detail: Any = None


REQUESTS: tuple[type[BaseModel], ...] = (
    SemlocMap, LocalizeRequest, SessionCreate, SessionUpdate, ChangeReport
)  # fmt: skip
"""The request bodies the routes read themselves (declared as OpenAPI components)."""


def checked(model: type[BaseModel], document: Any) -> Any:
    """`document` checked against `model` (pydantic's ValidationError if not), as the service
    takes it: integers as integers (JSON Schema's 3.0 is the integer 3)."""
    _integers(document, model.model_validate(document))
    return document


def _integers(document: dict[str, Any], instance: BaseModel) -> None:
    """Write the integer fields of a checked document back as the model read them (in place:
    a few fields, where dumping the model would copy every point)."""
    if isinstance(instance, SemlocMap):
        document["version"] = instance.version
    if isinstance(instance, (SemlocMap, SessionUpdate)):
        for raw, obj in zip(document["objects"], instance.objects):
            raw["id"] = obj.id
            if "seen" in raw:
                raw["seen"] = obj.seen
    if isinstance(instance, ChangeReport):
        document["map_version"] = instance.map_version
        if instance.local is not None:
            _integers(document["local"], instance.local)
        for raw, hypothesis in zip(document.get("hypotheses", []), instance.hypotheses):
            for raw_pair, pair in zip(raw.get("pairs", []), hypothesis.pairs):
                raw_pair["global"], raw_pair["local"] = pair.global_, pair.local
