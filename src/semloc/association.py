"""Candidate (singleton) associations between local and global objects (paper Sec. III-B, init).

A local object may be associated with a global object when their labels agree (compared after
an optional label map of synonyms, case- and space-insensitive) and, when both carry shape
descriptors of the same length, the descriptor distance is below `delta`.  Every candidate
becomes a singleton association set with score 0.  With `descriptor` set, the Localizer
computes descriptors of that kind for objects with points (semloc.descriptors) and the bound is
`descriptor_delta`, by default the kind's calibrated δ.

Descriptor kinds are a registry (`DESCRIBERS`, name -> `Describer`) that `semloc.descriptors`
fills when semloc is imported; the Localizer resolves its describer and gate once, when it is
built, and a user may pass a describer of their own.
"""

from __future__ import annotations

import weakref
from collections.abc import Sequence
from typing import Protocol

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator

from semloc.maps import ObjectMap, SemanticObject


class Describer(Protocol):
    """A shape descriptor kind: computes descriptors, and the gate δ calibrated for them."""

    delta: float

    def describe(self, objects: Sequence[SemanticObject]) -> list[SemanticObject]:
        """The objects with a descriptor for every one that has enough points and none yet."""
        ...


DESCRIBERS: dict[str, Describer] = {}
"""The descriptor kinds by name (filled by `semloc.descriptors`)."""


class AssociationConfig(BaseModel):
    """Which (global, local) object pairs may be associated at all."""

    model_config = ConfigDict(extra="forbid")

    delta: float = Field(
        0.5, gt=0, description="Descriptor distance bound for a candidate pair (paper: 0.5)."
    )
    label_map: dict[str, str] = Field(
        default_factory=dict,
        description="Synonyms mapped onto one label before comparing, e.g. {'sofa': 'couch'}.",
    )
    use_descriptors: bool = Field(
        True, description="Gate candidates by descriptor distance when both objects have one."
    )
    descriptor: str | None = Field(
        None,
        description="Compute shape descriptors of this kind for objects with points that lack "
        "one (semloc.descriptors); None: use only descriptors the maps carry.",
    )
    descriptor_delta: float | None = Field(
        None,
        gt=0,
        description="Gate bound when `descriptor` is set; None: the calibrated δ of the kind "
        "(semloc.descriptors.DELTAS).",
    )

    @field_validator("descriptor")
    @classmethod
    def _known_kind(cls, kind: str | None) -> str | None:
        if kind is not None and kind not in DESCRIBERS:
            raise ValueError(f"unknown descriptor kind {kind!r}; choose from {sorted(DESCRIBERS)}")
        return kind

    @property
    def computed_descriptor(self) -> str | None:
        """The descriptor kind the Localizer computes for objects with points (None: none)."""
        return self.descriptor if self.use_descriptors else None

    def describer(self) -> Describer | None:
        """The registered describer of `descriptor` when descriptors are computed (else None)."""
        kind = self.computed_descriptor
        return None if kind is None else DESCRIBERS[kind]

    def gate(self, describer: Describer | None) -> float:
        """The descriptor distance bound in effect with `describer` (None: stored ones)."""
        if describer is None:
            return self.delta
        return self.descriptor_delta if self.descriptor_delta is not None else describer.delta


def canonical_label(label: str, label_map: dict[str, str]) -> str:
    """The label used for comparison: trimmed, lower case, mapped through `label_map`."""
    key = label.strip().lower()
    mapped = label_map.get(label, label_map.get(key, key))
    return mapped.strip().lower()


class CandidateIndex:
    """Global objects grouped by label, ready to answer "which global objects may this be?".

    Built in time linear in the map, once per map and label map (`label_groups`): labels are
    canonicalised once per distinct label, and the descriptors of each label group are
    stacked per length, so a query is one vectorised distance computation over the group.
    """

    def __init__(
        self, global_map: ObjectMap, config: AssociationConfig, gate: float | None = None
    ) -> None:
        self.config = config
        self._label_map = {k.strip().lower(): v for k, v in config.label_map.items()}
        self._by_label = label_groups(global_map, self._label_map)
        self._map = global_map
        self._stacks: dict[tuple[str, int], tuple[np.ndarray, np.ndarray]] = {}
        self._gate = config.delta if gate is None else gate

    @property
    def labels(self) -> set[str]:
        return set(self._by_label)

    def candidates(self, obj: SemanticObject) -> np.ndarray:
        """Indices of the global objects that `obj` may be associated with (sorted)."""
        label = canonical_label(obj.label, self._label_map)
        indices = self._by_label.get(label, np.zeros(0, dtype=int))
        if not self.config.use_descriptors or obj.descriptor is None or len(indices) == 0:
            return indices
        local = np.asarray(obj.descriptor, dtype=float)
        with_same, stack = self._stack(label, local.shape)
        ok = np.ones(len(indices), dtype=bool)  # without a comparable descriptor: allowed
        if len(with_same):
            distance = np.linalg.norm(stack - local.ravel(), axis=1)
            ok[np.searchsorted(indices, with_same[distance >= self._gate])] = False
        return indices[ok]

    def _stack(self, label: str, shape: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
        """The group's objects whose descriptor has `shape`, and those descriptors stacked."""
        key = (label, shape)
        if key not in self._stacks:
            indices = self._by_label[label]
            described = [(i, self._map[i].descriptor) for i in indices.tolist()]
            kept = [(i, d) for i, d in described if d is not None and d.shape == shape]
            rows = [i for i, _ in kept]
            stack = np.array([np.ravel(d) for _, d in kept], dtype=float)
            width = int(np.prod(shape))
            self._stacks[key] = (np.array(rows, dtype=int), stack.reshape(len(rows), width))
        return self._stacks[key]


_LABEL_GROUPS: weakref.WeakKeyDictionary[ObjectMap, dict[tuple, dict[str, np.ndarray]]] = (
    weakref.WeakKeyDictionary()
)


def label_groups(global_map: ObjectMap, label_map: dict[str, str]) -> dict[str, np.ndarray]:
    """The sorted indices of the map's objects per canonical label (read-only arrays), computed
    once per map (its objects never change) and label map, whichever Localizer asks."""
    per_map = _LABEL_GROUPS.setdefault(global_map, {})
    key = tuple(sorted(label_map.items()))
    if key not in per_map:
        raw, inverse = np.unique(np.asarray(global_map.labels, dtype=str), return_inverse=True)
        canonical = np.array([canonical_label(str(x), label_map) for x in raw], dtype=str)
        labels = canonical[inverse.ravel()] if len(raw) else np.zeros(0, dtype=str)
        order = np.argsort(labels, kind="stable")
        names, starts = np.unique(labels[order], return_index=True)
        groups = np.split(order, starts[1:]) if len(order) else []
        per_map[key] = {str(name): np.sort(group) for name, group in zip(names, groups)}
        for group in per_map[key].values():
            group.flags.writeable = False
    return per_map[key]
