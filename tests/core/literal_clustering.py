"""A literal, slow transcription of the paper's clustering rules — the oracle for clustering.py.

Sets are frozensets of (global index, local index) pairs.  Every merge test enumerates the new
cross pairs and evaluates h on them one by one, exactly as the paper states it; the frontier,
pruning, tie-breaking and expiry rules are the ones documented in `semloc.clustering`.
"""

from __future__ import annotations

import hashlib

import numpy as np

from semloc.clustering import ClusteringConfig, merge_metric


def pair_hash(global_id: str, local_id: str) -> int:
    """The tie-break digest of a pair, as documented: 8-byte BLAKE2b of 'global\\x00local'."""
    text = f"{global_id}\x00{local_id}".encode()
    return int.from_bytes(hashlib.blake2b(text, digest_size=8).digest(), "little")


class LiteralClustering:
    def __init__(self, global_positions, global_ids, config: ClusteringConfig) -> None:
        self.g = np.asarray(global_positions, dtype=float)
        self.gids = list(global_ids)
        self.cfg = config
        self.capacity = config.sets_per_object * len(self.gids)
        self.step = 0
        self.local = np.zeros((0, 3))
        self.lids: list[str] = []
        self.sets: dict[frozenset, list] = {}  # set -> [score, last_merge]

    def h(self, a, b, tolerance=0.0) -> float:
        (ga, la), (gb, lb) = a, b
        if ga == gb or la == lb:
            return 0.0
        d_global = np.linalg.norm(self.g[ga] - self.g[gb])
        d_local = np.linalg.norm(self.local[la] - self.local[lb])
        return float(merge_metric(d_global, d_local, tolerance, self.cfg.min_distance))

    def update(self, local_positions, local_ids, detections) -> None:
        self.step += 1
        self.local = np.asarray(local_positions, dtype=float)
        self.lids = list(local_ids)
        frontier = []
        for local, globals_ in detections.items():
            for g in sorted(set(int(x) for x in globals_)):
                key = frozenset({(g, local)})
                self.sets.setdefault(key, [0.0, self.step])[1] = self.step
                frontier.append(key)
        frontier = list(dict.fromkeys(frontier))
        while frontier:
            merged: dict[frozenset, float] = {}
            tried = set()
            for a in frontier:
                for b in list(self.sets):
                    if a == b or frozenset({a, b}) in tried:
                        continue
                    tried.add(frozenset({a, b}))
                    if a <= b or b <= a:
                        continue
                    cross = [(p, q) for p in a - b for q in b - a]
                    gate = [self.h(p, q, self.cfg.distance_tolerance) for p, q in cross]
                    if not all(x > self.cfg.gamma for x in gate):
                        continue
                    score = self.sets[a][0] + self.sets[b][0] + sum(self.h(p, q) for p, q in cross)
                    self.sets[a][1] = self.sets[b][1] = self.step
                    union = a | b
                    merged[union] = max(merged.get(union, -np.inf), score)
            frontier = []
            for union, score in merged.items():
                if union in self.sets:
                    self.sets[union][0] = max(self.sets[union][0], score)
                else:
                    self.sets[union] = [score, self.step]
                    frontier.append(union)
            if len(self.sets) > self.capacity:
                keep = set(self.ranking()[: self.capacity])
                self.sets = {k: v for k, v in self.sets.items() if k in keep}
                frontier = [f for f in frontier if f in keep]
        self.expire()

    def ranking(self) -> list[frozenset]:
        def key(s):
            total = np.uint64(0)
            for g, l in s:
                total = np.uint64((int(total) + pair_hash(self.gids[g], self.lids[l])) % 2**64)
            return (-round(self.sets[s][0], 9), -len(s), int(total))

        return sorted(self.sets, key=key)

    def expire(self) -> None:
        protected = set(self.ranking()[: self.cfg.protect_top])
        self.sets = {
            k: v
            for k, v in self.sets.items()
            if self.step - v[1] <= self.cfg.expiry_updates or k in protected
        }
