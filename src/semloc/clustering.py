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
    A boolean compatibility matrix C over candidates holds h(a, b) > γ for one-to-one pairs
    (C[a, a] = True).  Every set is a clique of C (singletons trivially; a merge only joins
    sets whose new cross pairs are all compatible), so D1 ∪ D2 passes the literal test exactly
    when D2 ⊆ M(D1) = ⋂_{a ∈ D1} C[a].  Sets are bitsets over candidates (rows of uint64
    words), M(D) is kept per set, and the test is a vectorised `D2 & ~M(D1) == 0`, read
    from D2's short member list.  The merges of an iteration are grouped by union through an
    additive set hash (hash(A ∪ B) = hash(A) + Σ over B∖A), checked by a second hash and,
    on disagreement, by the bitsets themselves.

Where the paper is silent (see also DESIGN.md)
    * "Marking merged sets": every pair of sets is tried once.  A clustering round works on a
      frontier: in each iteration only pairs with at least one set created in the previous
      iteration (or at this update) are tried; iterations run until no new set appears.
      Within an iteration all merges use the scores from its start, so the result does not
      depend on the order of objects.
    * K is capped by `max_sets` (default 2000, None for the paper's 10·n): the merge search
      costs about K² per iteration, so a 1000-object map would otherwise spend seconds per
      update once 15+ local objects are in.
    * Top-K pruning happens after every iteration (bounding work and memory), with ties broken
      by size and then by an order-independent hash of the set's (global id, local id) pairs.
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

import hashlib
from dataclasses import dataclass

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

_CHUNK_ELEMENTS = 1 << 22  # bound on the (frontier x pool x words) intermediate arrays


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
        description="Upper bound on K (work grows with K²); None keeps the paper's 10·n.",
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


def _pack_rows(matrix: np.ndarray, words: int) -> np.ndarray:
    """Pack a boolean matrix (rows x columns) into rows of `words` little-endian uint64."""
    rows = matrix.shape[0]
    padded = np.zeros((rows, words * 64), dtype=bool)
    padded[:, : matrix.shape[1]] = matrix
    return np.packbits(padded, axis=1, bitorder="little").view(np.uint64).reshape(rows, words)


def _unpack_rows(bits: np.ndarray, columns: int) -> np.ndarray:
    flat = np.unpackbits(bits.view(np.uint8), axis=1, bitorder="little")
    return flat[:, :columns].astype(bool)


def _members(bits: np.ndarray, columns: int) -> np.ndarray:
    """Member candidate indices per row, padded with -1 (rows x max size)."""
    mask = _unpack_rows(bits, columns)
    sizes = mask.sum(axis=1)
    width = max(int(sizes.max(initial=0)), 1)
    out = np.full((len(bits), width), -1, dtype=np.int64)
    rows, cols = np.nonzero(mask)
    slot = np.arange(len(rows)) - np.repeat(np.cumsum(sizes) - sizes, sizes)
    out[rows, slot] = cols
    return out


def _pair_hash(global_id: str, local_id: str) -> np.uint64:
    digest = hashlib.blake2b(f"{global_id}\x00{local_id}".encode(), digest_size=8).digest()
    return np.frombuffer(digest, dtype=np.uint64)[0]


class HierarchicalClustering:
    """The pool of association sets over a growing local map, grown incrementally.

    `global_positions` and `global_ids` describe the global map; `update()` receives the
    positions of all local objects so far and the candidate global indices of the local
    objects that are new or re-detected at this update.
    """

    def __init__(
        self,
        global_positions: np.ndarray,
        global_ids: list[str],
        config: ClusteringConfig | None = None,
    ) -> None:
        self.config = config or ClusteringConfig()
        self.criterion = MergeCriterion.of(self.config)
        self._global_positions = np.asarray(global_positions, dtype=float)
        self._global_ids = list(global_ids)
        self.capacity = self.config.sets_per_object * max(len(self._global_ids), 1)
        if self.config.max_sets is not None:
            self.capacity = min(self.capacity, self.config.max_sets)
        self.step = 0
        # candidates
        self._cand_g = np.zeros(0, dtype=np.int64)
        self._cand_l = np.zeros(0, dtype=np.int64)
        self._cand_hash = np.zeros(0, dtype=np.uint64)
        self._cand_alive = np.zeros(0, dtype=bool)
        self._cand_index: dict[tuple[int, int], int] = {}
        self._cands_of_local: dict[int, dict[int, int]] = {}
        self._local_positions = np.zeros((0, 3))
        self._local_ids: list[str] = []
        self._h = np.zeros((0, 0))
        self._compat = np.zeros((0, 0), dtype=bool)
        self._compat_bits = np.zeros((0, 1), dtype=np.uint64)
        # sets
        self._words = 1
        self._bits = np.zeros((0, 1), dtype=np.uint64)
        self._common = np.zeros((0, 1), dtype=np.uint64)
        self._members = np.full((0, 1), -1, dtype=np.int64)
        self._score = np.zeros(0)
        self._last_merge = np.zeros(0, dtype=np.int64)
        self._row_of: dict[bytes, int] = {}

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
        return [self._set(row) for row in self._ranking()]

    def top(self, k: int, min_size: int = 1, largest_first: bool = False) -> list[AssociationSet]:
        """The k best sets with at least `min_size` pairs (by score, or by size then score)."""
        ranking = self._ranking()
        size = (self._members[ranking] >= 0).sum(axis=1)
        if largest_first:
            order = np.argsort(-size, kind="stable")
            ranking, size = ranking[order], size[order]
        return [self._set(row) for row in ranking[size >= min_size][:k]]

    def _set(self, row: int) -> AssociationSet:
        members = self._members[row][self._members[row] >= 0]
        pairs = tuple(sorted((int(self._cand_g[c]), int(self._cand_l[c])) for c in members))
        return AssociationSet(pairs, float(self._score[row]), int(self._last_merge[row]))

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
        moved = self._moved_locals(np.asarray(local_positions, dtype=float), detections)
        self._local_positions = np.asarray(local_positions, dtype=float).reshape(-1, 3)
        self._local_ids = list(local_ids)
        stale = self._register_candidates(detections)
        self._refresh_compatibility(set(detections), stale)
        fresh_rows = self._revalidate(stale, moved)
        fresh_rows += self._add_singletons(detections)
        self._cluster(np.unique(np.array(fresh_rows, dtype=np.int64)))
        self._expire()

    def _moved_locals(self, positions: np.ndarray, detections: dict[int, np.ndarray]) -> set[int]:
        known = len(self._local_positions)
        return {
            local
            for local in detections
            if local < known
            and np.linalg.norm(positions[local] - self._local_positions[local]) > 1e-6
        }

    def _register_candidates(self, detections: dict[int, np.ndarray]) -> set[int]:
        """Add new candidate pairs; return candidates that a re-detection no longer allows."""
        stale: set[int] = set()
        new_g, new_l = [], []
        for local, globals_ in detections.items():
            allowed = {int(g) for g in globals_}
            known = self._cands_of_local.setdefault(local, {})
            stale.update(c for g, c in known.items() if g not in allowed)
            for g in sorted(allowed):
                if g in known:
                    self._cand_alive[known[g]] = True
                else:
                    known[g] = self._cand_index[(g, local)] = len(self._cand_g) + len(new_g)
                    new_g.append(g)
                    new_l.append(local)
        if new_g:
            hashes = [
                _pair_hash(self._global_ids[g], self._local_ids[l]) for g, l in zip(new_g, new_l)
            ]
            self._cand_g = np.concatenate([self._cand_g, new_g]).astype(np.int64)
            self._cand_l = np.concatenate([self._cand_l, new_l]).astype(np.int64)
            self._cand_hash = np.concatenate([self._cand_hash, np.array(hashes, np.uint64)])
            self._cand_alive = np.concatenate([self._cand_alive, np.ones(len(new_g), bool)])
        self._cand_alive[list(stale)] = False
        return stale

    def _refresh_compatibility(self, detected: set[int], stale: set[int]) -> None:
        """Update h and compatibility for the candidates of detected objects and stale ones."""
        n, known = len(self._cand_g), len(self._h)
        rows = np.union1d(
            np.arange(known, n),
            np.flatnonzero(
                np.isin(self._cand_l, list(detected)) | np.isin(np.arange(n), list(stale))
            ),
        ).astype(np.int64)
        h = np.zeros((n, n))
        h[:known, :known] = self._h
        compat = np.zeros((n, n), dtype=bool)
        compat[:known, :known] = self._compat
        if len(rows):
            h_rows, compat_rows = self._pair_rows(rows)
            h[rows], h[:, rows] = h_rows, h_rows.T
            compat[rows], compat[:, rows] = compat_rows, compat_rows.T
        np.fill_diagonal(compat, True)
        self._h, self._compat = h, compat
        words = max(1, -(-n // 64))
        self._compat_bits = np.vstack(
            [_pack_rows(compat, words), np.full((1, words), ~np.uint64(0))]
        )  # the last row (all ones) serves as padding for member lists
        if words != self._words:
            self._bits = np.hstack(
                [self._bits, np.zeros((len(self._bits), words - self._words), np.uint64)]
            )
            self._words = words
        self._common = self._common_of(self._members)
        self._row_of = {self._bits[r].tobytes(): r for r in range(len(self._bits))}

    def _pair_rows(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """h and compatibility of the candidates `rows` against all candidates."""
        g, l = self._cand_g, self._cand_l
        d_global = np.linalg.norm(
            self._global_positions[g[rows]][:, None] - self._global_positions[g][None], axis=2
        )
        d_local = np.linalg.norm(
            self._local_positions[l[rows]][:, None] - self._local_positions[l][None], axis=2
        )
        one_to_one = (g[rows][:, None] != g[None]) & (l[rows][:, None] != l[None])
        h = np.where(one_to_one, self.criterion.score(d_global, d_local), 0.0)
        alive = self._cand_alive
        compatible = self.criterion.compatible(d_global, d_local)
        compat = compatible & one_to_one & alive[rows][:, None] & alive[None]
        return h, compat

    def _common_of(self, members: np.ndarray) -> np.ndarray:
        padded = np.where(members >= 0, members, len(self._compat_bits) - 1)
        return np.bitwise_and.reduce(self._compat_bits[padded], axis=1)

    def _revalidate(self, stale: set[int], moved: set[int]) -> list[int]:
        """Drop sets with stale candidates or broken cliques; sets with moved objects are fresh."""
        if not len(self._score):
            return []
        members = self._members
        valid = members >= 0
        has_stale = np.isin(members, list(stale)) & valid
        is_clique = np.all((self._bits & ~self._common) == 0, axis=1)
        keep = ~has_stale.any(axis=1) & is_clique
        touched = np.isin(self._cand_l[np.where(valid, members, 0)], list(moved)) & valid
        self._keep_rows(keep)
        return list(np.flatnonzero(touched.any(axis=1)[keep]))

    def _add_singletons(self, detections: dict[int, np.ndarray]) -> list[int]:
        """Add (or refresh) the singleton of every candidate of the detected objects."""
        candidates = sorted(
            self._cand_index[(g, local)]
            for local, globals_ in detections.items()
            for g in {int(x) for x in globals_}
        )
        if not candidates:
            return []
        bits = np.zeros((len(candidates), self._words), np.uint64)
        index = np.array(candidates)
        bits[np.arange(len(index)), index // 64] = np.uint64(1) << (index % 64).astype(np.uint64)
        rows = [self._row_of.get(row.tobytes(), -1) for row in bits]
        missing = [i for i, row in enumerate(rows) if row < 0]
        if missing:
            added = self._append(bits[missing], index[missing, None], np.zeros(len(missing)))
            for i, row in zip(missing, added):
                rows[i] = int(row)
        self._last_merge[rows] = self.step
        return rows

    # ------------------------------------------------------------------------------------
    # Clustering round
    def _cluster(self, frontier: np.ndarray) -> None:
        while len(frontier):
            bits = _dense(self._bits)  # the pool is fixed until the insert below
            parents_a, parents_b = self._find_merges(frontier, bits)
            if not len(parents_a):
                break
            self._last_merge[parents_a] = self.step
            self._last_merge[parents_b] = self.step
            unions, scores = self._best_merges(parents_a, parents_b, bits)
            frontier = self._insert(unions, scores)
            frontier = self._prune(frontier)
        self._prune(np.zeros(0, dtype=np.int64))  # a round ends with at most K sets

    def _find_merges(self, frontier: np.ndarray, bits: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """All (a, b) rows with a in the frontier whose union passes the merge criterion
        (`bits`: the pool's sets as a dense boolean matrix)."""
        n_pool = len(self._bits)
        in_frontier = np.zeros(n_pool, dtype=bool)
        in_frontier[frontier] = True
        chunk = max(1, _CHUNK_ELEMENTS // max(n_pool, 1))
        size = (self._members >= 0).sum(axis=1)
        floor = self._survival_floor()
        folded_bits = np.bitwise_or.reduce(self._bits, axis=1)
        folded_common = np.bitwise_or.reduce(self._common, axis=1)
        common = _dense(self._common)
        found_a, found_b = [], []
        for start in range(0, len(frontier), chunk):
            rows = frontier[start : start + chunk]
            # b ⊆ M(a) (the union is a clique); folding the words with OR keeps ⊆, so a
            # one-word test screens the pairs before the exact test on every word
            ia, ib = np.nonzero((folded_bits[None, :] & ~folded_common[rows][:, None]) == 0)
            once = ~in_frontier[ib] | (ib > rows[ia])  # two frontier sets: tried from the lower
            ia, ib = ia[once], ib[once]
            if floor > -np.inf:  # merges that cannot reach the top K would be pruned at once
                bound = self.criterion.UPPER_BOUND * size[rows[ia]] * size[ib]
                fits = self._score[rows[ia]] + self._score[ib] + bound >= floor
                ia, ib = ia[fits], ib[fits]
            ia = rows[ia]
            b_members = self._members[ib]
            inside = _contains_rows(common, ia, b_members) | (b_members < 0)
            exact = np.all(inside, axis=1)
            ia, ib = ia[exact], ib[exact]
            a_adds, b_adds = self._adds(bits, ia, ib, size)[:2]
            keep = (a_adds > 0) & (b_adds > 0)  # neither contains the other
            if floor > -np.inf:
                bound = self.criterion.UPPER_BOUND * a_adds * b_adds
                keep &= self._score[ia] + self._score[ib] + bound >= floor
            found_a.append(ia[keep])
            found_b.append(ib[keep])
        return np.concatenate(found_a), np.concatenate(found_b)

    def _survival_floor(self) -> float:
        """The K-th best score in the pool (-inf while the pool is not full), less a hair.

        A merge scores at most v_A + v_B + |A|·|B| (h ≤ UPPER_BOUND = 1).  One that cannot reach the K-th
        best score is pruned at the end of the iteration, and so are both of its parents
        (their scores are lower still), so such merges are skipped without changing the result.
        """
        if len(self._score) < self.capacity:
            return -np.inf
        kth = np.partition(self._score, len(self._score) - self.capacity)
        return float(kth[len(self._score) - self.capacity]) - 1e-9

    def _best_merges(
        self, rows_a: np.ndarray, rows_b: np.ndarray, bits: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Distinct unions of the merges and, for each, the largest merge score.

        A merge scores v_A + v_B + Σh over |A∖B|·|B∖A| new pairs with h ≤ 1, which bounds it
        from above.  Per union, one merge (the largest v_A + v_B) is scored exactly; only the
        merges whose bound beats that score need their own exact score.  Same result as scoring
        every merge, at a fraction of the work.
        """
        size = (self._members >= 0).sum(axis=1)
        a_adds, b_adds, b_new = self._adds(bits, rows_a, rows_b, size)
        first, group = self._group_unions(rows_a, rows_b, b_new)
        unions = self._bits[rows_a[first]] | self._bits[rows_b[first]]
        base = self._score[rows_a] + self._score[rows_b]
        bound = base + self.criterion.UPPER_BOUND * a_adds * b_adds
        order = np.lexsort((-base, group))  # per group, the largest v_A + v_B first
        first = order[np.r_[True, group[order][1:] != group[order][:-1]]]
        best = np.full(len(unions), -np.inf)
        best[group[first]] = base[first] + self._cross_sum(bits, rows_a[first], rows_b[first])
        todo = np.flatnonzero(bound > best[group] + 1e-12)
        if len(todo):
            exact = base[todo] + self._cross_sum(bits, rows_a[todo], rows_b[todo])
            np.maximum.at(best, group[todo], exact)
        return unions, best

    def _adds(self, bits: np.ndarray, rows_a: np.ndarray, rows_b: np.ndarray, size: np.ndarray):
        """|A∖B|, |B∖A| and B's members not in A (-1 elsewhere), for each merge (A, B).

        Read from B's short member list against A's bitset: (merges x members) lookups
        instead of whole (merges x words) bitset operations.
        """
        b_members = self._members[rows_b]
        b_new = (b_members >= 0) & ~_contains_rows(bits, rows_a, b_members)
        b_adds = b_new.sum(axis=1)
        return size[rows_a] - size[rows_b] + b_adds, b_adds, np.where(b_new, b_members, -1)

    def _group_unions(self, rows_a, rows_b, b_new) -> tuple[np.ndarray, np.ndarray]:
        """One representative merge per distinct union A ∪ B, and each merge's group.

        A set's hash is the wrapping sum of its candidates' 64-bit hashes, so hash(A ∪ B) =
        hash(A) + Σ over B∖A (`b_new`: those members, -1 padded); a second, independent sum
        checks every group, and the bitsets themselves are compared if the two disagree.
        """
        keys = []
        for table in (self._cand_hash, _mix(self._cand_hash)):
            keys.append(_hash_sums(table, self._members)[rows_a] + _hash_sums(table, b_new))
        key, check = keys
        order = np.argsort(key)
        starts = np.r_[True, key[order][1:] != key[order][:-1]]
        group = np.empty(len(key), dtype=np.int64)
        group[order] = np.cumsum(starts) - 1
        first = order[starts]
        if np.array_equal(check, check[first][group]):
            return first, group
        unions = self._bits[rows_a] | self._bits[rows_b]  # a hash collision: exact path
        _, first, group = np.unique(unions, axis=0, return_index=True, return_inverse=True)
        return first, group.ravel()

    def _cross_sum(self, bits: np.ndarray, rows_a: np.ndarray, rows_b: np.ndarray) -> np.ndarray:
        """Σ h over the new cross pairs (a ∈ A∖B, b ∈ B∖A) for each merge (A, B).

        Each merge is oriented so that its smaller set is indexed by a short member list;
        merges are grouped by that size, keeping the gathers at (merges x large x small).
        """
        size = (self._members >= 0).sum(axis=1)
        swap = size[rows_a] < size[rows_b]
        large = np.where(swap, rows_b, rows_a)
        small = np.where(swap, rows_a, rows_b)
        out = np.zeros(len(rows_a))
        for k in np.unique(size[small]):
            sel = np.flatnonzero(size[small] == k)
            big, little = large[sel], small[sel]
            ml = self._members[big, : size[big].max()]
            ms = self._members[little, :k]
            a_new = (ml >= 0) & ~_contains_rows(bits, little, ml)
            b_new = ~_contains_rows(bits, big, ms)
            h = self._h[np.maximum(ml, 0)[:, :, None], ms[:, None, :]]
            out[sel] = np.sum(h * (a_new[:, :, None] & b_new[:, None, :]), axis=(1, 2))
        return out

    def _insert(self, unique: np.ndarray, best: np.ndarray) -> np.ndarray:
        """Add distinct merged sets (duplicates keep the larger score); return new rows."""
        new_mask = np.ones(len(unique), dtype=bool)
        for i, row_bits in enumerate(unique):
            row = self._row_of.get(row_bits.tobytes())
            if row is not None:
                new_mask[i] = False
                self._score[row] = max(self._score[row], best[i])
        if not new_mask.any():
            return np.zeros(0, dtype=np.int64)
        added = unique[new_mask]
        members = _members(added, len(self._cand_g))
        return self._append(added, members, best[new_mask])

    def _append(self, bits: np.ndarray, members: np.ndarray, scores: np.ndarray) -> np.ndarray:
        start = len(self._bits)
        width = max(self._members.shape[1], members.shape[1])
        self._members = np.vstack([_pad(self._members, width), _pad(members, width)])
        self._bits = np.vstack([self._bits, bits])
        self._common = np.vstack([self._common, self._common_of(members)])
        self._score = np.concatenate([self._score, scores])
        self._last_merge = np.concatenate(
            [self._last_merge, np.full(len(scores), self.step, dtype=np.int64)]
        )
        rows = np.arange(start, start + len(scores))
        for r in rows:
            self._row_of[self._bits[r].tobytes()] = int(r)
        return rows

    # ------------------------------------------------------------------------------------
    # Pruning
    def _ranking(self) -> np.ndarray:
        """Rows best first: score (rounded), size, then an order-independent hash."""
        size = (self._members >= 0).sum(axis=1)
        set_hash = _hash_sums(self._cand_hash, self._members)
        return np.lexsort((set_hash, -size, -np.round(self._score, 9)))

    def _prune(self, frontier: np.ndarray) -> np.ndarray:
        """Keep the top K sets; return the surviving part of the frontier (renumbered)."""
        if len(self._score) <= self.capacity:
            return frontier
        keep = np.zeros(len(self._score), dtype=bool)
        keep[self._ranking()[: self.capacity]] = True
        is_frontier = np.zeros(len(self._score), dtype=bool)
        is_frontier[frontier] = True
        self._keep_rows(keep)
        return np.flatnonzero(is_frontier[keep])

    def _expire(self) -> None:
        old = self.step - self._last_merge > self.config.expiry_updates
        if not old.any():
            return
        protected = np.zeros(len(old), dtype=bool)
        protected[self._ranking()[: self.config.protect_top]] = True
        self._keep_rows(~old | protected)

    def _keep_rows(self, keep: np.ndarray) -> None:
        self._bits = self._bits[keep]
        self._common = self._common[keep]
        self._members = self._members[keep]
        self._score = self._score[keep]
        self._last_merge = self._last_merge[keep]
        self._row_of = {self._bits[r].tobytes(): r for r in range(len(self._bits))}


def _mix(x: np.ndarray) -> np.ndarray:
    """A bijective 64-bit mixer (splitmix64's finaliser): a second, independent hash."""
    x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return x ^ (x >> np.uint64(31))


def _hash_sums(table: np.ndarray, members: np.ndarray) -> np.ndarray:
    """Per row of member indices (-1 padded), the wrapping sum of their hashes in `table`."""
    return np.append(table, np.uint64(0))[members].sum(axis=1, dtype=np.uint64)  # -1 reads 0


def _dense(bits: np.ndarray) -> np.ndarray:
    """Bitset rows (uint64 words) as a boolean matrix over candidates."""
    return np.unpackbits(bits.astype("<u8").view(np.uint8), axis=1, bitorder="little").view(bool)


def _contains_rows(dense: np.ndarray, rows: np.ndarray, candidates: np.ndarray) -> np.ndarray:
    """Whether set `rows[i]` (of a `_dense` matrix) holds `candidates[i, j]` (-1: False)."""
    return dense[rows[:, None], np.maximum(candidates, 0)] & (candidates >= 0)


def _pad(members: np.ndarray, width: int) -> np.ndarray:
    if members.shape[1] == width:
        return members
    out = np.full((len(members), width), -1, dtype=np.int64)
    out[:, : members.shape[1]] = members
    return out
