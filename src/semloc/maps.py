"""Object-level maps: `SemanticObject` (one object) and `ObjectMap` (a frame's set of objects).

An `ObjectMap` is an immutable sequence of objects plus frame metadata (`up`, `name`) and the
unknown top-level keys of the file it came from.  Column views (`ids`, `labels`, `positions`,
`sizes`, `rotations`, `seen`) are numpy arrays computed once, and so is the order of sweeps over
the positions (`sweep_order`).  Construction validates every object and raises `MapError`
naming the object and the problem, so API users get the same guarantees as file readers.  This
module does no I/O.

Points may be any N x 3 array-like or anything with a `.points` attribute convertible to one
(an `open3d.geometry.PointCloud`, duck-typed: open3d is not imported here).  The one use of an
optional library is `ObjectMap.to_open3d`, which imports open3d when called.
"""

from __future__ import annotations

import math
import reprlib
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Any

import numpy as np

from semloc.digests import EncodedIds, encode_ids
from semloc.pointsets import SweepOrder


class MapError(ValueError):
    """A map (file or in-memory) is invalid; the message names the source, object and problem."""


MAX_OBJECTS = 100_000
"""Most objects in one map."""
MAX_POINTS_PER_OBJECT = 1_000_000
"""Most points of one object."""
MAX_POINTS_PER_MAP = 10_000_000
"""Most points of all objects of one map together."""
MAX_ID_LENGTH = 200
"""Longest object id (characters)."""
MAX_LABEL_LENGTH = 200
"""Longest semantic label (characters)."""
MAX_COORDINATE = 1e6
"""Largest magnitude (m) of a position, box size or point coordinate: keeps every product
and sum of the pipeline finite and precise."""
MAX_DESCRIPTOR_LENGTH = 4096
"""Most entries of a shape descriptor."""
MAX_EMBEDDING_LENGTH = 8192
"""Most entries of a semantic embedding."""
MAX_SEEN = 2**31 - 1
"""Largest keyframe index `seen`."""


def _brief(value: Any) -> str:
    return reprlib.repr(value)[:60]


def _numbers(value: Any, what: str, shape: str) -> np.ndarray:
    """`value` as a float array; `MapError` for anything but numbers (no strings, booleans, or
    integers beyond the float range)."""
    kind = "" if shape.isdigit() else f"{shape} "
    if _small_with_non_numbers(value):
        raise MapError(f"{what} must be {kind}numbers, got {_brief(value)}")
    try:
        array = np.asarray(value)
    except (TypeError, ValueError, OverflowError) as exc:
        raise MapError(f"{what} must be {kind}numbers, got {_brief(value)}") from exc
    if array.size and array.dtype.kind not in "iuf":
        raise MapError(f"{what} must be {kind}numbers, got {_brief(value)}")
    try:
        return array.astype(float)
    except (TypeError, ValueError, OverflowError) as exc:
        raise MapError(f"{what} must be {kind}numbers, got {_brief(value)}") from exc


def _small_with_non_numbers(value: Any, depth: int = 2) -> bool:
    """Whether a short (nested) list holds booleans or strings, which numpy would convert."""
    if isinstance(value, (bool, str, bytes, np.bool_)):
        return True
    if depth == 0 or not isinstance(value, (list, tuple)) or len(value) > 16:
        return False
    return any(_small_with_non_numbers(v, depth - 1) for v in value)


def _bounded(array: np.ndarray, what: str, limit: float = MAX_COORDINATE) -> np.ndarray:
    if not np.all(np.isfinite(array)):
        raise MapError(f"{what} has non-finite values")
    if array.size and np.abs(array).max() > limit:
        raise MapError(f"{what} has values beyond ±{limit:g} (the input limit)")
    return array


def _as_vector(value: Any, length: int, what: str, limit: float = MAX_COORDINATE) -> np.ndarray:
    array = _numbers(value, what, str(length))
    if array.shape != (length,):
        raise MapError(f"{what} must have shape ({length},), got {array.shape}")
    return _bounded(array, what, limit)


def _as_points(value: Any, what: str = "points") -> np.ndarray:
    if not isinstance(value, (np.ndarray, list, tuple)) and hasattr(value, "points"):
        value = value.points  # a point cloud object (open3d's PointCloud and the like)
    array = _numbers(value, what, "an N x 3 array of")
    if array.size == 0:
        return np.zeros((0, 3))
    if array.ndim != 2 or array.shape[1] != 3:
        raise MapError(f"{what} must have shape (N, 3), got {array.shape}")
    if len(array) > MAX_POINTS_PER_OBJECT:
        raise MapError(f"{what}: {len(array):,} points, more than {MAX_POINTS_PER_OBJECT:,}")
    return _bounded(array, what)


