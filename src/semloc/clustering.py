"""Association sets and their incremental hierarchical clustering (the paper's Sec. III-B).

Vocabulary
    candidate        a pair (global object, local object) allowed by `association.py`.
    association set  a set of candidates, one-to-one, with a score v; singletons score 0.
    h(a, b)          distance-ratio merge metric of two candidates a=(α_i, β_i), b=(α_j, β_j):
                     min(d^B/d^A, d^A/d^B) of the global and local object distances.

The paper's rules, as implemented
    * Two sets D1, D2 merge when every *new* cross pair (a ∈ D1∖D2, b ∈ D2∖D1) has h > γ; a
      set containing the other is not merged.  A cross pair sharing a global or a local object
      with different partners has h = 0 (the union must stay one-to-one).
    * The merged set scores v1 + v2 + Σ h over the new cross pairs; the originals are kept.
    * Duplicates keep the larger score.  Only the top K = sets_per_object · n_global sets are
      kept.  Sets that have not merged for more than `expiry_updates` updates are dropped.
    * Each update adds the singletons of new or re-detected local objects, then clusters again.

Formulation (equivalent to the literal pairwise test, see tests/core/test_clustering.py)
    Two candidates are *compatible* when they are one-to-one and pass the merge criterion.
    Every set is a clique of compatible candidates (singletons trivially; a merge only joins
    sets whose new cross pairs are all compatible), so D1 ∪ D2 passes the literal test exactly
    when D2 ⊆ M(D1), the candidates compatible with (or in) every member of D1.  Nothing is
    kept over all candidates of a map: compatibility is needed only among the *live*
    candidates (members of the sets in the pool, at most K · n_local of them plus the
    singletons of this update).  It is a sparse graph, found per new live candidate by a
    sweep along the map's longest axis (only global objects within the gate's reach
    (d^B + ε)/γ of it are tested exactly) and kept across updates for candidates that stay
    live.  Memory grows with the live candidates times their compatible neighbours, never
    with candidates².
    One iteration is one compiled pass (numba, `_clustering_fast.merges_of_frontier`): for each frontier set
    A, E(A) = M(A)∖A is counted from its members' neighbourhoods; every pool set is filed
    under one pivot member (the one held by the fewest sets), so the sets inside M(A) are
    among those filed under M(A)'s candidates, and a 64-bit member signature screens them
    before the exact test B∖A ⊆ E(A).  Merges are grouped by union on the fly through
    additive 64-bit set keys (key(A ∪ B) = key(A) + Σ over B∖A), checked by a second key and,
    on disagreement, by the member lists themselves; a merge is scored (Σ h over the new
    cross pairs, from the object positions) only when its bound v_A + v_B + |A∖B|·|B∖A| can
    beat the best score of its union so far, which leaves every union's score unchanged.

Where the paper is silent (see also docs/contracts.md, "How semloc reads the paper")
    * "Marking merged sets": every pair of sets is tried once.  A clustering round works on a
      frontier: in each iteration only pairs with at least one set created in the previous
      iteration (or at this update) are tried; iterations run until no new set appears.
      Within an iteration all merges use the scores from its start, so the result does not
      depend on the order of objects.
    * K is capped by `max_sets` (default 2000, None for the paper's 10·n).  The paper's rule
      makes sense for small maps, where 10·n sets cover the plausible hypotheses; in a
      building the plausible hypotheses are the repetitions of the local layout, which do
      not grow with the part of the map that is not like it, while 10·n would make every
      iteration cost (10·n)².  Above 200 objects the pool is therefore bounded by a size that
      does not depend on the map: work and memory per iteration stay bounded, and only the
      singletons of a new local object (one per same-label global object) grow with the map.
    * Top-K pruning happens after every iteration (bounding work and memory), with ties broken
      by size and then by an order-independent hash of the set's (global id, local id) pairs:
      the wrapping sum of their 64-bit BLAKE2b digests (`semloc.digests`; computed only for
      the sets that tie at a cut).
    * A set's age is reset when it merges (as either parent), when it is created, and when a
      re-detection re-adds it as a singleton.  Expiry spares the `protect_top` best sets, so
      an answer is not forgotten while new detections bring nothing consistent.
    * `distance_tolerance` (ε, metres; default 0.4, 0 is the paper's pure ratio) softens the
      merge criterion for centres biased by partial views (the paper bounds this uncertainty
      "by a predefined threshold" without giving one): a pair passes when
      1 − max(0, |d^A − d^B| − ε) / max(d^A, d^B) > γ.  Scores always use the paper's h, so
      they still reward the closest agreement.  Distances both below `min_distance` count as
      h = 1.
    * When a re-detection moves a local object, the compatibility of its candidates is
      recomputed; sets that are no longer cliques are dropped and the others keep their score.
    * Many objects at once (a whole second map, `semloc.align`): the candidates of one update
      grow with its objects and their compatibility edges with its square, and every new set
      may merge with every other, so the clustering itself does not bound that work.
      `semloc.alignment` never gives it more than `whole_below` objects in one update: a
      larger map is clustered in small seed views (the case the paper's rules are made for,
      unchanged) and grown over the whole map by guided matching once a view has a pose.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from semloc._clustering_fast import (
    agreements,
    candidate_keys,
    compatible_among,
    compatible_sweep,
    find_by_keys,
    gate_windows,
    gates,
    held,
    kept_edges,
    merges_of_frontier,
    renumbered,
    row_sizes,
    rows_of,
    stacked,
    symmetric_csr,
    union_rows,
)
from semloc.digests import EncodedIds, encode_ids, pair_digests
from semloc.pointsets import SweepOrder

_BRUTE_FORCE_PAIRS = 3_000  # up to this many candidate pairs the compatibility test takes them all
_WINDOW_ENTRIES = 1 << 22  # the sweep keeps window starts (8 bytes each) up to this many


class ClusteringConfig(BaseModel):
    """Parameters of the hierarchical clustering of association sets."""

    model_config = ConfigDict(extra="forbid")

    gamma: float = Field(0.8, gt=0, lt=1, description="Merge threshold on the distance ratio h.")
    distance_tolerance: float = Field(
        0.4,
        ge=0,
        description="Slack ε (m) on distance differences in the merge criterion, bounding the "
        "centre bias of partially seen objects; 0 is the paper's pure ratio.",
    )
    min_distance: float = Field(
        0.05, ge=0, description="Distances below this (m) on both sides count as equal."
    )
    sets_per_object: int = Field(
        10, ge=1, description="Keep the top K = sets_per_object * n_global sets (paper: 10)."
    )
    max_sets: int | None = Field(
        2000,
        ge=1,
        description="Upper bound on K, independent of the map size (work grows with K²); "
        "None keeps the paper's 10·n.",
    )
    expiry_updates: int = Field(
        2, ge=0, description="Drop sets that have not merged for more than this many updates."
    )
    protect_top: int = Field(10, ge=0, description="The best sets are never expired.")


@dataclass(frozen=True)
class MergeCriterion:
    """The merge criterion: what two candidates add to a set's score, and whether they may
    share a set at all.  The rule itself is compiled (`_clustering_fast.agreement`, `gate`,
    `gate_window`, the ones the clustering runs); these methods apply it to arrays.

    * `score` is the paper's h = min(d^B/d^A, d^A/d^B) (with `min_distance`), at most
      `UPPER_BOUND`; the clustering's exact pruning bounds (`_survival_floor`, `_best_merges`)
      rely on that bound, so a new score must keep it or change `UPPER_BOUND`.
    * `compatible` is the gate h_ε > γ, where h_ε is h with the slack ε (`tolerance`) taken
      off the distance difference; one-to-one-ness is checked by the caller.
    * `window` bounds the global distances the gate may pass for a local distance (the
      windows of the clustering's sweep and of place retrieval).
    """

    gamma: float
    tolerance: float = 0.0
    min_distance: float = 0.05

    UPPER_BOUND = 1.0

    @classmethod
    def of(cls, config: ClusteringConfig) -> MergeCriterion:
        return cls(config.gamma, config.distance_tolerance, config.min_distance)

    def score(self, d_global: np.ndarray, d_local: np.ndarray) -> np.ndarray:
        return merge_metric(d_global, d_local, 0.0, self.min_distance)

    def compatible(self, d_global: np.ndarray, d_local: np.ndarray) -> np.ndarray:
        shape, (d_global, d_local) = _flat(d_global, d_local)
        passes = gates(d_global, d_local, self.tolerance, self.gamma, self.min_distance)
        return passes.reshape(shape)

    def window(self, d_local: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The lowest and the highest global distance the gate may pass for each local one."""
        shape, (d_local,) = _flat(d_local)
        lowest, highest = gate_windows(d_local, self.tolerance, self.gamma, self.min_distance)
        return lowest.reshape(shape), highest.reshape(shape)


def merge_metric(
    d_global: np.ndarray,
    d_local: np.ndarray,
    tolerance: float = 0.0,
    min_distance: float = 0.05,
) -> np.ndarray:
    """h_ε for arrays of global and local distances (broadcasting; `_clustering_fast.agreement`
    element-wise); 1 is perfect agreement."""
    shape, (d_global, d_local) = _flat(d_global, d_local)
    return agreements(d_global, d_local, tolerance, min_distance).reshape(shape)


def _flat(*arrays: np.ndarray) -> tuple[tuple[int, ...], list[np.ndarray]]:
    """The shape the arrays broadcast to, and each of them broadcast to it as a flat float
    array (the compiled kernels take flat arrays)."""
    found = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in arrays))
    return found[0].shape, [a.ravel() for a in found]


