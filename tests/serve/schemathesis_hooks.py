"""What JSON Schema cannot say about semloc's requests, for the requests schemathesis generates
(`SCHEMATHESIS_HOOKS=schemathesis_hooks`, used by test_openapi.py).

`/openapi.json` states every shape and bound a JSON Schema can; a few rules of a semloc map
are beyond it: object ids unique within a map, a box rotation that is a proper rotation, `up`
and an `embedding` that are not zero vectors and embeddings of one length per map, a change
report's pose and a session update's coverage pose that are rigid transforms, a position prior's floor band in order and its
heading tolerance with a heading; and two of the service's own: an Idempotency-Key
names one request (a key reused with another body is refused), and If-Match names the
current version (which the schema cannot know).  The hook makes generated requests obey
those rules, so that a request that satisfies the schema is one the service must accept.

Each change touches only a part that already satisfies its schema and leaves it satisfying
it, so a request generated to break the schema still breaks it (negative tests stay
negative).
"""

from __future__ import annotations

import math
import uuid
from typing import Any

import schemathesis

IDENTITY3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
IDENTITY4 = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]


@schemathesis.hook
def before_call(context: Any, case: Any, kwargs: dict[str, Any]) -> None:
    """Every phase's requests (coverage, fuzzing, stateful) just before they are sent;
    schemathesis checks afterwards which of them still break the schema."""
    if isinstance(case.body, dict):
        _fix_body(case.body)
    if case.headers:
        _fix_headers(case.headers)


def _fix_body(body: dict[str, Any]) -> None:
    _fix_map_like(body)
    if _matrix(body.get("pose"), 4, math.inf):
        body["pose"] = [row[:] for row in IDENTITY4]
    if isinstance(body.get("local"), dict):
        _fix_map_like(body["local"])


def _fix_headers(headers: dict[str, Any]) -> None:
    key = headers.get("Idempotency-Key")
    if isinstance(key, str) and 0 < len(key) <= 200 and all("!" <= c <= "~" for c in key):
        headers["Idempotency-Key"] = uuid.uuid4().hex  # one key, one request
    match = headers.get("If-Match")
    if isinstance(match, str) and len(match) <= 200:
        del headers["If-Match"]  # the current version is the server's to know


def _fix_map_like(document: dict[str, Any]) -> None:
    """A map, a session's create body or a session update."""
    if _vector(document.get("up"), 3, 1e6) and max(map(abs, document["up"])) < 1e-6:
        document["up"] = [0.0, 0.0, 1.0]
    document.pop("points_file", None)  # an unknown key to the schema: a file on the server
    objects = document.get("objects")
    if isinstance(objects, list):
        _fix_objects(objects)
    if isinstance(document.get("prior"), dict):
        _fix_prior(document["prior"])
    coverage = document.get("coverage")
    if isinstance(coverage, dict) and _matrix(coverage.get("pose"), 4, math.inf):
        coverage["pose"] = [row[:] for row in IDENTITY4]


def _fix_prior(prior: dict[str, Any]) -> None:
    """A position prior: floor [z_min, z_max] in order; a heading tolerance with a heading."""
    floor = prior.get("floor")
    if _vector(floor, 2, math.inf):
        prior["floor"] = sorted(floor)
    tolerance = prior.get("heading_tolerance")
    if _number(tolerance, math.inf) and prior.get("heading") is None:
        prior["heading"] = 0.0


def _fix_objects(objects: list[Any]) -> None:
    taken: set[str] = set()
    length = None  # of the first embedding
    for number, obj in enumerate(objects):
        if not isinstance(obj, dict):
            continue
        if _matrix(obj.get("rotation"), 3, 2.0):
            obj["rotation"] = [row[:] for row in IDENTITY3]
        embedding = obj.get("embedding")
        if _vector(embedding, None, math.inf) and 0 < len(embedding) <= 8192:
            length = length or len(embedding)
            if len(embedding) != length or max(map(abs, embedding)) < 1e-30:
                obj["embedding"] = [1.0] + [0.0] * (length - 1)
        _unique_id(obj, taken, number)


def _unique_id(obj: dict[str, Any], taken: set[str], number: int) -> None:
    value = obj.get("id")
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    if isinstance(value, str) and 0 < len(value) <= 200:
        name = value
        while name in taken:
            name = f"{value[:180]}~{number}~{len(taken)}"
        obj["id"] = name
    elif isinstance(value, int) and not isinstance(value, bool) and abs(value) < 2**62:
        while str(value) in taken:
            value = value + 1 if value < 2**62 - 1 else -(2**62)
        obj["id"] = value
    else:
        return
    taken.add(str(obj["id"]))


def _number(value: Any, bound: float) -> bool:
    return (isinstance(value, (int, float)) and not isinstance(value, bool)
            and abs(value) <= bound)  # fmt: skip


def _vector(value: Any, length: int | None, bound: float) -> bool:
    return (isinstance(value, list) and (length is None or len(value) == length)
            and all(_number(v, bound) for v in value))  # fmt: skip


def _matrix(value: Any, size: int, bound: float) -> bool:
    return (isinstance(value, list) and len(value) == size
            and all(_vector(row, size, bound) for row in value))  # fmt: skip