def _as_rotation(value: Any) -> np.ndarray:
    array = _numbers(value, "rotation", "a 3 x 3 array of")
    if array.shape != (3, 3):
        raise MapError(f"rotation must have shape (3, 3), got {array.shape}")
    _bounded(array, "rotation", 2.0)
    if not np.allclose(array @ array.T, np.eye(3), atol=1e-3) or np.linalg.det(array) < 0:
        raise MapError("rotation is not a proper rotation matrix")
    return array


def _as_embedding(value: Any) -> np.ndarray:
    """A non-empty vector of finite numbers, not all zero, scaled to unit length."""
    array = _numbers(value, "embedding", "a vector of").ravel()
    if not 0 < array.size <= MAX_EMBEDDING_LENGTH:
        raise MapError(
            f"embedding must be a non-empty vector of at most {MAX_EMBEDDING_LENGTH} numbers"
        )
    if not np.all(np.isfinite(array)):
        raise MapError("embedding must be a vector of finite numbers")
    largest = np.abs(array).max()
    if largest < 1e-30:
        raise MapError("embedding is a zero vector (it has no direction)")
    array = array / largest  # the norm cannot overflow or underflow now
    return array / np.linalg.norm(array)


def _text(value: Any, what: str, limit: int, blank: bool = False) -> str:
    if not isinstance(value, str) or not (value if blank else value.strip()):
        raise MapError(f"{what} must be a non-empty string, got {_brief(value)}")
    if len(value) > limit:
        raise MapError(f"{what} has {len(value):,} characters, more than {limit}")
    try:
        value.encode("utf-8")
    except UnicodeEncodeError:
        raise MapError(f"{what} is not valid Unicode text (lone surrogate)") from None
    return value


@dataclass(frozen=True, eq=False)
class SemanticObject:
    """One object: id, semantic label and centre, with optional box, points and descriptor.

    `embedding` is an optional semantic feature vector (e.g. CLIP features), any dimension,
    scaled to unit length on construction; objects of one map must agree on its dimension.

    `position` defaults to the centre (mean) of `points`; `points` may be an N x 3 array-like
    or a point cloud object with a `.points` attribute (e.g. `open3d.geometry.PointCloud`).
    `seen` is the keyframe index of the first detection (drives incremental replay);
    `extra` keeps unknown keys of the file so that they survive a round trip.
    """

    id: str
    label: str
    position: np.ndarray = None  # type: ignore[assignment]  # None: the centre of the points
    size: np.ndarray | None = None
    rotation: np.ndarray | None = None
    points: np.ndarray | None = None
    descriptor: np.ndarray | None = None
    seen: int = 0
    score: float | None = None
    extra: dict[str, Any] = field(default_factory=dict)
    embedding: np.ndarray | None = None

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        if isinstance(self.id, (int, np.integer)) and not isinstance(self.id, bool):
            set_(self, "id", str(self.id))
        if not isinstance(self.id, str) or not self.id:
            raise MapError(f"object id must be a non-empty string, got {_brief(self.id)}")
        _text(self.id, "object id", MAX_ID_LENGTH, blank=True)
        try:
            self._validate()
        except MapError as exc:
            raise MapError(f"object '{self.id}': {exc}") from None

    def _validate(self) -> None:
        set_ = object.__setattr__
        _text(self.label, "label", MAX_LABEL_LENGTH)
        if self.points is not None:
            set_(self, "points", _as_points(self.points))
        if self.position is None:
            if self.points is None or not len(self.points):
                raise MapError("position is missing and there are no points to take the centre of")
            set_(self, "position", self.points.mean(axis=0))
        set_(self, "position", _as_vector(self.position, 3, "position"))
        if self.size is not None:
            size = _as_vector(self.size, 3, "size")
            if np.any(size < 0):
                raise MapError("size has negative entries")
            set_(self, "size", size)
        if self.rotation is not None:
            set_(self, "rotation", _as_rotation(self.rotation))
        if self.descriptor is not None:
            descriptor = _numbers(self.descriptor, "descriptor", "a vector of").ravel()
            if not 0 < descriptor.size <= MAX_DESCRIPTOR_LENGTH:
                raise MapError(
                    f"descriptor must be a non-empty vector of at most {MAX_DESCRIPTOR_LENGTH} numbers"
                )
            if not np.all(np.isfinite(descriptor)):
                raise MapError("descriptor must be a vector of finite numbers")
            set_(self, "descriptor", descriptor)
        if self.embedding is not None:
            set_(self, "embedding", _as_embedding(self.embedding))
        if isinstance(self.seen, bool) or not isinstance(self.seen, (int, np.integer)):
            raise MapError(f"seen must be an integer, got {_brief(self.seen)}")
        if not 0 <= self.seen <= MAX_SEEN:
            raise MapError(f"seen must be a keyframe index from 0 to {MAX_SEEN}, got {self.seen}")
        set_(self, "seen", int(self.seen))
        if self.score is not None:
            if isinstance(self.score, bool) or not isinstance(
                self.score, (int, float, np.integer, np.floating)
            ):
                raise MapError(f"score must be a number, got {_brief(self.score)}")
            try:
                score = float(self.score)
            except OverflowError:
                score = math.inf
            if not math.isfinite(score):
                raise MapError("score is not finite")
            set_(self, "score", score)

    def replace(self, **changes: Any) -> SemanticObject:
        """A copy with some fields changed (validated again).

        A new `position` without new `points` moves the points with the centre (by the same
        offset), so that an object's points stay where its centre says it is; give `points`
        too to set both as given.  To move or turn a whole object, `transformed` does it with
        its box as well.
        """
        if "position" in changes and "points" not in changes and self.points is not None:
            position = changes["position"]
            if position is not None:
                offset = _as_vector(position, 3, "position") - self.position
                changes["points"] = self.points + offset
        return replace(self, **changes)

    def transformed(self, T: np.ndarray) -> SemanticObject:
        """This object expressed in another frame: `p_new = R @ p + t` for T = [R t; 0 1]."""
        R, t = T[:3, :3], T[:3, 3]
        return self.replace(
            position=R @ self.position + t,
            rotation=None if self.rotation is None else R @ self.rotation,
            points=None if self.points is None else self.points @ R.T + t,
        )