@dataclass(frozen=True)
class AssociationSet:
    """One association set: (global index, local index) pairs, score and bookkeeping."""

    pairs: tuple[tuple[int, int], ...]
    score: float
    last_merge: int

    def __len__(self) -> int:
        return len(self.pairs)


class SetPairs(NamedTuple):
    """Association sets as arrays: their (global index, local index) pairs one set after the
    other (`sizes` pairs each, ascending by global index) and their scores."""

    pairs: np.ndarray  # (P, 2) int64
    sizes: np.ndarray  # (S,) int64
    scores: np.ndarray  # (S,)


class HierarchicalClustering:
    """The pool of association sets over a growing local map, grown incrementally.

    `global_positions` and `global_ids` describe the global map; `update()` receives the
    positions of all local objects so far and the candidate global indices of the local
    objects that are new or re-detected at this update.  `encoded_ids` and `sweep_order`
    (the map's `ObjectMap.encoded_ids` and `ObjectMap.sweep_order`, computed once per map)
    spare a clustering per localization from deriving them again.
    """

    def __init__(
        self,
        global_positions: np.ndarray,
        global_ids: Sequence[str],
        config: ClusteringConfig | None = None,
        *,
        encoded_ids: EncodedIds | None = None,
        sweep_order: SweepOrder | None = None,
    ) -> None:
        self.config = config or ClusteringConfig()
        self.criterion = MergeCriterion.of(self.config)
        self._global_positions = np.asarray(global_positions, dtype=float).reshape(-1, 3)
        self._global_ids = list(global_ids)
        self._encoded_global = encoded_ids  # their UTF-8 bytes, encoded when first needed
        self.capacity = self.config.sets_per_object * max(len(self._global_ids), 1)
        if self.config.max_sets is not None:
            self.capacity = min(self.capacity, self.config.max_sets)
        self.step = 0
        # candidates: (global, local) pairs, numbered in order of registration
        self._cand_g = np.zeros(0, dtype=np.int64)
        self._cand_l = np.zeros(0, dtype=np.int64)
        self._cand_alive = np.zeros(0, dtype=bool)
        self._cand_key = np.zeros(0, dtype=np.uint64)
        self._cand_key2 = np.zeros(0, dtype=np.uint64)
        self._cand_hash = np.zeros(0, dtype=np.uint64)  # pair hash, filled when first needed
        self._hashed = np.zeros(0, dtype=bool)
        self._by_local: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # sorted globals, cands
        self._local_positions = np.zeros((0, 3))
        self._local_distances = np.zeros((0, 0))
        self._local_ids: list[str] = []
        # compatibility among live candidates: edges known between all of `_covered`
        self._covered = np.zeros(0, dtype=np.int64)
        self._edges = np.zeros((2, 0), dtype=np.int64)
        self._live = np.zeros(0, dtype=np.int64)
        self._live_index = np.zeros(0, dtype=np.int64)  # candidate -> row of the graph
        self._graph_indptr = np.zeros(1, dtype=np.int64)
        self._graph_indices = np.zeros(0, dtype=np.int64)
        self._live_global = np.zeros((0, 3))  # per live candidate: global, local position
        self._live_local = np.zeros((0, 3))
        self._live_key = np.zeros(0, dtype=np.uint64)  # and its two keys
        self._live_key2 = np.zeros(0, dtype=np.uint64)
        self._sweep = sweep_order  # of the global positions, found when first needed
        self._merge_room = 4096  # unions one merge pass has room for (see _with_room)
        self._edge_room = 16384  # compatible pairs one search has room for
        # sets: member candidates (ascending, -1 padded), score, age, keys
        self._members = np.full((0, 1), -1, dtype=np.int64)
        self._live_members: np.ndarray | None = None  # members as graph rows, while known
        self._size = np.zeros(0, dtype=np.int64)
        self._score = np.zeros(0)
        self._last_merge = np.zeros(0, dtype=np.int64)
        self._key = np.zeros(0, dtype=np.uint64)
        self._key2 = np.zeros(0, dtype=np.uint64)

    # ------------------------------------------------------------------------------------
    # Public view
    @property
    def n_sets(self) -> int:
        return len(self._score)

    @property
    def n_candidates(self) -> int:
        return int(self._cand_alive.sum())

    def sets(self) -> list[AssociationSet]:
        """All sets, best first (score, then size, then an order-independent tie-break)."""
        return self._sets(self._ranking())

    def top(self, k: int, min_size: int = 1, largest_first: bool = False) -> list[AssociationSet]:
        """The k best sets with at least `min_size` pairs (by score, or by size then score)."""
        return self._sets(self._top_rows(k, min_size, largest_first))

    def top_pairs(self, k: int, min_size: int = 1, largest_first: bool = False) -> SetPairs:
        """`top` as arrays, without a Python object per set or pair."""
        return self._set_pairs(self._top_rows(k, min_size, largest_first))

    def top_scores(self, k: int, min_size: int = 1) -> list[float]:
        """The scores of `top(k, min_size)`, largest first, without building the sets and,
        unless sets of equal rounded score but different scores tie at the cut, without
        ranking them (which of the tied sets are chosen then does not change the scores)."""
        scores = self._score[self._size >= min_size]
        if len(scores) > k:
            rounded = np.round(scores, 9)
            cut = _kth_largest(rounded, k)
            above, at_cut = scores[rounded > cut], scores[rounded == cut]
            if np.any(at_cut != at_cut[0]):
                scores = self._score[self._top_rows(k, min_size, False)]
            else:
                scores = np.concatenate([above, at_cut[: k - len(above)]])
        return sorted(scores.tolist(), reverse=True)

    def _top_rows(self, k: int, min_size: int, largest_first: bool) -> np.ndarray:
        rows = np.flatnonzero(self._sizes() >= min_size)
        return rows[self._ranking(rows, limit=k, largest_first=largest_first)][:k]

    def _sets(self, rows: np.ndarray) -> list[AssociationSet]:
        """The sets of pool rows, each with its (global, local) pairs in ascending order (one
        global object per set, so ordered by the global index)."""
        found = self._set_pairs(rows)
        pairs, ends = found.pairs.tolist(), np.cumsum(found.sizes).tolist()
        ages = self._last_merge[rows].tolist()
        return [
            AssociationSet(tuple(map(tuple, pairs[end - n : end])), score, age)
            for n, end, score, age in zip(found.sizes.tolist(), ends, found.scores.tolist(), ages)
        ]

    def _set_pairs(self, rows: np.ndarray) -> SetPairs:
        """The sets of pool rows as arrays, each set's pairs ascending by global index."""
        members = self._members[rows]
        g = np.where(members >= 0, self._cand_g[np.maximum(members, 0)], np.iinfo(np.int64).max)
        members = np.take_along_axis(members, np.argsort(g, axis=1, kind="stable"), axis=1)
        members = members[members >= 0]  # each row's members first: the padding sorts last
        pairs = np.stack([self._cand_g[members], self._cand_l[members]], axis=1)
        return SetPairs(pairs, self._size[rows], self._score[rows])

    def _sizes(self) -> np.ndarray:
        return self._size

    # ------------------------------------------------------------------------------------
    # Update
    def update(
        self,
        local_positions: np.ndarray,
        local_ids: list[str],
        detections: dict[int, np.ndarray],
    ) -> None:
        """One incremental update: new/re-detected local objects, then a clustering round.

        `local_positions` (L, 3) and `local_ids` cover all local objects so far (index = local
        index); `detections` maps the local index of each new or re-detected object to the
        global indices it may be associated with.
        """
        self.step += 1
        self._live_members = None  # the graph's rows change: known again once it is built
        positions = np.array(local_positions, dtype=float).reshape(-1, 3)  # a copy: see moves
        moved = self._moved_locals(positions, detections)
        changed = self._changed_locals(positions, detections)
        self._local_distances = self._distances_to(positions)
        self._local_positions = positions
        self._local_ids = list(local_ids)
        stale, detected = self._register_candidates(detections)
        self._forget_edges(moved, stale)
        fresh_rows = self._revalidate(stale, moved, changed)
        fresh_rows = np.concatenate([fresh_rows, self._add_singletons(detected)])
        self._cover_live()
        self._cluster(np.unique(fresh_rows))
        self._expire()

    def _moved_locals(self, positions: np.ndarray, detections: dict[int, np.ndarray]) -> set[int]:
        known = len(self._local_positions)
        return {
            local
            for local in detections
            if local < known
            and np.linalg.norm(positions[local] - self._local_positions[local]) > 1e-6
        }

    def _changed_locals(
        self, positions: np.ndarray, detections: dict[int, np.ndarray]
    ) -> np.ndarray:
        """The known local objects whose position changed at all (moved or not)."""
        known = len(self._local_positions)
        return np.array(
            [
                local
                for local in detections
                if local < known and np.any(positions[local] != self._local_positions[local])
            ],
            dtype=np.int64,
        )

    def _register_candidates(
        self, detections: dict[int, np.ndarray]
    ) -> tuple[np.ndarray, np.ndarray]:
        """Add new candidate pairs; return the candidates that a re-detection no longer allows
        and those of the detected objects (ascending)."""
        stale, revived, new_g, new_l, detected = [], [], [], [], []
        start = len(self._cand_g)
        for local, globals_ in detections.items():
            allowed = np.unique(np.asarray(globals_, dtype=np.int64))
            ids_from = start + sum(len(x) for x in new_g)
            new_l.append(np.full(len(allowed), local, dtype=np.int64))
            if local not in self._by_local:  # a new object: all its candidates are new
                new_g.append(allowed)
                self._by_local[local] = (allowed, ids_from + np.arange(len(allowed)))
                detected.append(self._by_local[local][1])
                continue
            known_g, known_c = self._by_local[local]
            kept = np.isin(known_g, allowed)
            stale.append(known_c[~kept])
            revived.append(known_c[kept])
            fresh = allowed[~np.isin(allowed, known_g)]
            new_l[-1] = new_l[-1][: len(fresh)]
            ids = ids_from + np.arange(len(fresh))
            new_g.append(fresh)
            globals_all = np.concatenate([known_g, fresh])
            order = np.argsort(globals_all, kind="stable")
            known_g, known_c = globals_all[order], np.concatenate([known_c, ids])[order]
            self._by_local[local] = (known_g, known_c)
            detected.append(known_c[np.searchsorted(known_g, allowed)])
        count = sum(len(x) for x in new_g)
        if count:
            key, key2 = candidate_keys(np.arange(start, start + count))
            self._cand_g = np.concatenate([self._cand_g, *new_g])
            self._cand_l = np.concatenate([self._cand_l, *new_l])
            self._cand_alive = np.concatenate([self._cand_alive, np.ones(count, bool)])
            self._cand_key = np.concatenate([self._cand_key, key])
            self._cand_key2 = np.concatenate([self._cand_key2, key2])
            self._cand_hash = np.concatenate([self._cand_hash, np.zeros(count, np.uint64)])
            self._hashed = np.concatenate([self._hashed, np.zeros(count, bool)])
        stale_c = np.concatenate([np.zeros(0, np.int64), *stale]).astype(np.int64)
        self._cand_alive[np.concatenate([np.zeros(0, np.int64), *revived])] = True
        self._cand_alive[stale_c] = False
        return stale_c, np.sort(np.concatenate([np.zeros(0, np.int64), *detected]))

    def _pair_hashes(self, candidates: np.ndarray) -> np.ndarray:
        """The order-independent pair hash of each candidate (computed once, when needed)."""
        wanted = np.zeros(len(self._hashed), dtype=bool)
        wanted[candidates] = True
        todo = np.flatnonzero(wanted & ~self._hashed)
        if len(todo):
            if self._encoded_global is None:
                self._encoded_global = encode_ids(self._global_ids)
            self._cand_hash[todo] = pair_digests(
                self._encoded_global,
                self._cand_g[todo],
                encode_ids(self._local_ids),
                self._cand_l[todo],
            )
            self._hashed[todo] = True
        return self._cand_hash[candidates]

    # ------------------------------------------------------------------------------------
    # Compatibility of live candidates
    def _forget_edges(self, moved: set[int], stale: np.ndarray) -> None:
        """Edges of stale candidates and of candidates of moved objects are recomputed."""
        if not moved and not len(stale):
            return
        drop = np.isin(self._cand_l[self._covered], list(moved)) | np.isin(self._covered, stale)
        self._covered = self._covered[~drop]

    def _cover_live(self) -> None:
        """Know the compatibility among all live candidates; build its sparse graph N.

        Edges are kept once per pair; the graph has both directions (rows by counting sort).
        """
        is_live = held(self._members, len(self._cand_g))
        live = np.flatnonzero(is_live)
        is_covered = np.zeros(len(self._cand_g), dtype=bool)
        is_covered[self._covered] = True
        is_covered &= is_live
        added = live[~is_covered[live]]
        new_edges = np.zeros((2, 0), dtype=np.int64)
        if len(added):
            new_edges = self._compatible_pairs(added, live[is_covered[live]])
        index = np.zeros(len(self._cand_g), dtype=np.int64)
        index[live] = np.arange(len(live))
        self._edges = kept_edges(self._edges, is_covered, new_edges)
        self._graph_indptr, self._graph_indices = symmetric_csr(self._edges, index, len(live))
        self._covered, self._live, self._live_index = live, live, index
        self._live_members = self._as_live(self._members)
        self._live_global = rows_of(self._global_positions, self._cand_g, live)
        self._live_local = rows_of(self._local_positions, self._cand_l, live)
        self._live_key, self._live_key2 = self._cand_key[live], self._cand_key2[live]

    def _as_live(self, members: np.ndarray) -> np.ndarray:
        """Members (candidates, -1 padded) as rows of the compatibility graph."""
        return renumbered(members, self._live_index)

    def _compatible_pairs(self, added: np.ndarray, covered: np.ndarray) -> np.ndarray:
        """All compatible (a, b) with a in `added` and b in `added` ∪ `covered` (2 x E).

        Few pairs: all of them, tested in one compiled pass; many: a sweep along the map's
        longest axis per pair of local objects (only global pairs within the gate's reach)."""
        rule = self.criterion
        candidates = (added, covered, self._cand_g, self._cand_l, self._global_positions)
        gate = (rule.tolerance, rule.gamma, rule.min_distance)
        distances = self._local_distances
        if len(added) * (len(added) + len(covered)) <= _BRUTE_FORCE_PAIRS:
            arguments: tuple = (*candidates, distances, *gate)
            kernel = compatible_among
        else:
            reach = rule.window(distances)[1] * (1 + 1e-9) + 1e-12  # the gate decides
            order = self._sweep_order()
            arguments = (*candidates, distances, reach, *gate, *order, _WINDOW_ENTRIES)
            kernel = compatible_sweep
        (edges,), self._edge_room = _with_room(kernel, arguments, self._edge_room)
        return edges

    def _sweep_order(self) -> SweepOrder:
        """The sweep order of the global positions (given, or found once per clustering)."""
        if self._sweep is None:
            self._sweep = SweepOrder.of(self._global_positions)
        return self._sweep

    def _distances_to(self, positions: np.ndarray) -> np.ndarray:
        """Distances between the local objects at `positions` (each as `np.linalg.norm` of the
        difference computes it: the root of its dot product with itself), recomputed only for
        objects that are new or changed position since the last update."""
        known = min(len(self._local_positions), len(positions))
        out = np.zeros((len(positions), len(positions)))
        out[:known, :known] = self._local_distances[:known, :known]
        same = np.all(positions[:known] == self._local_positions[:known], axis=1)
        changed = np.concatenate([np.flatnonzero(~same), np.arange(known, len(positions))])
        for j in changed.tolist():
            row = np.sqrt([d.dot(d) for d in positions - positions[j]])
            row[j] = 0.0
            out[j, :] = row
            out[:, j] = row
        return out

    def _gate_of_sets(self, members: np.ndarray, changed: np.ndarray) -> np.ndarray:
        """Whether every pair of members of each set (rows, -1 padded) passes the criterion.

        Only pairs with a member whose local object `changed` position are measured: each set
        is a clique of compatible candidates, and the pairs of unchanged members are measured
        as they were when it was formed."""
        valid = members >= 0
        m = np.maximum(members, 0)
        rows, slots = np.nonzero(valid & np.isin(self._cand_l[m], changed))
        g = self._global_positions[self._cand_g[m]]
        l = self._local_positions[self._cand_l[m]]
        d_global = np.linalg.norm(g[rows, slots][:, None] - g[rows], axis=2)
        d_local = np.linalg.norm(l[rows, slots][:, None] - l[rows], axis=2)
        compatible = self.criterion.compatible(d_global, d_local)
        pair = valid[rows] & (np.arange(members.shape[1])[None] != slots[:, None])
        passes = np.ones(len(members), dtype=bool)
        passes[rows[~np.all(compatible | ~pair, axis=1)]] = False
        return passes

    def _revalidate(self, stale: np.ndarray, moved: set[int], changed: np.ndarray) -> np.ndarray:
        """Drop sets with stale candidates or broken cliques; return the rows of the sets with
        moved objects (fresh: they take part in the next round as new ones)."""
        if not len(self._score) or not (len(stale) or moved):
            return np.zeros(0, dtype=np.int64)
        members = self._members
        valid = members >= 0
        keep = ~(np.isin(members, stale) & valid).any(axis=1)
        touched = (np.isin(self._cand_l[np.where(valid, members, 0)], list(moved)) & valid).any(
            axis=1
        )
        check = np.flatnonzero(touched & keep)
        if len(check):
            keep[check] = self._gate_of_sets(members[check], changed)
        self._keep_rows(keep)
        return np.flatnonzero(touched[keep])

    def _add_singletons(self, candidates: np.ndarray) -> np.ndarray:
        """Add (or refresh) the singleton of each given candidate; return their rows."""
        if not len(candidates):
            return np.zeros(0, dtype=np.int64)
        members = candidates[:, None]
        rows = self._lookup(self._cand_key[candidates], self._cand_key2[candidates], members)
        missing = np.flatnonzero(rows < 0)
        if len(missing):
            rows[missing] = self._append(
                members[missing],
                np.zeros(len(missing)),
                self._cand_key[candidates[missing]],
                self._cand_key2[candidates[missing]],
            )
        self._last_merge[rows] = self.step
        return rows

    # ------------------------------------------------------------------------------------
    # Clustering round
    def _cluster(self, frontier: np.ndarray) -> None:
        while len(frontier):
            merges = self._find_merges(frontier)
            if merges is None:
                break
            frontier = self._insert(*merges)
            frontier = self._prune(frontier)
        self._prune(np.zeros(0, dtype=np.int64))  # a round ends with at most K sets

    def _find_merges(self, frontier: np.ndarray):
        """The merges of one iteration (A in the frontier, B in the pool), grouped by union:
        each distinct union's members, its largest merge score and its keys (None: no merge).
        The parents of every merge are marked as merged at this step."""
        live_members = self._live_members
        assert live_members is not None  # known from _cover_live to the end of the update
        in_frontier = np.zeros(len(self._score), dtype=np.bool_)
        in_frontier[frontier] = True
        arguments = (
            frontier.astype(np.int64),
            in_frontier,
            live_members,
            self._size,
            self._score,
            self._graph_indptr,
            self._graph_indices,
            self._live_global,
            self._live_local,
            self._live_key,
            self._live_key2,
            self._key,
            self._key2,
            self._survival_floor(),
            self.criterion.min_distance,
            self.criterion.UPPER_BOUND,
        )
        merged, rows_a, rows_b, best, key, key2, collided = self._merges(arguments, True)
        if collided:  # a key collision: every merge, grouped by the union's member lists
            merged, rows_a, rows_b, scores, key, key2, _ = self._merges(arguments, False)
            unions = union_rows(self._members, self._size, rows_a, rows_b)
            _, first, group = np.unique(unions, axis=0, return_index=True, return_inverse=True)
            best = np.full(len(first), -np.inf)
            np.maximum.at(best, group.ravel(), scores)
            rows_a, rows_b, key, key2 = rows_a[first], rows_b[first], key[first], key2[first]
        if not len(rows_a):
            return None
        self._last_merge[merged] = self.step
        return union_rows(self._members, self._size, rows_a, rows_b), best, key, key2

    def _merges(self, arguments: tuple, grouped: bool) -> list:
        arguments = (*arguments, grouped)
        found, self._merge_room = _with_room(merges_of_frontier, arguments, self._merge_room)
        return found

    def _survival_floor(self) -> float:
        """The K-th best score in the pool (-inf while the pool is not full), less a hair.

        A merge scores at most v_A + v_B + |A∖B|·|B∖A| (h ≤ UPPER_BOUND = 1).  One that cannot
        reach the K-th best score is pruned at the end of the iteration, and so are both of its
        parents (their scores are lower still), so such merges are skipped without changing the
        result.
        """
        if len(self._score) < self.capacity:
            return -np.inf
        return _kth_largest(self._score, self.capacity) - 1e-9

    def _insert(self, members: np.ndarray, best: np.ndarray, key: np.ndarray, key2: np.ndarray):
        """Add distinct merged sets (duplicates keep the larger score); return new rows."""
        rows = self._lookup(key, key2, members)
        known = rows >= 0
        at = rows[known]  # distinct: the merges come grouped by union
        self._score[at] = np.maximum(self._score[at], best[known])
        if known.all():
            return np.zeros(0, dtype=np.int64)
        new = ~known
        return self._append(members[new], best[new], key[new], key2[new])

    def _lookup(self, key: np.ndarray, key2: np.ndarray, members: np.ndarray) -> np.ndarray:
        """The pool row holding each given set (-1: not in the pool)."""
        if not len(self._key) or not len(key):
            return np.full(len(key), -1, dtype=np.int64)
        rows, exact = find_by_keys(self._key, self._key2, self._members, key, key2, members)
        if exact:
            return rows
        # a key collision: look sets up by their member lists
        index = {tuple(m[m >= 0]): r for r, m in enumerate(self._members)}
        return np.array([index.get(tuple(m[m >= 0]), -1) for m in members], dtype=np.int64)

    def _append(self, members, scores, key, key2) -> np.ndarray:
        start = len(self._score)
        self._members = stacked(self._members, members)
        if self._live_members is not None:
            self._live_members = stacked(self._live_members, self._as_live(members))
        self._size = np.concatenate([self._size, row_sizes(members)])
        self._score = np.concatenate([self._score, scores])
        self._last_merge = np.concatenate(
            [self._last_merge, np.full(len(scores), self.step, dtype=np.int64)]
        )
        self._key = np.concatenate([self._key, key])
        self._key2 = np.concatenate([self._key2, key2])
        return np.arange(start, start + len(scores))

    # ------------------------------------------------------------------------------------
    # Pruning
    def _ranking(
        self, rows: np.ndarray | None = None, limit: int | None = None, largest_first=False
    ) -> np.ndarray:
        """Positions in `rows` (default: all sets), best first: score (rounded), size, then an
        order-independent hash of the pairs (size first with `largest_first`).  With `limit`,
        only the first `limit` positions are exact (and only the rows that could be among them
        are ranked); the hash is computed only where sets tie among them."""
        rows = np.arange(len(self._score)) if rows is None else rows
        score = -np.round(self._score[rows], 9)
        size = -self._sizes()[rows]
        if limit is not None and 0 < limit < len(rows):
            # only the rows up to the limit's value of the first key can be in its head
            first = size if largest_first else score
            near = np.flatnonzero(first <= -_kth_largest(-first, limit))
            if len(near) < len(rows):
                return near[self._ranking(rows[near], limit, largest_first)]
        if len(rows) > 1 and (score == score[0]).all() and (size == size[0]).all():
            # all tied (the singletons at a cut): the hashes decide, as they would below
            return np.argsort(self._set_hashes(rows), kind="stable")
        keys = (score, size) if largest_first else (size, score)
        order = np.lexsort(keys)
        head = order if limit is None else order[:limit]
        if not len(head):
            return order
        last = (score[head[-1]], size[head[-1]])
        same = (score[order][1:] == score[order][:-1]) & (size[order][1:] == size[order][:-1])
        tied = np.zeros(len(order), dtype=bool)
        tied[1:] |= same
        tied[:-1] |= same
        if limit is not None:  # ties past the cut only matter if they tie with its last set
            beyond = np.arange(len(order)) >= len(head)
            tied &= ~beyond | ((score[order] == last[0]) & (size[order] == last[1]))
        set_hash = np.zeros(len(rows), dtype=np.uint64)
        needs = order[tied]
        if len(needs):
            set_hash[needs] = self._set_hashes(rows[needs])
        return np.lexsort((set_hash, *keys))

    def _set_hashes(self, rows: np.ndarray) -> np.ndarray:
        """The order-independent hash of each set: the wrapping sum of its pair hashes."""
        members = self._members[rows]
        if (self._size[rows] == 1).all():  # singletons: the pair hash itself
            return self._pair_hashes(members[:, 0])
        hashes = np.zeros(members.shape, dtype=np.uint64)
        valid = members >= 0
        hashes[valid] = self._pair_hashes(members[valid])
        return hashes.sum(axis=1, dtype=np.uint64)

    def _best_rows(self, k: int) -> np.ndarray:
        """Which sets are among the k best of `_ranking` (the same k, without sorting all):
        the sets above the k-th score for sure, and the k-th score's sets ranked exactly."""
        score = np.round(self._score, 9)
        kth = _kth_largest(score, k)
        keep = score > kth
        at_cut = np.flatnonzero(score == kth)
        if k - int(keep.sum()) < len(at_cut):
            at_cut = at_cut[self._ranking(at_cut, limit=k - int(keep.sum()))]
        keep[at_cut[: k - int(keep.sum())]] = True
        return keep

    def _prune(self, frontier: np.ndarray) -> np.ndarray:
        """Keep the top K sets; return the surviving part of the frontier (renumbered)."""
        if len(self._score) <= self.capacity:
            return frontier
        keep = self._best_rows(self.capacity)
        is_frontier = np.zeros(len(self._score), dtype=bool)
        is_frontier[frontier] = True
        self._keep_rows(keep)
        return np.flatnonzero(is_frontier[keep])

    def _expire(self) -> None:
        old = self.step - self._last_merge > self.config.expiry_updates
        if not old.any():
            return
        top = self.config.protect_top
        protected = self._best_rows(top) if 0 < top < len(old) else np.full(len(old), top > 0)
        self._keep_rows(~old | protected)

    def _keep_rows(self, keep: np.ndarray) -> None:
        rows = np.flatnonzero(keep)  # taking rows is several times faster than masking
        self._members = self._members.take(rows, axis=0)
        if self._live_members is not None:
            self._live_members = self._live_members.take(rows, axis=0)
        self._size = self._size.take(rows)
        self._score = self._score.take(rows)
        self._last_merge = self._last_merge.take(rows)
        self._key = self._key.take(rows)
        self._key2 = self._key2.take(rows)


