"""Label similarity sources are a registry (`semloc.association.SIMILARITY_SOURCES`): applied
in order, a later one deciding for the map objects it scores; a source that scores per label
caches under its own name, so sources never read each other's values."""

from __future__ import annotations

import numpy as np
import pytest

from semloc.association import (
    SIMILARITY_SOURCES,
    AssociationConfig,
    CandidateIndex,
    SimilaritySource,
    register_similarity,
)
from semloc.maps import ObjectMap, SemanticObject

MAP = ObjectMap([SemanticObject("g0", "chair", [0, 0, 0]), SemanticObject("g1", "table", [1, 0, 0]),
                 SemanticObject("g2", "zorblax", [2, 0, 0])])  # fmt: skip


@pytest.fixture()
def registry():
    saved = dict(SIMILARITY_SOURCES)
    yield SIMILARITY_SOURCES
    SIMILARITY_SOURCES.clear()
    SIMILARITY_SOURCES.update(saved)


def test_the_shipped_sources_are_the_taxonomy_then_embeddings():
    assert list(SIMILARITY_SOURCES) == ["taxonomy", "embedding"]
    index = CandidateIndex(MAP, AssociationConfig())
    assert index.candidates(SemanticObject("l0", "armchair", [0, 0, 0])).tolist() == [0]


def test_a_registered_source_decides_for_the_objects_it_scores(registry):
    """A source of its own (say a vocabulary the taxonomy lacks) that caches per label: its
    values are its own, not the taxonomy's cached ones for the same label."""
    calls = []

    def alien(label: str) -> np.ndarray:
        calls.append(label)
        return np.array([0.0, 0.0, 1.0 if label == "blorp" else 0.0])

    register_similarity(SimilaritySource(
        "alien", lambda index, obj: ([2], index.per_label("alien", obj.label, alien)[2:]),
    ))  # fmt: skip
    index = CandidateIndex(MAP, AssociationConfig())
    blorp = SemanticObject("l0", "blorp", [0, 0, 0])
    assert index.label_similarity("blorp").tolist() == [0.0, 0.0, 0.0]  # the taxonomy's
    assert index.candidates(blorp).tolist() == [2]
    assert CandidateIndex(MAP, AssociationConfig()).candidates(blorp).tolist() == [2]
    assert calls == ["blorp"]  # computed once per map and label, then shared
    chair = SemanticObject("l1", "chair", [0, 0, 0])
    assert index.candidates(chair).tolist() == [0]  # the alien source says 0 for g2 only