FAR_FROM_POINTS_M = 2.0
"""An object whose centre lies farther than this from the box around its points is suspect
(`far_from_points`): its points and its centre say different places."""


def far_from_points(objects: Iterable[SemanticObject]) -> list[tuple[str, float]]:
    """(id, metres) of each object whose `position` lies more than `FAR_FROM_POINTS_M` outside
    the axis-aligned box around its points (e.g. a centre moved without its points)."""
    found = []
    for obj in objects:
        if obj.points is None or not len(obj.points):
            continue
        low, high = obj.points.min(axis=0), obj.points.max(axis=0)
        outside = np.maximum(0.0, np.maximum(low - obj.position, obj.position - high))
        distance = float(np.linalg.norm(outside))
        if distance > FAR_FROM_POINTS_M:
            found.append((obj.id, distance))
    return found


class ObjectMap(Sequence[SemanticObject]):
    """An immutable, validated collection of objects in one frame.

    Build it from `SemanticObject`s (`ObjectMap(objects, up=..., name=...)`) or from arrays
    (`ObjectMap.from_arrays`).  Ids must be unique.
    """

    def __init__(
        self,
        objects: Iterable[SemanticObject],
        up: Any = None,
        name: str = "",
        extra: dict[str, Any] | None = None,
    ) -> None:
        if isinstance(objects, (str, bytes)) or not isinstance(objects, Iterable):
            raise TypeError(f"ObjectMap takes an iterable of SemanticObject, got {_brief(objects)}")
        self._objects: tuple[SemanticObject, ...] = tuple(objects)
        if len(self._objects) > MAX_OBJECTS:
            raise MapError(
                f"{len(self._objects):,} objects, more than the limit of {MAX_OBJECTS:,}"
            )
        total = 0
        for obj in self._objects:
            if not isinstance(obj, SemanticObject):
                raise MapError(f"map entries must be SemanticObject, got {type(obj).__name__}")
            total += 0 if obj.points is None else len(obj.points)
        if total > MAX_POINTS_PER_MAP:
            raise MapError(
                f"{total:,} points in all, more than the limit of {MAX_POINTS_PER_MAP:,}"
            )
        self.up: np.ndarray | None = None if up is None else _unit_up(up)
        self.name = str(name)
        self.extra: dict[str, Any] = dict(extra or {})
        self._index: dict[str, int] = {}
        dimension: tuple[str, int] | None = None  # of the first embedding: (object id, length)
        for i, obj in enumerate(self._objects):
            if obj.id in self._index:
                raise MapError(f"object '{obj.id}': duplicate id")
            self._index[obj.id] = i
            if obj.embedding is not None:
                dimension = dimension or (obj.id, len(obj.embedding))
                if len(obj.embedding) != dimension[1]:
                    raise MapError(
                        f"object '{obj.id}': embedding has {len(obj.embedding)} entries, object "
                        f"'{dimension[0]}' of the same map has {dimension[1]}"
                    )

    @classmethod
    def from_arrays(
        cls,
        ids: Sequence[Any],
        labels: Sequence[str],
        positions: Any,
        *,
        points: Sequence[Any] | None = None,
        descriptors: Sequence[Any] | None = None,
        sizes: Any = None,
        rotations: Any = None,
        seen: Sequence[int] | None = None,
        embeddings: Sequence[Any] | None = None,
        up: Any = None,
        name: str = "",
    ) -> ObjectMap:
        """Build a map from parallel arrays (one row per object); optional columns may be None."""
        positions = _numbers(positions, "positions", "an N x 3 array of")
        columns = {"ids": ids, "labels": labels, "points": points, "descriptors": descriptors,
                   "sizes": sizes, "rotations": rotations, "seen": seen,
                   "embeddings": embeddings}  # fmt: skip
        for what, column in columns.items():
            if column is not None and (
                isinstance(column, (str, bytes)) or not hasattr(column, "__len__")
            ):
                raise TypeError(f"from_arrays: {what} must be a sequence, got {_brief(column)}")
        n = len(ids)
        if len(labels) != n or positions.shape != (n, 3):
            raise MapError(
                f"ids ({n}), labels ({len(labels)}) and positions {positions.shape} do not match"
            )
        for what, column in columns.items():
            if column is not None and len(column) != n:
                raise MapError(f"{what} has {len(column)} entries for {n} objects")
        objects = [
            SemanticObject(
                id=ids[i],
                label=labels[i],
                position=positions[i],
                size=None if sizes is None else sizes[i],
                rotation=None if rotations is None else rotations[i],
                points=None if points is None else points[i],
                descriptor=None if descriptors is None else descriptors[i],
                seen=0 if seen is None else seen[i],
                embedding=None if embeddings is None else embeddings[i],
            )
            for i in range(n)
        ]
        return cls(objects, up=up, name=name)

    # Sequence protocol -------------------------------------------------------------------
    def __len__(self) -> int:
        return len(self._objects)

    def __getitem__(self, item):  # type: ignore[override]
        if isinstance(item, slice):
            return self.with_objects(self._objects[item])
        return self._objects[item]

    def __iter__(self) -> Iterator[SemanticObject]:
        return iter(self._objects)

    def __repr__(self) -> str:
        return f"ObjectMap(name={self.name!r}, objects={len(self)}, up={self.up})"

    # Lookup --------------------------------------------------------------------------------
    def index_of(self, object_id: str) -> int:
        return self._index[str(object_id)]

    def get(self, object_id: str) -> SemanticObject:
        return self._objects[self.index_of(object_id)]

    def __contains__(self, object_id: object) -> bool:
        return str(object_id) in self._index

    # Column views --------------------------------------------------------------------------
    @cached_property
    def ids(self) -> np.ndarray:
        return np.array([o.id for o in self._objects], dtype=object)

    @cached_property
    def encoded_ids(self) -> EncodedIds:
        """The ids' UTF-8 bytes, as `semloc.digests` reads them."""
        return encode_ids(self.ids.tolist())

    @cached_property
    def labels(self) -> np.ndarray:
        return np.array([o.label for o in self._objects], dtype=object)

    @cached_property
    def positions(self) -> np.ndarray:
        if not self._objects:
            return np.zeros((0, 3))
        return np.stack([o.position for o in self._objects])

    @cached_property
    def sweep_order(self) -> SweepOrder:
        """The order of sweeps over the positions (see `semloc.pointsets.SweepOrder`)."""
        return SweepOrder.of(self.positions)

    @cached_property
    def sizes(self) -> np.ndarray:
        """(N, 3); NaN rows where an object has no box."""
        return np.array(
            [o.size if o.size is not None else [np.nan] * 3 for o in self._objects]
        ).reshape(-1, 3)

    @cached_property
    def rotations(self) -> np.ndarray:
        """(N, 3, 3); identity where an object has no box rotation."""
        return np.array(
            [o.rotation if o.rotation is not None else np.eye(3) for o in self._objects]
        ).reshape(-1, 3, 3)

    @cached_property
    def seen(self) -> np.ndarray:
        return np.array([o.seen for o in self._objects], dtype=int)

    @property
    def points(self) -> list[np.ndarray | None]:
        return [o.points for o in self._objects]

    @property
    def descriptors(self) -> list[np.ndarray | None]:
        return [o.descriptor for o in self._objects]

    @cached_property
    def embeddings(self) -> tuple[np.ndarray, np.ndarray]:
        """(indices of the objects with an embedding, their unit embeddings stacked (M, D))."""
        rows = [i for i, o in enumerate(self._objects) if o.embedding is not None]
        if not rows:
            return np.zeros(0, dtype=int), np.zeros((0, 0))
        return np.array(rows), np.stack([self._objects[i].embedding for i in rows])

    # Derived maps ----------------------------------------------------------------------------
    def with_objects(self, objects: Iterable[SemanticObject]) -> ObjectMap:
        """A map with the same frame metadata and other objects."""
        return ObjectMap(objects, up=self.up, name=self.name, extra=self.extra)

    def subset(self, ids: Iterable[str]) -> ObjectMap:
        return self.with_objects(self.get(i) for i in ids)

    def transformed(self, T: np.ndarray) -> ObjectMap:
        """The same objects expressed in another frame (`p_new = R p + t`); `up` rotates too."""
        T = np.asarray(T, dtype=float)
        up = None if self.up is None else T[:3, :3] @ self.up
        return ObjectMap(
            (o.transformed(T) for o in self._objects), up=up, name=self.name, extra=self.extra
        )

    # Interop -------------------------------------------------------------------------------
    def cloud(
        self, colors: Mapping[str, Any] | None = None
    ) -> tuple[np.ndarray, np.ndarray | None]:
        """All objects' points as one (N, 3) array (an object without points: its centre), and
        with `colors` (label -> "#rrggbb" or RGB in 0..1) the (N, 3) RGB of each point."""
        parts = [o.points if o.points is not None and len(o.points) else o.position[None]
                 for o in self._objects]  # fmt: skip
        points = np.concatenate(parts) if parts else np.zeros((0, 3))
        if colors is None:
            return points, None
        missing = sorted({o.label for o in self._objects} - set(colors))
        if missing:
            raise MapError(f"colors has no colour for the labels {missing}")
        rgb = [np.tile(_rgb(colors[o.label]), (len(p), 1))
               for o, p in zip(self._objects, parts)]  # fmt: skip
        return points, np.concatenate(rgb) if rgb else np.zeros((0, 3))

    def to_open3d(self, colors: Mapping[str, Any] | None = None) -> Any:
        """The map as an `open3d.geometry.PointCloud` (see `cloud`; needs `semloc[sim]`).

        `semloc.pictures.colors.label_colors` gives every label its own colour, as in semloc's pictures.
        """
        import open3d  # the one optional import of the core: only when asked for

        points, rgb = self.cloud(colors)
        cloud = open3d.geometry.PointCloud(open3d.utility.Vector3dVector(points))
        if rgb is not None:
            cloud.colors = open3d.utility.Vector3dVector(rgb)
        return cloud


