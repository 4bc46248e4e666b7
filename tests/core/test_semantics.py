"""Label semantics: every listed vocabulary resolves, the similarity's levels and symmetry,
embeddings' calibration, and soft candidates in the Localizer."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import semloc
from semloc import semantics
from semloc.association import AssociationConfig, CandidateIndex, label_report
from semloc.semantics import (
    EXACT,
    SIMILAR,
    build_taxonomy,
    embedding_similarity,
    normalise,
    relation,
    similarity,
    taxonomy,
)

VOCABULARIES = json.loads((Path(__file__).parent / "vocabularies.json").read_text())
LISTS = {k: v for k, v in VOCABULARIES.items() if k != "about"}
NAMES = sorted({n for names in LISTS.values() for n in names})
KNOWN = sorted(taxonomy().class_of)


@pytest.mark.parametrize("vocabulary", sorted(LISTS))
def test_every_name_of_the_listed_vocabularies_resolves(vocabulary):
    unknown = [n for n in LISTS[vocabulary] if taxonomy().resolve(n) is None]
    assert not unknown, f"{vocabulary}: {unknown}"


def test_the_shipped_taxonomy_refers_only_to_its_own_classes():
    with pytest.raises(ValueError, match="does not define"):
        build_taxonomy({"classes": {"chair": {"parents": ["seat"]}}})


@pytest.mark.parametrize(
    ("a", "b", "kind"),
    [
        ("Trash_Can", "trash cans", "exact"),
        ("chairs", "chair", "exact"),
        ("part of a chair", "chair", "exact"),
        ("sofa", "couch", "synonym"),
        ("fridge", "refrigerator", "synonym"),
        ("tv-screen", "television", "synonym"),
        ("armchair", "chair", "parent"),
        ("chair", "armchair", "child"),
        ("table", "coffee table", "child"),
        ("pillow", "cushion", "similar"),
        ("lamp", "light", "similar"),
        ("chair", "toilet", "unrelated"),
        ("zorblax", "zorblax", "exact"),
        ("zorblax", "chair", "unrelated"),
    ],
)
def test_relations(a, b, kind):
    assert relation(a, b)[0] == kind


def test_levels_are_ordered_exact_synonym_parent_similar_unrelated():
    levels = [similarity("sofa", x) for x in ("Sofas", "couch", "loveseat", "armchair", "toilet")]
    assert levels == sorted(levels, reverse=True) and len(set(levels)) == 5
    assert levels[0] == EXACT and levels[3] == SIMILAR and levels[4] == 0.0


LABELS_OR_TEXT = st.one_of(st.sampled_from(NAMES + KNOWN), st.text(min_size=1, max_size=12))


@given(LABELS_OR_TEXT, LABELS_OR_TEXT)
def test_similarity_is_symmetric_and_in_the_unit_interval(a, b):
    assert similarity(a, b) == similarity(b, a)
    assert 0.0 <= similarity(a, b) <= 1.0


@given(st.text(min_size=1, max_size=30))
def test_equal_normalised_labels_are_exact(text):
    assert similarity(text, text) == 1.0
    assert similarity(text.upper(), text.lower()) == 1.0 or text.upper().lower() != text.lower()


@given(st.text(alphabet="abcXYZ _-/", min_size=1, max_size=20))
def test_normalise_is_idempotent(text):
    assert normalise(normalise(text)) == normalise(text)
    assert similarity("___", "--") == 0.0


def test_embedding_calibration_is_monotone_and_clipped():
    cos = np.linspace(-1, 1, 41)
    s = embedding_similarity(cos)
    assert (np.diff(s) >= 0).all() and s[0] == 0.0 and s[-1] == 1.0


def _room(labels, seed=0, embeddings=None):
    rng = np.random.default_rng(seed)
    positions = rng.uniform(0, 6, (len(labels), 3))
    objects = [
        semloc.SemanticObject(
            str(i), lb, p, embedding=None if embeddings is None else embeddings[i]
        )
        for i, (lb, p) in enumerate(zip(labels, positions))
    ]
    return semloc.ObjectMap(objects)


def _view(room, names, T):
    return room.with_objects(
        o.replace(label=names.get(o.label, o.label)) for o in room
    ).transformed(T)


T = np.eye(4)
T[:3, 3] = [0.3, -0.2, 0.0]
LABELS = [
    "armchair",
    "couch",
    "refrigerator",
    "coffee table",
    "television",
    "pillow",
    "lamp",
    "desk",
]


def test_a_detector_vocabulary_localizes_by_soft_candidates():
    room = _room(LABELS)
    names = {"armchair": "chair", "couch": "sofa", "refrigerator": "fridge",
             "coffee table": "table", "television": "tv", "pillow": "cushion"}  # fmt: skip
    local = _view(room, names, T)
    result = semloc.localize(room, local)
    assert result.pose is not None
    assert np.allclose(result.pose, np.linalg.inv(T), atol=1e-6)
    exact = semloc.localize(room, local, min_similarity=1.0)
    assert exact.pose is None or not np.allclose(exact.pose, np.linalg.inv(T), atol=1e-6)


def test_unknown_labels_still_localize_by_exact_equality():
    labels = [f"thing-{i % 4}" for i in range(8)]
    room = _room(labels, seed=3)
    result = semloc.localize(room, room.transformed(T))
    assert np.allclose(result.pose, np.linalg.inv(T), atol=1e-6)


def test_exact_pairs_weigh_more_than_parent_pairs():
    room = _room(LABELS)
    exact = semloc.localize(room, room.transformed(T)).best
    coarse = semloc.localize(
        room, _view(room, {"armchair": "chair", "coffee table": "table"}, T)
    ).best
    assert exact.features["n_pairs"] > coarse.features["n_pairs"]


def test_label_map_wins_over_the_taxonomy():
    room = _room(LABELS)
    index = CandidateIndex(room, AssociationConfig(label_map={"chair": "desk"}))
    chair = semloc.SemanticObject("x", "chair", [0, 0, 0])
    assert [room[i].label for i in index.candidates(chair)] == ["desk"]
    plain = CandidateIndex(room, AssociationConfig())
    assert [room[i].label for i in plain.candidates(chair)] == ["armchair", "couch"]


def test_label_report_for_a_hand_built_case():
    room = _room(LABELS)
    local = _room(["chair", "sofa", "armchair", "cushion", "zorblax"])
    report = label_report(CandidateIndex(room, AssociationConfig()), local)
    got = {k: (v.resolved, v.map_labels) for k, v in report.items()}
    assert got == {
        "armchair": ("exact", ("armchair",)),
        "chair": ("child", ("armchair", "couch")),
        "cushion": ("similar", ("pillow",)),
        "sofa": ("synonym", ("couch",)),
        "zorblax": ("unmatched", ()),
    }


def test_embeddings_decide_where_both_objects_carry_one():
    rng = np.random.default_rng(1)
    prototypes = rng.normal(size=(len(LABELS), 16))
    room = _room(LABELS, embeddings=prototypes)
    noisy = prototypes + 0.05 * rng.normal(size=prototypes.shape)
    local = _room(["thing"] * len(LABELS), embeddings=noisy).transformed(T)
    result = semloc.localize(room, local)
    assert np.allclose(result.pose, np.linalg.inv(T), atol=1e-6)
    index = CandidateIndex(room, AssociationConfig())
    assert label_report(index, local)["thing"].resolved == "embedding"


def test_each_label_is_read_once_however_many_pairs_it_is_in(monkeypatch):
    """A new local label against a map compares with every map label, but each label is
    normalised only when first read (`semantics.reading`), not once per pair."""
    calls: list[str] = []
    monkeypatch.setattr(
        semantics, "normalise", lambda label: calls.append(label) or normalise(label)
    )
    semantics.reading.cache_clear()
    semantics.relation.cache_clear()
    map_labels = ["Chair", "office chair", "sofa", "Table", "desk", "lamp", "pillows"]
    objects = [semloc.SemanticObject(f"g{i}", x, [i, 0.0, 0.0]) for i, x in enumerate(map_labels)]
    gmap = semloc.ObjectMap(objects)
    index = CandidateIndex(gmap, AssociationConfig())
    local_labels = ["armchair", "couch", "cushion", "chair"]
    for local in local_labels:
        index.label_similarity(local)
    read = {x.lower() for x in map_labels} | set(local_labels)  # map labels as canonical
    assert sorted(set(calls)) == sorted(read)
    assert all(calls.count(label) == 2 for label in read)  # its key, then its class
    assert relation("armchair", "chair") == ("parent", 0.7)
