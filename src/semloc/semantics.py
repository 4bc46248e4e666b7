"""Label semantics: how alike two object labels (or two embeddings) are, as a number in [0, 1].

Labels are first normalised (`normalise`): lower case, `_ - /` and other separators read as
spaces, parenthesised glosses dropped ("mouse (computer equipment)"), leading qualifiers
dropped ("part of a", "anonymize"), and a plural read as its singular when the taxonomy knows
only the singular.  Then the shipped taxonomy of indoor object classes (`data/taxonomy.json`
in this package, a package resource read once; see docs/vocabulary.md for its sources) gives:

    exact      1.0   equal normalised labels ("Trash_Can" / "trash can")
    synonym    0.9   names of one class ("couch" / "sofa")
    parent     0.7   the other label is the direct parent class ("armchair" / "chair");
    child      0.7   ... or a direct child class ("chair" / "armchair");
                0.6  a farther ancestor or descendant ("armchair" / "seating")
    similar    0.5   a pair of classes detectors confuse ("pillow" / "cushion")
    unrelated  0.0   anything else, and any label the taxonomy does not know that is not
                     exactly equal to the other

The similarity is symmetric; `relation(a, b)` names the kind as seen from `a` ("parent": `b`
is a parent class of `a`).  Embeddings (e.g. CLIP features) are compared by cosine similarity
mapped linearly onto [0, 1] between `EMBEDDING_FLOOR` (→ 0) and `EMBEDDING_FULL` (→ 1).

Each label is read once per process (`reading`: its key and class; the taxonomy never
changes) and each pair of classes related once (`class_relation`): a new local label is
compared with every label of a map, and those are few and recur in every comparison.

Pure computation: the one resource read is the package's own taxonomy file.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from functools import cache, lru_cache
from importlib import resources
from typing import Literal

import numpy as np

Relation = Literal["exact", "synonym", "parent", "child", "similar", "unrelated"]

EXACT, SYNONYM, PARENT, ANCESTOR, SIMILAR = 1.0, 0.9, 0.7, 0.6, 0.5
"""The similarity of each relation (`ANCESTOR`: parent or child over more than one link)."""

EMBEDDING_FLOOR, EMBEDDING_FULL = 0.7, 0.9
"""Cosine similarities mapped onto similarity 0 and 1 (linear between, clipped): with the
default candidate threshold 0.5 a pair of embeddings is a candidate from cosine 0.8 on."""

QUALIFIERS = ("part of a ", "part of an ", "part of the ", "part of ", "a ", "an ", "the ",
              "anonymize ", "anonymized ", "some ", "pair of ")  # fmt: skip
"""Leading words that do not change what an object is."""

_SEPARATORS = re.compile(r"[\s_\-/\\.,;:|+]+")
_GLOSS = re.compile(r"\([^)]*\)")
_IRREGULAR = {"shelves": "shelf", "knives": "knife", "people": "person", "mice": "mouse",
              "leaves": "leaf", "feet": "foot", "children": "child", "women": "woman",
              "men": "man", "teeth": "tooth"}  # fmt: skip


def normalise(label: str) -> str:
    """`label` lower case, glosses and leading qualifiers dropped, separators as one space."""
    text = _GLOSS.sub(" ", label.lower())
    text = _SEPARATORS.sub(" ", text).strip()
    changed = True
    while changed:
        changed = False
        for qualifier in QUALIFIERS:
            if text.startswith(qualifier) and len(text) > len(qualifier):
                text, changed = text[len(qualifier) :].strip(), True
    return text or label.strip().lower()  # a label of separators only stays itself


def singular(text: str) -> str:
    """`text` with its last word made singular by the common English rules."""
    head, _, word = text.rpartition(" ")
    if word in _IRREGULAR:
        word = _IRREGULAR[word]
    elif len(word) > 4 and word.endswith("ies"):
        word = word[:-3] + "y"
    elif len(word) > 4 and word.endswith(("ses", "xes", "zes", "ches", "shes")):
        word = word[:-2]
    elif len(word) > 3 and word.endswith("s") and not word.endswith(("ss", "us", "is")):
        word = word[:-1]
    return f"{head} {word}" if head else word


@dataclass(frozen=True)
class Taxonomy:
    """Canonical classes: names -> class, parent links, confusable class pairs."""

    class_of: dict[str, str]  # normalised name or synonym -> canonical class
    parents: dict[str, tuple[str, ...]]  # class -> its direct parent classes
    confusable: frozenset[frozenset[str]]

    def key(self, label: str) -> str:
        """The normalised form of `label`, singular unless the taxonomy knows the plural as a
        name of another class than the singular."""
        text = normalise(label)
        one = singular(text)
        if text in self.class_of and self.class_of.get(one) != self.class_of[text]:
            return text  # a plural the taxonomy knows as another class ("blinds")
        return one

    def resolve(self, label: str) -> str | None:
        """The canonical class of `label`, None if the taxonomy does not know it.  A label of
        alternatives ("Monitor/TV", Objects365's style) is the class of the first one known."""
        found = self.class_of.get(self.key(label))
        if found is None and "/" in label:
            parts = (self.class_of.get(self.key(part)) for part in label.split("/"))
            found = next((c for c in parts if c is not None), None)
        return found

    def depth(self, child: str, ancestor: str) -> int | None:
        """Links from class `child` up to class `ancestor` (None: not an ancestor)."""
        frontier, seen, depth = {child}, {child}, 0
        while frontier:
            depth += 1
            frontier = {p for c in frontier for p in self.parents.get(c, ())} - seen
            if ancestor in frontier:
                return depth
            seen |= frontier
        return None


def build_taxonomy(data: dict) -> Taxonomy:
    """A `Taxonomy` from the data of a taxonomy file (see `data/taxonomy.json`)."""
    class_of: dict[str, str] = {}
    parents: dict[str, tuple[str, ...]] = {}
    classes = data["classes"]
    for name, entry in classes.items():
        for alias in (name, *entry.get("synonyms", ())):
            class_of.setdefault(normalise(alias), name)
        parents[name] = tuple(entry.get("parents", ()))
    unknown = {p for ps in parents.values() for p in ps} - set(classes)
    unknown |= {c for pair in data.get("confusable", ()) for c in pair} - set(classes)
    if unknown:
        raise ValueError(f"taxonomy refers to classes it does not define: {sorted(unknown)}")
    confusable = frozenset(frozenset(pair) for pair in data.get("confusable", ()))
    return Taxonomy(class_of, parents, confusable)


@cache
def taxonomy() -> Taxonomy:
    """The shipped taxonomy (read once from the package's `data/taxonomy.json`)."""
    text = resources.files("semloc").joinpath("data", "taxonomy.json").read_text("utf-8")
    return build_taxonomy(json.loads(text))


@lru_cache(maxsize=65536)
def reading(label: str) -> tuple[str, str | None]:
    """How the taxonomy reads `label`: its key (`Taxonomy.key`) and its class (None: not known).
    Computed once per label: a map's labels and a robot's are few and recur in every pair."""
    tax = taxonomy()
    return tax.key(label), tax.resolve(label)


@lru_cache(maxsize=65536)
def relation(a: str, b: str) -> tuple[Relation, float]:
    """How label `b` relates to label `a` (as seen from `a`), and their similarity."""
    (key_a, ca), (key_b, cb) = reading(a), reading(b)
    if key_a == key_b:
        return "exact", EXACT
    if ca is None or cb is None:
        return "unrelated", 0.0
    return class_relation(ca, cb)


@lru_cache(maxsize=65536)
def class_relation(ca: str, cb: str) -> tuple[Relation, float]:
    """How class `cb` relates to class `ca` (both canonical, e.g. from `reading`)."""
    if ca == cb:
        return "synonym", SYNONYM
    tax = taxonomy()
    up = tax.depth(ca, cb)
    if up is not None:
        return "parent", PARENT if up == 1 else ANCESTOR
    down = tax.depth(cb, ca)
    if down is not None:
        return "child", PARENT if down == 1 else ANCESTOR
    if frozenset((ca, cb)) in tax.confusable:
        return "similar", SIMILAR
    return "unrelated", 0.0


def similarity(a: str, b: str) -> float:
    """The semantic similarity of two labels in [0, 1] (symmetric; 1 for equal normalised)."""
    return relation(a, b)[1]


def pair_weight(similarity: np.ndarray | float) -> np.ndarray:
    """How much a candidate pair of this semantic similarity counts in a hypothesis' evidence:
    1 for an exact match, halfway between 1 and its similarity otherwise (a synonym 0.95, a
    parent class 0.85, a confusable class 0.75), so names a detector spells differently cost
    little while an exact match still outweighs a parent class, which outweighs a confusable."""
    return 0.5 + 0.5 * np.asarray(similarity, dtype=float)


def embedding_similarity(cosine: np.ndarray | float) -> np.ndarray:
    """Cosine similarities of unit embeddings mapped onto [0, 1] (see `EMBEDDING_FLOOR`)."""
    span = EMBEDDING_FULL - EMBEDDING_FLOOR
    return np.clip((np.asarray(cosine, dtype=float) - EMBEDDING_FLOOR) / span, 0.0, 1.0)
