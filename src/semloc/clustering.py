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
    One iteration is one compiled pass (numba, `_merges_of_frontier`): for each frontier set
    A, E(A) = M(A)∖A is counted from its members' neighbourhoods; every pool set is filed
    under one pivot member (the one held by the fewest sets), so the sets inside M(A) are
    among those filed under M(A)'s candidates, and a 64-bit member signature screens them
    before the exact test B∖A ⊆ E(A).  Merges are grouped by union on the fly through
    additive 64-bit set keys (key(A ∪ B) = key(A) + Σ over B∖A), checked by a second key and,
    on disagreement, by the member lists themselves; a merge is scored (Σ h over the new
    cross pairs, from the object positions) only when its bound v_A + v_B + |A∖B|·|B∖A| can
    beat the best score of its union so far, which leaves every union's score unchanged.

Where the paper is silent (see also DESIGN.md)
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
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numba import njit
from pydantic import BaseModel, ConfigDict, Field

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
    """The merge criterion in one place: what two candidates add to a set's score, and whether
    they may share a set at all.

    * `score` is the paper's h = min(d^B/d^A, d^A/d^B) (with `min_distance`), at most
      `UPPER_BOUND`; the clustering's exact pruning bounds (`_survival_floor`, `_best_merges`)
      rely on that bound, so a new score must keep it or change `UPPER_BOUND`.
    * `compatible` is the gate h_ε > γ, where h_ε is h with the slack ε (`tolerance`) taken
      off the distance difference; one-to-one-ness is checked by the caller.
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
        gate = merge_metric(d_global, d_local, self.tolerance, self.min_distance)
        return gate > self.gamma


def merge_metric(
    d_global: np.ndarray,
    d_local: np.ndarray,
    tolerance: float = 0.0,
    min_distance: float = 0.05,
) -> np.ndarray:
    """h for arrays of global and local distances (broadcasting); 1 is perfect agreement."""
    d_global, d_local = np.broadcast_arrays(np.asarray(d_global), np.asarray(d_local))
    d_max = np.maximum(d_global, d_local)
    excess = np.maximum(np.abs(d_global - d_local) - tolerance, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        h = 1.0 - excess / d_max
    return np.where(d_max < min_distance, 1.0, np.where(d_max > 0, h, 1.0))


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


@njit(cache=True, inline="always")
def _mix(x: np.uint64) -> np.uint64:
    """A bijective 64-bit mixer (splitmix64's finaliser)."""
    x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return x ^ (x >> np.uint64(31))


@njit(cache=True)
def _candidate_keys(candidates: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two independent 64-bit keys per candidate index (set keys are their wrapping sums)."""
    key = np.empty(len(candidates), dtype=np.uint64)
    key2 = np.empty(len(candidates), dtype=np.uint64)
    for i in range(len(candidates)):
        base = np.uint64(candidates[i]) * np.uint64(2)
        key[i] = _mix(base + np.uint64(1))
        key2[i] = _mix(base + np.uint64(2))
    return key, key2


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
        self._local_distances = self._distances_to(positions)
        self._local_positions = positions
        self._local_ids = list(local_ids)
        stale, detected = self._register_candidates(detections)
        self._forget_edges(moved, stale)
        fresh_rows = self._revalidate(stale, moved)
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
            key, key2 = _candidate_keys(np.arange(start, start + count))
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
        is_live = _held(self._members, len(self._cand_g))
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
        self._edges = _kept_edges(self._edges, is_covered, new_edges)
        self._graph_indptr, self._graph_indices = _symmetric_csr(self._edges, index, len(live))
        self._covered, self._live, self._live_index = live, live, index
        self._live_members = self._as_live(self._members)
        self._live_global = _rows_of(self._global_positions, self._cand_g, live)
        self._live_local = _rows_of(self._local_positions, self._cand_l, live)
        self._live_key, self._live_key2 = self._cand_key[live], self._cand_key2[live]

    def _as_live(self, members: np.ndarray) -> np.ndarray:
        """Members (candidates, -1 padded) as rows of the compatibility graph."""
        return _renumbered(members, self._live_index)

    def _compatible_pairs(self, added: np.ndarray, covered: np.ndarray) -> np.ndarray:
        """All compatible (a, b) with a in `added` and b in `added` ∪ `covered` (2 x E).

        Few pairs: all of them, tested in one compiled pass; many: a sweep along the map's
        longest axis per pair of local objects (only global pairs within the gate's reach)."""
        cfg = self.config
        candidates = (added, covered, self._cand_g, self._cand_l, self._global_positions)
        gate = (cfg.distance_tolerance, cfg.gamma, cfg.min_distance)
        distances = self._local_distances
        if len(added) * (len(added) + len(covered)) <= _BRUTE_FORCE_PAIRS:
            arguments: tuple = (*candidates, distances, *gate)
            kernel = _compatible_among
        else:
            # the gate 1 - max(0, |d^A - d^B| - ε) / max(d^A, d^B) > γ needs d^A < (d^B + ε) / γ
            reach = np.maximum((distances + cfg.distance_tolerance) / cfg.gamma, cfg.min_distance)
            reach = reach * (1 + 1e-9) + 1e-12  # the exact test decides at the boundary
            order = self._sweep_order()
            arguments = (*candidates, distances, reach, *gate, *order, _WINDOW_ENTRIES)
            kernel = _compatible_sweep
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

    def _gate_of_sets(self, members: np.ndarray) -> np.ndarray:
        """Whether every pair of members of each set (rows, -1 padded) passes the criterion."""
        valid = members >= 0
        m = np.maximum(members, 0)
        g = self._global_positions[self._cand_g[m]]
        l = self._local_positions[self._cand_l[m]]
        d_global = np.linalg.norm(g[:, :, None] - g[:, None], axis=3)
        d_local = np.linalg.norm(l[:, :, None] - l[:, None], axis=3)
        compatible = self.criterion.compatible(d_global, d_local)
        pair = valid[:, :, None] & valid[:, None, :] & ~np.eye(members.shape[1], dtype=bool)
        return np.all(compatible | ~pair, axis=(1, 2))

    def _revalidate(self, stale: np.ndarray, moved: set[int]) -> np.ndarray:
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
            keep[check] = self._gate_of_sets(members[check])
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
            unions = _union_rows(self._members, self._size, rows_a, rows_b)
            _, first, group = np.unique(unions, axis=0, return_index=True, return_inverse=True)
            best = np.full(len(first), -np.inf)
            np.maximum.at(best, group.ravel(), scores)
            rows_a, rows_b, key, key2 = rows_a[first], rows_b[first], key[first], key2[first]
        if not len(rows_a):
            return None
        self._last_merge[merged] = self.step
        return _union_rows(self._members, self._size, rows_a, rows_b), best, key, key2

    def _merges(self, arguments: tuple, grouped: bool) -> list:
        arguments = (*arguments, grouped)
        found, self._merge_room = _with_room(_merges_of_frontier, arguments, self._merge_room)
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
        rows, exact = _find_by_keys(self._key, self._key2, self._members, key, key2, members)
        if exact:
            return rows
        # a key collision: look sets up by their member lists
        index = {tuple(m[m >= 0]): r for r, m in enumerate(self._members)}
        return np.array([index.get(tuple(m[m >= 0]), -1) for m in members], dtype=np.int64)

    def _append(self, members, scores, key, key2) -> np.ndarray:
        start = len(self._score)
        self._members = _stacked(self._members, members)
        if self._live_members is not None:
            self._live_members = _stacked(self._live_members, self._as_live(members))
        self._size = np.concatenate([self._size, _row_sizes(members)])
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


@njit(cache=True)
def _held(members: np.ndarray, n: int) -> np.ndarray:
    """Which of n candidates are members of some set (rows -1 padded)."""
    out = np.zeros(n, dtype=np.bool_)
    for r in range(members.shape[0]):
        for k in range(members.shape[1]):
            if members[r, k] >= 0:
                out[members[r, k]] = True
    return out


@njit(cache=True)
def _rows_of(table: np.ndarray, owner: np.ndarray, which: np.ndarray) -> np.ndarray:
    """table[owner[which]]: the rows (e.g. positions) of the given candidates' objects."""
    out = np.empty((len(which), table.shape[1]))
    for i in range(len(which)):
        row = owner[which[i]]
        for c in range(table.shape[1]):
            out[i, c] = table[row, c]
    return out


@njit(cache=True)
def _stacked(top: np.ndarray, bottom: np.ndarray) -> np.ndarray:
    """The rows of `top` then those of `bottom`, -1 padded to the wider of the two."""
    out = np.full((len(top) + len(bottom), max(top.shape[1], bottom.shape[1])), -1, np.int64)
    out[: len(top), : top.shape[1]] = top
    out[len(top) :, : bottom.shape[1]] = bottom
    return out


@njit(cache=True)
def _renumbered(members: np.ndarray, index: np.ndarray) -> np.ndarray:
    """`index[m]` for each member m (-1 padding stays -1)."""
    out = np.empty(members.shape, dtype=np.int64)
    for r in range(members.shape[0]):
        for k in range(members.shape[1]):
            m = members[r, k]
            out[r, k] = index[m] if m >= 0 else -1
    return out


@njit(cache=True)
def _row_sizes(members: np.ndarray) -> np.ndarray:
    """The number of members (entries >= 0) of each row."""
    out = np.zeros(members.shape[0], dtype=np.int64)
    for r in range(members.shape[0]):
        for k in range(members.shape[1]):
            out[r] += members[r, k] >= 0
    return out


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


# ---------------------------------------------------------------------------------------------
# Compiled inner loops of the clustering round (numba; compiled once, cached on disk)
@njit(cache=True)
def _merges_of_frontier(
    frontier,
    in_frontier,
    members,
    size,
    score,
    indptr,
    indices,
    global_xyz,
    local_xyz,
    cand_key,
    cand_key2,
    set_key,
    set_key2,
    floor,
    min_distance,
    upper_bound,
    grouped,
    capacity,
):
    """The merges (A, B) of one iteration with A in the frontier: which sets merged, and per
    distinct union (by its first key; with `grouped`, else per merge) one merge's rows, the
    largest merge score v_A + v_B + Σ h over the new cross pairs, and the two keys; then
    whether two unions shared a first key but not the second (then call again ungrouped);
    last, whether `capacity` unions were too few (then call again with more: `_with_room`).
    A merge whose score bound cannot beat its union's best so far is not scored.

    `members` are the pool's sets in live-candidate indices (-1 padded), `indptr`/`indices`
    the compatibility graph over the live candidates.  E(A), the candidates compatible with
    every member of A, is found by counting over the members' neighbourhoods; B qualifies
    when B∖A ⊆ E(A) and B∖A ≠ ∅ ≠ A∖B (then all new cross pairs are compatible), and only
    sets meeting E(A) are looked at (an inverted index candidate -> sets).  Two frontier
    sets are tried from the lower row only; merges whose score bound cannot reach `floor`
    are skipped.
    """
    n_sets, width = members.shape
    n_live = len(indptr) - 1
    # every set is filed under one pivot, its member held by the fewest sets: a set inside
    # M(A) has its pivot in M(A), so only the lists of M(A)'s candidates are looked at
    held = np.zeros(n_live, dtype=np.int64)
    for r in range(n_sets):
        for k in range(size[r]):
            held[members[r, k]] += 1
    pivot = np.empty(n_sets, dtype=np.int64)
    count = np.zeros(n_live + 1, dtype=np.int64)
    for r in range(n_sets):
        best = members[r, 0]
        for k in range(1, size[r]):
            m = members[r, k]
            if held[m] < held[best]:
                best = m
        pivot[r] = best
        count[best + 1] += 1
    starts = np.cumsum(count)
    fill = starts[:-1].copy()
    filed = np.empty(n_sets, dtype=np.int64)
    for r in range(n_sets):
        filed[fill[pivot[r]]] = r
        fill[pivot[r]] += 1
    # a 64-bit signature per set (one bit per member, from its key): B ⊆ M(A) needs
    # sig(B) ⊆ sig(M(A)), a cheap first screen
    bit = np.empty(n_live, dtype=np.uint64)
    for c in range(n_live):
        bit[c] = np.uint64(1) << (cand_key[c] >> np.uint64(58))
    sig = np.zeros(n_sets, dtype=np.uint64)
    for r in range(n_sets):
        for k in range(size[r]):
            sig[r] |= bit[members[r, k]]
    hits = np.zeros(n_live, dtype=np.int64)
    touched = np.empty(n_live, dtype=np.int64)
    ext = np.empty(n_live, dtype=np.int64)
    ext_stamp = np.full(n_live, -1, dtype=np.int64)
    ext_at = np.zeros(n_live, dtype=np.int64)
    own_stamp = np.full(n_live, -1, dtype=np.int64)
    own_at = np.zeros(n_live, dtype=np.int64)
    h = np.empty(1024)
    h_known = np.zeros(n_live, dtype=np.bool_)
    new_at = np.empty(width, dtype=np.int64)
    kept = np.zeros(width, dtype=np.bool_)
    merged = np.zeros(n_sets, dtype=np.bool_)
    out_a = np.empty(capacity, dtype=np.int64)
    out_b = np.empty(capacity, dtype=np.int64)
    out_score = np.empty(capacity)
    out_key = np.empty(capacity, dtype=np.uint64)
    out_key2 = np.empty(capacity, dtype=np.uint64)
    n_out = 0
    table = np.full(2 * capacity, -1, dtype=np.int64)  # first key -> union (open addressing)
    for a in frontier:
        n_a = size[a]
        n_touched = 0
        for k in range(n_a):
            m = members[a, k]
            for p in range(indptr[m], indptr[m + 1]):
                c = indices[p]
                if hits[c] == 0:
                    touched[n_touched] = c
                    n_touched += 1
                hits[c] += 1
        n_ext = 0
        for t in range(n_touched):
            c = touched[t]
            if hits[c] == n_a:  # members of A are compatible with the |A| - 1 others only
                ext_stamp[c] = a
                ext_at[c] = n_ext
                ext[n_ext] = c
                n_ext += 1
            hits[c] = 0
        if n_ext == 0:
            continue
        outside = sig[a]
        for j in range(n_ext):
            outside |= bit[ext[j]]
        outside = ~outside
        for k in range(n_a):
            own_stamp[members[a, k]] = a
            own_at[members[a, k]] = k
        if n_a * n_ext > len(h):
            h = np.empty(2 * n_a * n_ext)
        for j in range(n_ext):
            h_known[j] = False
        for j in range(n_a + n_ext):
            x = members[a, j] if j < n_a else ext[j - n_a]
            for p in range(starts[x], starts[x + 1]):
                b = filed[p]
                if b == a or (in_frontier[b] and b < a) or sig[b] & outside:
                    continue
                n_new, shared, ok = 0, 0, True
                key = set_key[a]
                key2 = set_key2[a]
                for k in range(n_a):
                    kept[k] = False
                for k in range(size[b]):
                    m = members[b, k]
                    if ext_stamp[m] == a:
                        new_at[n_new] = ext_at[m]
                        n_new += 1
                        key += cand_key[m]
                        key2 += cand_key2[m]
                    elif own_stamp[m] == a:
                        kept[own_at[m]] = True
                        shared += 1
                    else:
                        ok = False
                        break
                if not ok or shared >= n_a or n_new == 0:
                    continue
                base = score[a] + score[b]
                bound = base + upper_bound * (n_a - shared) * n_new
                if bound < floor:
                    continue
                merged[a] = True
                merged[b] = True
                g = n_out
                if grouped:
                    at = np.int64(key & np.uint64(len(table) - 1))
                    while table[at] >= 0 and out_key[table[at]] != key:
                        at = (at + 1) & (len(table) - 1)
                    if table[at] >= 0:
                        g = table[at]
                        if out_key2[g] != key2:
                            return (
                                merged,
                                out_a[:0],
                                out_b[:0],
                                out_score[:0],
                                out_key[:0],
                                out_key2[:0],
                                True,
                                False,
                            )
                if g == n_out:  # a new union (or, ungrouped, a new merge)
                    if n_out == capacity:  # no room: the caller calls again with more
                        return merged, out_a[:0], out_b[:0], out_score[:0], out_key[:0], out_key2[:0], False, True  # fmt: skip
                    if grouped:
                        table[at] = g
                    out_a[g] = a
                    out_b[g] = b
                    out_score[g] = -np.inf
                    out_key[g] = key
                    out_key2[g] = key2
                    n_out += 1
                elif bound <= out_score[g]:
                    continue
                cross = 0.0
                for q in range(n_new):
                    j = new_at[q]
                    if not h_known[j]:  # h(a_k, e_j), the paper's ratio, when first needed
                        for k in range(n_a):
                            h[k * n_ext + j] = _ratio(
                                global_xyz, local_xyz, members[a, k], ext[j], min_distance
                            )
                        h_known[j] = True
                for k in range(n_a):
                    if not kept[k]:
                        for q in range(n_new):
                            cross += h[k * n_ext + new_at[q]]
                out_score[g] = max(out_score[g], base + cross)
    return (
        merged,
        out_a[:n_out],
        out_b[:n_out],
        out_score[:n_out],
        out_key[:n_out],
        out_key2[:n_out],
        False,
        False,
    )


@njit(cache=True)
def _ratio(global_xyz, local_xyz, i, j, min_distance):
    """The paper's h of live candidates i and j (as `merge_metric` with no tolerance)."""
    d_global = np.sqrt(
        (global_xyz[i, 0] - global_xyz[j, 0]) ** 2
        + (global_xyz[i, 1] - global_xyz[j, 1]) ** 2
        + (global_xyz[i, 2] - global_xyz[j, 2]) ** 2
    )
    d_local = np.sqrt(
        (local_xyz[i, 0] - local_xyz[j, 0]) ** 2
        + (local_xyz[i, 1] - local_xyz[j, 1]) ** 2
        + (local_xyz[i, 2] - local_xyz[j, 2]) ** 2
    )
    d_max = max(d_global, d_local)
    if d_max < min_distance or d_max <= 0:
        return 1.0
    return 1.0 - abs(d_global - d_local) / d_max


@njit(cache=True)
def _union_rows(members, size, rows_a, rows_b):
    """The members of A ∪ B for each merge, ascending and -1 padded (rows are ascending)."""
    n = len(rows_a)
    width = 1
    for i in range(n):
        width = max(width, size[rows_a[i]] + size[rows_b[i]])
    out = np.full((n, width), -1, dtype=np.int64)
    longest = 1
    for i in range(n):
        a, b = rows_a[i], rows_b[i]
        p, q, k = 0, 0, 0
        while p < size[a] or q < size[b]:
            x = members[a, p] if p < size[a] else np.iinfo(np.int64).max
            y = members[b, q] if q < size[b] else np.iinfo(np.int64).max
            if x <= y:
                out[i, k] = x
                p += 1
                if x == y:
                    q += 1
            else:
                out[i, k] = y
                q += 1
            k += 1
        longest = max(longest, k)
    return out[:, :longest]


@njit(cache=True)
def _compatible_among(added, covered, cand_g, cand_l, global_xyz, local_distance, tolerance,
                      gamma, min_distance, capacity):  # fmt: skip
    """The compatible pairs (a, b), a in `added`, b in `covered` or later in `added` (2 x E):
    other local and global objects, and the gate of `MergeCriterion.compatible`; then whether
    `capacity` pairs were too few (the pairs are then incomplete, see `_with_room`)."""
    out = np.empty((2, capacity), dtype=np.int64)
    n = 0
    for i in range(len(added)):
        x = added[i]
        for k in range(len(covered) + len(added) - i - 1):
            y = covered[k] if k < len(covered) else added[i + 1 + k - len(covered)]
            if cand_l[x] == cand_l[y] or cand_g[x] == cand_g[y]:
                continue
            gx, gy = cand_g[x], cand_g[y]
            d_global = _distance(global_xyz, gx, gy)
            d_local = local_distance[cand_l[x], cand_l[y]]
            if not _gate(d_global, d_local, tolerance, gamma, min_distance):
                continue
            if n == capacity:  # no room: the caller calls again with more
                return out[:, :0], True
            out[0, n] = x
            out[1, n] = y
            n += 1
    return out[:, :n], False


@njit(cache=True)
def _distance(xyz, i, j):
    """Euclidean distance of rows i and j of xyz."""
    return np.sqrt(
        (xyz[i, 0] - xyz[j, 0]) ** 2 + (xyz[i, 1] - xyz[j, 1]) ** 2 + (xyz[i, 2] - xyz[j, 2]) ** 2
    )


@njit(cache=True)
def _gate(d_global, d_local, tolerance, gamma, min_distance):
    """`MergeCriterion.compatible` for one pair of distances."""
    d_max = max(d_global, d_local)
    if d_max < min_distance or d_max <= 0:
        return gamma < 1.0
    excess = max(abs(d_global - d_local) - tolerance, 0.0)
    return 1.0 - excess / d_max > gamma


@njit(cache=True)
def _compatible_sweep(
    added,
    covered,
    cand_g,
    cand_l,
    global_xyz,
    local_distance,
    reach,
    tolerance,
    gamma,
    min_distance,
    axis,
    cross_axis,
    rank,
    n_ranks,
    window_entries,
    capacity,
):
    """`_compatible_among` for many candidates: per local object, its candidates sorted along
    the map's longest axis `axis` (by `rank`, the global objects' dense rank along it); a
    candidate of `la` is tested only against those of `lb` within `reach[la, lb]` along it and
    along the second longest axis `cross_axis` (necessary conditions of the gate; the second
    is read from a copy in sweep order, so most misses cost no distance).  Where each window
    starts is found for all candidates of `la` at once, walking them in sweep order along
    those of `lb` (a merge, not a binary search per candidate), unless that table would have
    more than `window_entries` entries (many objects added at once: then binary searches).
    Returns as `_compatible_among` does."""
    n_local = len(local_distance)
    everyone = np.concatenate((covered, added))
    slot = np.zeros(n_ranks + 1, dtype=np.int64)  # counting sort by rank: stable, as mergesort
    for c in everyone:
        slot[rank[cand_g[c]] + 1] += 1
    for i in range(n_ranks):
        slot[i + 1] += slot[i]
    order = np.empty(len(everyone), dtype=np.int64)
    for k in range(len(everyone)):
        r = rank[cand_g[everyone[k]]]
        order[slot[r]] = k
        slot[r] += 1
    count = np.zeros(n_local + 1, dtype=np.int64)
    for c in everyone:
        count[cand_l[c] + 1] += 1
    starts = np.cumsum(count)
    fill = starts[:-1].copy()
    by_local = np.empty(len(everyone), dtype=np.int64)
    for k in order:
        c = everyone[k]
        by_local[fill[cand_l[c]]] = c
        fill[cand_l[c]] += 1
    sorted_x = global_xyz[cand_g[by_local], axis]
    sorted_cross = global_xyz[cand_g[by_local], cross_axis]
    added_at = np.full(len(cand_g), -1, dtype=np.int64)
    for i in range(len(added)):
        added_at[added[i]] = i
    merged = len(added) * n_local <= window_entries
    window = np.empty((0, 0), dtype=np.int64)
    if merged:
        window = _window_starts(
            added, cand_g, cand_l, global_xyz, reach, axis, order, starts, sorted_x
        )
    out = np.empty((2, capacity), dtype=np.int64)
    n = 0
    for i in range(len(added)):
        x = added[i]
        la, gx = cand_l[x], cand_g[x]
        for lb in range(n_local):
            if lb == la or starts[lb] == starts[lb + 1]:
                continue
            r = reach[la, lb]
            lo, hi = starts[lb], starts[lb + 1]
            if merged:
                p = window[i, lb]
            else:
                p = lo + np.searchsorted(sorted_x[lo:hi], global_xyz[gx, axis] - r)
            while p < hi and sorted_x[p] <= global_xyz[gx, axis] + r:
                p += 1
                if abs(sorted_cross[p - 1] - global_xyz[gx, cross_axis]) > r:
                    continue
                y = by_local[p - 1]
                if added_at[y] >= 0 and added_at[y] <= i:  # pairs within `added` once
                    continue
                gy = cand_g[y]
                if gx == gy:
                    continue
                d_global = _distance(global_xyz, gx, gy)
                if not _gate(d_global, local_distance[la, lb], tolerance, gamma, min_distance):
                    continue
                if n == capacity:  # no room: the caller calls again with more
                    return out[:, :0], True
                out[0, n] = x
                out[1, n] = y
                n += 1
    return out[:, :n], False


@njit(cache=True)
def _window_starts(added, cand_g, cand_l, global_xyz, reach, axis, order, starts, sorted_x):
    """For each added candidate i (of local object la) and local object lb: the first row p of
    lb's candidates in sweep order (rows starts[lb]..starts[lb + 1] of `sorted_x`) with
    sorted_x[p] >= its coordinate along `axis` less reach[la, lb], i.e. the binary search's
    answer.  `order` is the sweep order of covered + added (added last), so each local
    object's added candidates are walked in ascending coordinate, and the row only advances."""
    n_local = len(starts) - 1
    n_covered = len(order) - len(added)
    count = np.zeros(n_local + 1, dtype=np.int64)
    for i in range(len(added)):
        count[cand_l[added[i]] + 1] += 1
    first = np.cumsum(count)
    fill = first[:-1].copy()
    in_order = np.empty(len(added), dtype=np.int64)  # per local object, in sweep order
    for k in order:
        if k >= n_covered:
            la = cand_l[added[k - n_covered]]
            in_order[fill[la]] = k - n_covered
            fill[la] += 1
    window = np.empty((len(added), n_local), dtype=np.int64)
    for la in range(n_local):
        for lb in range(n_local):
            if lb == la:
                continue
            p, hi = starts[lb], starts[lb + 1]
            for q in range(first[la], first[la + 1]):
                i = in_order[q]
                at = global_xyz[cand_g[added[i]], axis] - reach[la, lb]
                while p < hi and sorted_x[p] < at:
                    p += 1
                window[i, lb] = p
    return window


@njit(cache=True)
def _find_by_keys(pool_key, pool_key2, pool_members, key, key2, members):
    """The pool row with each given first key (-1: none), and whether that is exact: the
    pool's first keys are distinct and every hit has the same second key and members."""
    n = len(pool_key)
    slots = 1
    while slots < 2 * n:
        slots *= 2
    mask = np.uint64(slots - 1)
    table = np.full(slots, -1, dtype=np.int64)
    rows = np.full(len(key), -1, dtype=np.int64)
    for r in range(n):
        at = np.int64(pool_key[r] & mask)
        while table[at] >= 0:
            if pool_key[table[at]] == pool_key[r]:
                return rows, False
            at = (at + 1) & (slots - 1)
        table[at] = r
    width = min(members.shape[1], pool_members.shape[1])
    for i in range(len(key)):
        at = np.int64(key[i] & mask)
        while table[at] >= 0 and pool_key[table[at]] != key[i]:
            at = (at + 1) & (slots - 1)
        r = table[at]
        if r < 0:
            continue
        if pool_key2[r] != key2[i]:
            return rows, False
        for k in range(width):
            if pool_members[r, k] != members[i, k]:
                return rows, False
        for k in range(width, members.shape[1]):
            if members[i, k] >= 0:
                return rows, False
        for k in range(width, pool_members.shape[1]):
            if pool_members[r, k] >= 0:
                return rows, False
        rows[i] = r
    return rows, True


@njit(cache=True)
def _kept_edges(edges, is_covered, new_edges):
    """The edges (2 x E) between covered candidates, then `new_edges`, in order."""
    kept = 0
    for i in range(edges.shape[1]):
        kept += is_covered[edges[0, i]] and is_covered[edges[1, i]]
    out = np.empty((2, kept + new_edges.shape[1]), dtype=np.int64)
    e = 0
    for i in range(edges.shape[1]):
        if is_covered[edges[0, i]] and is_covered[edges[1, i]]:
            out[:, e] = edges[:, i]
            e += 1
    out[:, kept:] = new_edges
    return out


@njit(cache=True)
def _symmetric_csr(edges, index, n):
    """CSR rows (indptr, indices) over n nodes of the graph with edges (2 x E) between
    candidates, both ways; `index` maps a candidate to its node."""
    count = np.zeros(n + 1, dtype=np.int64)
    for i in range(edges.shape[1]):
        count[index[edges[0, i]] + 1] += 1
        count[index[edges[1, i]] + 1] += 1
    indptr = np.cumsum(count)
    fill = indptr[:-1].copy()
    indices = np.empty(2 * edges.shape[1], dtype=np.int64)
    for i in range(edges.shape[1]):
        u, v = index[edges[0, i]], index[edges[1, i]]
        indices[fill[u]] = v
        fill[u] += 1
        indices[fill[v]] = u
        fill[v] += 1
    return indptr, indices
