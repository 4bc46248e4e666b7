"""Place retrieval: which parts of a large map can hold the local view, before the clustering.

In a building the same labels repeat thousands of times: every chair of the map is a candidate
of every local chair, and the clustering (`semloc.clustering`) would test the consistency of
them all.  Place retrieval narrows each local object's candidates to the places whose object
constellation can hold the view, as scene-graph systems retrieve a room or submap before they
verify (Hydra, SceneGraphLoc); the clustering, verification and decision then run unchanged
on the candidates kept.

**Places.**  The map is cut into cells, cubes of `RetrievalConfig.cell` metres; the place of a
map object is its cell, or, when objects say which room they are in (`extra["room"]`: a scene
graph's rooms layer, `semloc.io.dsg`), the part of its cell in its room (no place spans a
wall between rooms).  Its **descriptor** is the set of its objects' *constellation words*:
(label of an object in the cell, label of a map object within `reach` of it, their distance in
bins of `bin` metres).  `PlaceIndex` holds every (word, cell) once, sorted by word: built once
per map (`place_index`, cached while the map lives; a changed map is a new map and gets a new
index), its memory bounded by the map's object pairs within `reach`, and at most one entry per
word and cell.

**Retrieval.**  For each local object a and each other local object b within `reach` of it,
the words (label of a candidate of a, label of a candidate of b, every bin of a map distance
the clustering's merge gate may pass for |ab| (`MergeCriterion.window`), widened to as far
below |ab| as it reaches above, and within `reach`) are looked up; a cell *supports* a for b
when it holds one of them.  The support of a cell for a (how many local objects b it
supports a for) bounds from above the number of local objects a candidate of a in that cell
is consistent with.  A candidate of a is kept when its cell's support is
within `slack` of the best cell's support for a (`slack`: a share of it, at least one object,
for detections the map lacks or mislabelled ones).  A local object with no neighbour within
`reach` keeps every candidate.  Every place as good as the best is kept, so a view that has
identical copies elsewhere keeps them all, and the decision still sees the rivals of a place.

A local object whose retrieved places still hold more than `wait_above` candidates (one chair
of a first view in a building of 40,000 chairs) *waits*: it joins the clustering once more
objects narrow its places (the search then regrows from the window).  The clustering keeps a
bounded pool of sets (`max_sets`, 2000), so feeding it tens of thousands of equally plausible
singletons only made it keep an arbitrary share of them; while every object waits the answer
is `failed`, with the reason that the view fits too many places.  An update whose objects all
wait gives the clustering's sets nothing to merge with, so it does not age them (the Localizer
skips the clustering then): the places found so far are not expired while the view waits.

Small maps are not retrieved at all (`RetrievalConfig.above`): their answers are exactly those
of the clustering on every candidate.
"""

from __future__ import annotations

import weakref

import numpy as np
from pydantic import BaseModel, ConfigDict, Field
from scipy.spatial import cKDTree

from semloc._places_fast import cell_support
from semloc.clustering import MergeCriterion
from semloc.maps import ObjectMap

__all__ = ["PlaceIndex", "RetrievalConfig", "place_index"]

_BLOCK = 4096  # map objects whose pairs are taken at once while the index is built


class RetrievalConfig(BaseModel):
    """Place retrieval in front of the clustering, for large maps."""

    model_config = ConfigDict(extra="forbid")

    above: int | None = Field(
        3000,
        ge=0,
        description="Maps with at least this many objects are retrieved (None: never); "
        "smaller maps are clustered on every candidate.",
    )
    cell: float = Field(4.0, gt=0, description="Edge of a place's cell (m).")
    reach: float = Field(
        6.0, gt=0, description="Object pairs up to this distance (m) make constellation words."
    )
    bin: float = Field(0.5, gt=0, description="Distance bin of a constellation word (m).")
    wait_above: int = Field(
        2000,
        ge=1,
        description="A local object with more candidates than this in its retrieved places "
        "waits out of the clustering until more objects narrow its places (the clustering's "
        "pool keeps max_sets = 2000 sets: more singletons would be cut arbitrarily).",
    )
    slack: float = Field(
        0.25,
        ge=0,
        le=1,
        description="A candidate's place may support its local object this share fewer "
        "times than the best place (at least one).",
    )