def _rgb(color: Any) -> np.ndarray:
    """A colour as RGB in 0..1, from "#rrggbb" or three numbers in 0..1."""
    if isinstance(color, str):
        hex_digits = color.removeprefix("#")
        try:
            return np.array([int(hex_digits[i : i + 2], 16) for i in (0, 2, 4)]) / 255.0
        except ValueError:
            raise MapError(f"colour {color!r} is not #rrggbb") from None
    return _as_vector(color, 3, "colour")


def unit_vector(value: Any, what: str = "up") -> np.ndarray:
    """`value` (3 finite numbers within ±`MAX_COORDINATE`, not all zero) scaled to length 1.

    A direction with larger entries is refused rather than rescaled: its length overflows
    to infinity in plain arithmetic (1e308² = inf), the mark of a damaged file."""
    vector = _numbers(value, what, "3")
    if vector.shape != (3,):
        raise MapError(f"{what} must have shape (3,), got {vector.shape}")
    if not np.all(np.isfinite(vector)):
        raise MapError(f"{what} has non-finite values")
    if np.abs(vector).max() > MAX_COORDINATE:
        raise MapError(
            f"{what} {_brief(vector.tolist())} is too large to normalise (its length overflows); "
            f"give a direction with entries within ±{MAX_COORDINATE:g}, e.g. [0, 0, 1]"
        )
    if np.abs(vector).max() < 1e-12:
        raise MapError(f"{what} must be a non-zero vector")
    return vector / np.linalg.norm(vector)


def _unit_up(up: Any) -> np.ndarray:
    return unit_vector(up, "up")
