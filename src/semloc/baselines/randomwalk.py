"""Random-walk descriptors on object graphs (Liu et al., "Global localization with object-level
semantics and topology", ICRA 2019; the X-View family of Gawel et al. 2018).

Each map becomes a graph whose nodes are objects and whose edges join objects closer than
`edge_distance`.  A node's descriptor is the set of label sequences of `n_walks` random walks of
`walk_length` steps that start at it (no immediate backtracking, as in X-View).  A local object
is matched to the `top_k_candidates` global objects of the same label whose descriptors share
the most walks with its own (matched-walk counts).  A consistent association is then chosen by
geometric-consistency grouping of those candidates (pairwise distances agree within
`consistency`), and each group gives a pose through the shared pose recovery.

Simplifications: global walks are sampled once per global map (seeded), local walks at every
update (seeded, so repeatable); the final consistent association uses the same greedy
consistency grouping as the SegMatch baseline instead of the original's graph matching +
RANSAC; the parameters are those of the paper where they fit indoor rooms (walk length 3 -
4 labels, 200 walks per node) and an edge distance suited to furniture spacing.
"""

from __future__ import annotations

from collections import Counter

import numpy as np
from pydantic import Field

from semloc.association import canonical_label
from semloc.baselines.base import BaselineConfig, Group, ObjectBaseline, consistency_groups
from semloc.maps import SemanticObject


class RandomWalkConfig(BaselineConfig):
    edge_distance: float = Field(2.0, gt=0, description="Objects closer than this (m) are joined.")
    walk_length: int = Field(3, ge=1, description="Steps of each random walk.")
    n_walks: int = Field(200, ge=1, description="Random walks per node.")
    top_k_candidates: int = Field(3, ge=1, description="Global candidates per local object.")
    consistency: float = Field(0.5, gt=0, description="Distance agreement (m) when grouping.")
    seed: int = Field(0, description="Seed of the random walks.")


def walk_descriptors(
    labels: list[str], xyz: np.ndarray, cfg: RandomWalkConfig, seed: int
) -> list[Counter]:
    """Per node: counts of the label sequences of its random walks."""
    n = len(labels)
    rng = np.random.default_rng(seed)
    if n == 0:
        return []
    dist = np.linalg.norm(xyz[:, None] - xyz[None], axis=2)
    neighbours = [
        np.flatnonzero((dist[i] < cfg.edge_distance) & (np.arange(n) != i)) for i in range(n)
    ]
    out = []
    for start in range(n):
        walks: Counter = Counter()
        for _ in range(cfg.n_walks):
            path, prev, node = [labels[start]], -1, start
            for _ in range(cfg.walk_length):
                options = neighbours[node]
                if len(options) > 1 and prev >= 0:
                    options = options[options != prev]
                if len(options) == 0:
                    break
                prev, node = node, int(options[rng.integers(len(options))])
                path.append(labels[node])
            walks[tuple(path)] += 1
        out.append(walks)
    return out


def matched_walks(local: Counter, global_: Counter) -> int:
    """How many of the local walks also occur among the global node's walks."""
    return sum(count for walk, count in local.items() if walk in global_)


class RandomWalkBaseline(ObjectBaseline):
    """Random-walk label descriptors, top-k candidates by matched walks, consistent grouping."""

    name = "random-walk"
    config_class = RandomWalkConfig
    config: RandomWalkConfig

    def __init__(self, global_map, config: RandomWalkConfig | None = None, local_up=None) -> None:
        super().__init__(global_map, config, local_up)
        self._labels = [canonical_label(label, {}) for label in global_map.labels]
        self._global = walk_descriptors(
            self._labels, global_map.positions, self.config, self.config.seed
        )

    def _groups(self, local: list[SemanticObject]) -> list[Group]:
        cfg = self.config
        labels = [canonical_label(o.label, {}) for o in local]
        xyz = np.array([o.position for o in local]).reshape(-1, 3)
        descriptors = walk_descriptors(labels, xyz, cfg, cfg.seed + 1)
        candidates = []
        for j, (label, desc) in enumerate(zip(labels, descriptors, strict=True)):
            same = [i for i, gl in enumerate(self._labels) if gl == label]
            scored = sorted(((matched_walks(desc, self._global[i]), i) for i in same), reverse=True)
            for count, i in scored[: cfg.top_k_candidates]:
                candidates.append((i, j, count / cfg.n_walks))
        return consistency_groups(candidates, xyz, self.global_map.positions, cfg.consistency)