class PlaceIndex:
    """The cells of a map and their constellation words, sorted by word."""

    def __init__(self, global_map: ObjectMap, config: RetrievalConfig) -> None:
        self.config = config
        positions = np.asarray(global_map.positions, dtype=float).reshape(-1, 3)
        label_names, self.label_codes = np.unique(global_map.labels, return_inverse=True)
        self.label_codes = self.label_codes.astype(np.int64)
        self.n_labels = max(len(label_names), 1)
        self.n_bins = int(np.floor(config.reach / config.bin)) + 1
        corners = np.floor(positions / config.cell).astype(np.int64)
        keys = np.column_stack([corners, _room_codes(global_map)])
        _, self.cell_of = np.unique(keys, axis=0, return_inverse=True)
        self.cell_of = self.cell_of.reshape(-1).astype(np.int64)
        self.n_cells = int(self.cell_of.max()) + 1 if len(positions) else 0
        self.words, self.cells = self._entries(positions)

    def _entries(self, positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Every (word, cell of the word's first object) once, sorted by word then cell.  The
        map's pairs are taken a block of objects at a time and reduced to distinct entries
        before the next block, so memory stays bounded by a block's pairs and the entries
        (at most one per word and cell), however dense the map."""
        if len(positions) < 2:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        tree = cKDTree(positions)
        found = []
        for start in range(0, len(positions), _BLOCK):
            block = np.arange(start, min(start + _BLOCK, len(positions)))
            near = tree.query_ball_point(positions[block], self.config.reach, return_sorted=False)
            counts = np.fromiter((len(n) for n in near), dtype=np.int64, count=len(near))
            first = np.repeat(block, counts)
            second = np.fromiter((j for n in near for j in n), dtype=np.int64, count=counts.sum())
            other = first != second
            first, second = first[other], second[other]
            bins = np.linalg.norm(positions[first] - positions[second], axis=1) // self.config.bin
            words = self.word(self.label_codes[first], self.label_codes[second],
                              bins.astype(np.int64))  # fmt: skip
            found.append(np.unique(words * self.n_cells + self.cell_of[first]))
        entries = np.unique(np.concatenate(found))
        return entries // self.n_cells, entries % self.n_cells

    def word(self, first: np.ndarray, second: np.ndarray, bins: np.ndarray) -> np.ndarray:
        """The constellation word of labels `first`, `second` (codes) `bins` apart."""
        return (first * self.n_labels + second) * self.n_bins + bins

    @property
    def nbytes(self) -> int:
        return int(self.words.nbytes + self.cells.nbytes + self.cell_of.nbytes)

    def support(
        self, local_positions: np.ndarray, candidates: list[np.ndarray], criterion: MergeCriterion
    ) -> np.ndarray:
        """Per local object (rows) and cell (columns): for how many other local objects the
        cell holds a word of the pair at a distance the clustering's merge gate may pass."""
        local_positions = np.asarray(local_positions, dtype=float).reshape(-1, 3)
        n = len(local_positions)
        codes = [np.unique(self.label_codes[c]) for c in candidates]
        starts = np.zeros(n + 1, np.int64)
        starts[1:] = np.cumsum([len(c) for c in codes])
        flat = np.concatenate(codes).astype(np.int64) if n else np.zeros(0, np.int64)
        gaps = np.linalg.norm(local_positions[:, None] - local_positions[None], axis=2)
        lowest, highest = criterion.window(gaps)  # the map distances the gate may pass
        # only pairs whose every consistent map distance is indexed (within reach)
        near = (highest <= self.config.reach) & ~np.eye(n, dtype=bool)
        first, second = np.nonzero(near)
        d, lowest, highest = gaps[first, second], lowest[first, second], highest[first, second]
        lowest = np.minimum(lowest, d - (highest - d))  # as far below |ab| as above it
        low = np.maximum(lowest // self.config.bin, 0).astype(np.int64)
        high = np.minimum(highest // self.config.bin, self.n_bins - 1).astype(np.int64)
        return cell_support(
            self.words, self.cells, first.astype(np.int64), second.astype(np.int64), low, high,
            starts, flat, self.n_labels, self.n_bins, n, self.n_cells,
        )  # fmt: skip

    def kept(self, support: np.ndarray, candidates: list[np.ndarray]) -> list[np.ndarray]:
        """Each local object's candidates whose cell's support is within the slack of the
        best cell's (all of them when no cell supports it); none while more than `wait_above`
        are left (the object waits)."""
        kept = []
        for row, found in zip(support, candidates):
            best = int(row.max()) if len(row) else 0
            if best == 0 or len(found) == 0:
                kept.append(found)
                continue
            floor = best - max(1, int(np.floor(self.config.slack * best)))
            kept.append(found[row[self.cell_of[found]] >= max(floor, 1)])
        return [k if len(k) <= self.config.wait_above else k[:0] for k in kept]


def _room_codes(global_map: ObjectMap) -> np.ndarray:
    """Per object, a number for its room (`extra["room"]`, e.g. a scene graph's rooms layer;
    -1 without one): a cell never spans two rooms."""
    codes: dict[str, int] = {}
    rooms = [obj.extra.get("room") for obj in global_map]
    return np.array(
        [-1 if room is None else codes.setdefault(str(room), len(codes)) for room in rooms],
        dtype=np.int64,
    ).reshape(-1, 1)


_INDEXES: weakref.WeakKeyDictionary[ObjectMap, dict[str, PlaceIndex]] = weakref.WeakKeyDictionary()


def place_index(global_map: ObjectMap, config: RetrievalConfig) -> PlaceIndex:
    """The place index of `global_map` for `config`, built on first use and kept while the
    map lives (every Localizer of one map shares it)."""
    cache = _INDEXES.setdefault(global_map, {})
    key = config.model_dump_json(exclude={"above", "slack"})
    if key not in cache:
        cache[key] = PlaceIndex(global_map, config)
    return cache[key]
