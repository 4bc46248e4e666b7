"""Shape descriptors of objects: one vector per object point set, compared by Euclidean distance.

    from semloc import descriptors
    f = descriptors.compute(points)                      # geometric (hand-made, no learning)
    F = descriptors.compute_batch(point_sets, "voxnet")  # learned, shipped weights, numpy only
    gmap = descriptors.with_descriptors(gmap, "voxnet")  # store them in a map

Both kinds work in a gravity-aligned frame (z up) with yaw and translation removed.  Each kind
is registered in the one registry of descriptor kinds, `semloc.association.DESCRIBERS`, with its
calibrated gate δ (≥ 98 % of true simulated pairs pass; see docs/descriptors.md and
`semloc descriptors-eval`); `KINDS` and `DELTAS` are views of it.  Adding a kind: a module with
its batch function, and one `_register` line below.

This package is run-time code only (numpy); training and evaluation live in
`semloc.eval.descriptors`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from semloc.association import DESCRIBERS
from semloc.descriptors.geometric import LENGTH, geometric_descriptor
from semloc.descriptors.voxnet import EMBEDDING, forward, occupancy_grid
from semloc.maps import ObjectMap, SemanticObject

MIN_POINTS = 10


@dataclass(frozen=True)
class DescriptorKind:
    """One registered kind: its name, calibrated gate δ and batch function."""

    name: str
    delta: float
    batch: Callable[[Sequence[np.ndarray]], np.ndarray]

    def describe(self, objects: Sequence[SemanticObject]) -> list[SemanticObject]:
        return describe_objects(objects, self.name)


def _geometric_batch(point_sets: Sequence[np.ndarray]) -> np.ndarray:
    rows = [geometric_descriptor(p) for p in point_sets]
    return np.stack(rows) if rows else np.zeros((0, LENGTH))


def _voxnet_batch(point_sets: Sequence[np.ndarray]) -> np.ndarray:
    if not len(point_sets):
        return np.zeros((0, EMBEDDING), dtype=np.float32)
    return forward(np.stack([occupancy_grid(p) for p in point_sets]))


def _register(kind: DescriptorKind) -> None:
    DESCRIBERS[kind.name] = kind


_register(DescriptorKind("geometric", 2.31, _geometric_batch))
_register(DescriptorKind("voxnet", 1.30, _voxnet_batch))

KINDS: tuple[str, ...] = tuple(DESCRIBERS)
DELTAS: dict[str, float] = {name: kind.delta for name, kind in DESCRIBERS.items()}
"""Calibrated gate δ per descriptor kind (distance below which a pair stays a candidate)."""


def _kind(name: str) -> DescriptorKind:
    if name not in DESCRIBERS:
        raise ValueError(f"unknown descriptor kind {name!r}; use one of {list(DESCRIBERS)}")
    return DESCRIBERS[name]  # type: ignore[return-value]


def compute(points: np.ndarray, kind: str = "geometric") -> np.ndarray:
    """The descriptor of one object's points (N, 3), z up: a 1D float array."""
    return compute_batch([points], kind)[0]


def compute_batch(point_sets: Sequence[np.ndarray], kind: str = "geometric") -> np.ndarray:
    """Descriptors (M, L) of M point sets (each (N_i, 3), z up)."""
    return _kind(kind).batch(point_sets)


def describe_objects(
    objects: Sequence[SemanticObject], kind: str = "geometric", overwrite: bool = False
) -> list[SemanticObject]:
    """The objects with a descriptor of `kind` for every one that has ≥ 10 points and no
    descriptor yet (all such objects with `overwrite`); the others are returned unchanged."""
    _kind(kind)
    objects = list(objects)
    todo = [
        i
        for i, o in enumerate(objects)
        if o.points is not None
        and len(o.points) >= MIN_POINTS
        and (overwrite or o.descriptor is None)
    ]
    if todo:
        values = compute_batch([objects[i].points for i in todo], kind)
        for i, value in zip(todo, values):
            objects[i] = objects[i].replace(descriptor=value.astype(float))
    return objects


def with_descriptors(
    objmap: ObjectMap, kind: str = "geometric", overwrite: bool = False
) -> ObjectMap:
    """The map with descriptors of `kind` added as `describe_objects` does (for map writers)."""
    return objmap.with_objects(describe_objects(objmap, kind, overwrite))


def described(objmap: ObjectMap, kind: str | None) -> ObjectMap:
    """What the map writers store: fresh descriptors of `kind` (the map unchanged for None)."""
    return objmap if kind is None else with_descriptors(objmap, kind, overwrite=True)


__all__ = [
    "DELTAS",
    "KINDS",
    "DescriptorKind",
    "compute",
    "compute_batch",
    "described",
    "describe_objects",
    "with_descriptors",
]