def _kth_largest(values: np.ndarray, k: int) -> float:
    """The k-th largest of `values` (1 <= k <= len): set sizes (integers >= 1) or scores (sums
    of h >= 0).  `np.partition` slows down many times over on many equal values (the
    singletons' zero scores, the few distinct sizes), so sizes are counted and scores are
    partitioned over the positive ones only; when at most k are positive (a pruned pool plus
    new singletons) it is the smallest positive one or 0, found without a partition."""
    if k == len(values):
        return float(values.min())
    if values.dtype.kind in "iu" and values.min() >= 0:
        at_least = np.cumsum(np.bincount(values)[::-1])  # how many are >= max, max - 1, ...
        return float(len(at_least) - 1 - np.searchsorted(at_least, k))
    if (values < 0).any():
        return float(np.partition(values, len(values) - k)[len(values) - k])
    positive = values[values > 0]
    if len(positive) <= k:
        return float(positive.min()) if len(positive) == k else 0.0
    return float(np.partition(positive, len(positive) - k)[len(positive) - k])


def _with_room(kernel, arguments: tuple, room: int) -> tuple[list, int]:
    """`kernel(*arguments, room)`, whose last output says whether it ran out of room for its
    output arrays, called again with four times the room until they fit; its other outputs
    and the room that sufficed.  A kernel that never grows its arrays inside its compiled
    loop runs markedly faster than one that can (the rare second call costs less)."""
    while True:
        *found, full = kernel(*arguments, room)
        if not full:
            return found, room
        room *= 4
