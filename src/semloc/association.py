"""Candidate (singleton) associations between local and global objects (paper Sec. III-B, init).

A local object may be associated with a global object when their labels are alike enough: a
semantic similarity (`semloc.semantics`: exact, synonym, parent / child class, confusable
classes; or calibrated embedding cosine) of at least `min_similarity` and within
`similarity_margin` of the object's best match (labels compared after an optional label map,
which wins: a mapped label matches by equality only) and, when both carry shape descriptors of
the same length, the descriptor distance is below `delta`.  Every candidate becomes a singleton
association set with score 0; its similarity weighs the pair in the evidence of a hypothesis.
With `descriptor` set, the Localizer computes descriptors of that kind for objects with points
(semloc.descriptors) and the bound is `descriptor_delta`, by default the kind's calibrated δ.

Descriptor kinds are a registry (`DESCRIBERS`, name -> `Describer`) that `semloc.descriptors`
fills when semloc is imported; the Localizer resolves its describer and gate once, when it is
built, and a user may pass a describer of their own.

Label similarity comes from a registry too (`SIMILARITY_SOURCES`, name -> `SimilaritySource`,
in order): the shipped taxonomy through the label map (`taxonomy`), then embeddings where both
objects carry one (`embedding`, overriding the taxonomy on those map objects).  A source that
scores per label caches its values per map, keyed by its name and the label map
(`CandidateIndex.per_label`), so two sources never read each other's values.
"""

from __future__ import annotations

import weakref
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator

from semloc.maps import ObjectMap, SemanticObject
from semloc.semantics import embedding_similarity, relation
from semloc.semantics import similarity as semantic_similarity


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
    min_similarity: float = Field(
        0.5,
        ge=0,
        le=1,
        description="Least semantic similarity of a candidate pair (semloc.semantics: exact 1, "
        "synonym 0.9, parent / child class 0.7, confusable classes 0.5; embeddings: calibrated "
        "cosine); 1: equal normalised labels only.",
    )
    similarity_margin: float = Field(
        0.3,
        ge=0,
        le=1,
        description="A local object's candidates are within this margin of its most similar map "
        "object (an exact match keeps parent / child classes, not merely confusable ones).",
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


@dataclass(frozen=True)
class LabelResolution:
    """How one local label was read against the map's labels (the `labels` report)."""

    resolved: str  # exact | synonym | parent | child | similar | embedding | unmatched
    map_labels: tuple[str, ...]  # the map labels its objects may be, most similar first


class CandidateIndex:
    """The map's objects ready to answer "which global objects may this one be, how surely?".

    Built once per map and label map: the map's labels are grouped once (`label_groups`), and
    each distinct local label's similarity to every map object is computed once
    (`semloc.semantics`), then reused.  A local object's candidates are the map objects whose
    semantic similarity is at least `min_similarity` and within `similarity_margin` of its
    best one, gated by descriptor distance where both carry comparable descriptors.  With an
    embedding on both objects the similarity is that of the embeddings (calibrated cosine).
    A local label that `label_map` maps is compared by equality only (the map wins).
    """

    def __init__(
        self, global_map: ObjectMap, config: AssociationConfig, gate: float | None = None
    ) -> None:
        self.config = config
        self._label_map = {k.strip().lower(): v for k, v in config.label_map.items()}
        self._label_map_key = tuple(sorted(self._label_map.items()))
        self._by_label = label_groups(global_map, self._label_map)
        self._map = global_map
        self._stacks: dict[tuple[int, ...], tuple[np.ndarray, np.ndarray]] = {}
        self._gate = config.delta if gate is None else gate
        self._caches = _SIMILARITIES.setdefault(global_map, {})  # shared by one map's indexes

    @property
    def map(self) -> ObjectMap:
        return self._map

    def per_label(
        self, source: str, label: str, compute: Callable[[str], np.ndarray]
    ) -> np.ndarray:
        """`compute(label)` (a similarity per map object) of source `source`, computed once
        per map, source, label map and label, then shared read-only."""
        cache = self._caches.setdefault((source, self._label_map_key), {})
        if label not in cache:
            values = np.asarray(compute(label), dtype=float)
            values.flags.writeable = False
            cache[label] = values
        return cache[label]

    @property
    def labels(self) -> set[str]:
        return set(self._by_label)

    def candidates(self, obj: SemanticObject) -> np.ndarray:
        """Indices of the global objects that `obj` may be associated with (sorted)."""
        return self.weighted(obj)[0]

    def weighted(self, obj: SemanticObject) -> tuple[np.ndarray, np.ndarray]:
        """The candidates of `obj` (sorted global indices) and their semantic similarity."""
        similarity = self._similarities(obj)
        indices = self._kept(similarity)
        if self.config.use_descriptors and obj.descriptor is not None and len(indices):
            indices = indices[self._descriptor_ok(indices, np.asarray(obj.descriptor, float))]
        return indices, similarity[indices]

    def resolution(self, label: str, objects: Sequence[SemanticObject] = ()) -> LabelResolution:
        """How `label` is read against the map (`objects`: the local objects of that label;
        with embeddings their candidates' labels are reported)."""
        embedded = [o for o in objects if self.embedding_scores(o) is not None]
        if embedded:
            found = {i for o in embedded for i in self.candidates(o).tolist()}
            names = sorted({str(self._map.labels[i]) for i in found})
            return LabelResolution("embedding" if names else "unmatched", tuple(names))
        similarity = self.label_similarity(label)
        kept = self._kept(similarity)
        best: dict[str, float] = {}
        for i in kept.tolist():
            name = str(self._map.labels[i])
            best[name] = max(best.get(name, 0.0), float(similarity[i]))
        if not best:
            return LabelResolution("unmatched", ())
        names = sorted(best, key=lambda n: (-best[n], n))
        if self._user_mapped(label):
            return LabelResolution("exact", tuple(names))
        kind = relation(canonical_label(label, self._label_map), self._mapped(names[0]))[0]
        return LabelResolution(kind, tuple(names))

    def label_similarity(self, label: str) -> np.ndarray:
        """The taxonomy's similarity of `label` to each map object's label, through the label
        map (read-only, cached)."""
        return self.per_label("taxonomy", label, self._taxonomy_similarity)

    def _taxonomy_similarity(self, label: str) -> np.ndarray:
        local = canonical_label(label, self._label_map)
        exact_only = self._user_mapped(label)
        similarity = np.zeros(len(self._map))
        for name, group in self._by_label.items():
            value = 1.0 if local == name else semantic_similarity(local, name)
            if exact_only and value < 1.0:
                value = 0.0
            similarity[group] = value
        return similarity

    def _user_mapped(self, label: str) -> bool:
        return label in self.config.label_map or label.strip().lower() in self._label_map

    def _mapped(self, map_label: str) -> str:
        return canonical_label(map_label, self._label_map)

    def _similarities(self, obj: SemanticObject) -> np.ndarray:
        """The similarity of `obj` to each map object: each registered source in turn, a later
        one deciding for the map objects it scores."""
        similarity = None
        for source in SIMILARITY_SOURCES.values():
            found = source.score(self, obj)
            if found is None:
                continue
            rows, values = found
            if rows is None:
                similarity = values
            else:
                similarity = np.zeros(len(self._map)) if similarity is None else similarity.copy()
                similarity[rows] = values
        return np.zeros(len(self._map)) if similarity is None else similarity

    def embedding_scores(self, obj: SemanticObject) -> tuple[np.ndarray, np.ndarray] | None:
        """(map objects with a comparable embedding, calibrated similarity) or None."""
        rows, stack = self._map.embeddings
        if obj.embedding is None or not len(rows) or self._user_mapped(obj.label):
            return None
        if stack.shape[1] != len(obj.embedding):
            return None
        return rows, embedding_similarity(stack @ obj.embedding)

    def _kept(self, similarity: np.ndarray) -> np.ndarray:
        if not len(similarity):
            return np.zeros(0, dtype=int)
        floor = max(self.config.min_similarity, similarity.max() - self.config.similarity_margin)
        return np.flatnonzero(similarity >= max(floor, 1e-12))

    def _descriptor_ok(self, indices: np.ndarray, local: np.ndarray) -> np.ndarray:
        """Which candidates pass the descriptor gate (without a comparable one: allowed)."""
        rows, stack = self._stack(local.shape)
        ok = np.ones(len(indices), dtype=bool)
        if not len(rows):
            return ok
        at = np.minimum(np.searchsorted(rows, indices), len(rows) - 1)
        described = rows[at] == indices
        distance = np.linalg.norm(stack[at[described]] - local.ravel(), axis=1)
        ok[np.flatnonzero(described)[distance >= self._gate]] = False
        return ok

    def _stack(self, shape: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
        """The map objects whose descriptor has `shape` (sorted), and those descriptors."""
        if shape not in self._stacks:
            kept = [(i, o.descriptor) for i, o in enumerate(self._map)
                    if o.descriptor is not None and o.descriptor.shape == shape]  # fmt: skip
            rows = np.array([i for i, _ in kept], dtype=int)
            width = int(np.prod(shape))
            stack = np.array([np.ravel(d) for _, d in kept], dtype=float).reshape(len(rows), width)
            self._stacks[shape] = (rows, stack)
        return self._stacks[shape]


def label_report(
    index: CandidateIndex, local_map: Iterable[SemanticObject]
) -> dict[str, LabelResolution]:
    """How every label of `local_map` was read against the map of `index` (sorted by label)."""
    by_label: dict[str, list[SemanticObject]] = {}
    for obj in local_map:
        by_label.setdefault(obj.label, []).append(obj)
    return {label: index.resolution(label, objs) for label, objs in sorted(by_label.items())}


def labels_json(report: dict[str, LabelResolution]) -> dict[str, dict]:
    """A `label_report` as the `labels` object of the result JSON (CLI, service, bag answers)."""
    return {label: {"resolved": found.resolved, "map_labels": list(found.map_labels)}
            for label, found in report.items()}  # fmt: skip


_SIMILARITIES: weakref.WeakKeyDictionary[ObjectMap, dict[tuple, dict[str, np.ndarray]]] = (
    weakref.WeakKeyDictionary()
)  # map -> (source, label map) -> local label -> similarity per map object


Scores = tuple[np.ndarray | None, np.ndarray]
"""(map object indices, or None for all of them; their similarity to a local object)."""


@dataclass(frozen=True)
class SimilaritySource:
    """A kind of label similarity: `score(index, obj)` gives the similarity of a local object
    to the map objects this source decides for (`Scores`), or None when it has no say (e.g. no
    embedding).  A source that depends on the label only should cache through
    `CandidateIndex.per_label` under its own name."""

    name: str
    score: Callable[[CandidateIndex, SemanticObject], Scores | None]


SIMILARITY_SOURCES: dict[str, SimilaritySource] = {}
"""The label similarity sources in the order they are applied (later ones decide for the map
objects they score)."""


def register_similarity(source: SimilaritySource) -> None:
    """Add (or replace) a similarity source, applied after those registered before it."""
    SIMILARITY_SOURCES[source.name] = source


register_similarity(
    SimilaritySource("taxonomy", lambda index, obj: (None, index.label_similarity(obj.label)))
)
register_similarity(SimilaritySource("embedding", lambda index, obj: index.embedding_scores(obj)))


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
