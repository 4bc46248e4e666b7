"""CLIPPER-style consistency graph and densest cluster (Lusk, Fathian, How, ICRA 2021).

All label-compatible (global, local) candidate associations (the same `CandidateIndex` as the
Localizer: labels, and descriptors when present) are nodes of a consistency graph.  Two
associations (a, b) and (a', b') are consistent when they are one-to-one and the distances
agree: c = | ||m_a - m_a'|| - ||m_b - m_b'|| | < epsilon; the edge weight is
exp(-c^2 / (2 sigma^2)).  The densest cluster maximises u^T M u over ||u|| = 1, u >= 0 with a
penalty d on inconsistent pairs that grows until the support of u is a clique (CLIPPER's
projected gradient ascent with an increasing penalty); the associations with large u_i form the
cluster and the pose comes from the shared pose recovery.

Simplifications: the top-k hypotheses are found by *peeling* (remove the cluster's
associations and solve again), CLIPPER itself returns one cluster; the step size is a simple
backtracking line search; uniform node weights (no descriptor similarity).
"""

from __future__ import annotations

import numpy as np
from pydantic import Field

from semloc.association import AssociationConfig, CandidateIndex
from semloc.baselines.base import BaselineConfig, Group, ObjectBaseline
from semloc.maps import SemanticObject


class ClipperConfig(BaselineConfig):
    epsilon: float = Field(0.5, gt=0, description="Max distance difference (m) of consistency.")
    sigma: float = Field(0.25, gt=0, description="Scale (m) of the consistency weight.")
    rounds: int = Field(15, ge=1, description="Peeling rounds (clusters tried) per update.")
    penalty_step: float = Field(2.0, gt=0, description="Factor by which the penalty d grows.")
    max_iterations: int = Field(300, ge=1, description="Gradient steps per penalty value.")


def dense_cluster(M: np.ndarray, C: np.ndarray, cfg: ClipperConfig) -> np.ndarray:
    """Indices of a dense, fully consistent cluster of the weighted consistency graph M (C: 0/1)."""
    n = len(M)
    if n == 0:
        return np.zeros(0, dtype=int)
    if n == 1:
        return np.array([0])
    values, vectors = np.linalg.eigh(M)
    u = np.abs(vectors[:, -1]) + 1e-6
    u /= np.linalg.norm(u)
    inconsistent = (1.0 - C) - np.eye(n) * 0  # diagonal of C is 1
    d = 0.5 * values[-1] if values[-1] > 0 else 1.0
    for _ in range(40):
        Md = M - d * inconsistent
        f = u @ Md @ u
        step = 1.0
        for _ in range(cfg.max_iterations):
            grad = 2 * Md @ u
            while True:
                v = np.maximum(u + step * grad, 0.0)
                norm = np.linalg.norm(v)
                if norm == 0:
                    step *= 0.5
                    if step < 1e-9:
                        v = u
                        break
                    continue
                v /= norm
                fv = v @ Md @ v
                if fv >= f or step < 1e-9:
                    break
                step *= 0.5
            converged = abs(fv - f) < 1e-9 and np.allclose(v, u, atol=1e-7)
            u, f = v, fv
            step = min(step * 2.0, 1e3)
            if converged:
                break
        support = np.flatnonzero(u > 1e-4)
        if np.all(C[np.ix_(support, support)] > 0):
            break
        d *= cfg.penalty_step
    # CLIPPER: keep the omega largest entries, omega ~ the cluster's density estimate
    order = np.argsort(-u)
    omega = int(np.clip(round(u @ M @ u), 1, np.count_nonzero(u > 1e-4) or 1))
    cluster = [int(order[0])]
    for i in order[1:omega]:
        if all(C[i, j] > 0 for j in cluster):
            cluster.append(int(i))
    return np.array(cluster, dtype=int)


class ClipperBaseline(ObjectBaseline):
    """Consistency graph of all label-compatible associations; densest clusters by peeling."""

    name = "clipper"
    config_class = ClipperConfig
    config: ClipperConfig

    def __init__(self, global_map, config: ClipperConfig | None = None, local_up=None) -> None:
        super().__init__(global_map, config, local_up)
        self._index = CandidateIndex(global_map, AssociationConfig(min_similarity=1.0))

    def _groups(self, local: list[SemanticObject]) -> list[Group]:
        cfg = self.config
        assoc = [(int(g), j) for j, o in enumerate(local) for g in self._index.candidates(o)]
        if not assoc:
            return []
        g = np.array([a[0] for a in assoc])
        loc = np.array([a[1] for a in assoc])
        lx = np.array([o.position for o in local])[loc]
        gx = self.global_map.positions[g]
        c = np.abs(
            np.linalg.norm(lx[:, None] - lx[None], axis=2)
            - np.linalg.norm(gx[:, None] - gx[None], axis=2)
        )
        C = (c < cfg.epsilon) & (g[:, None] != g[None]) & (loc[:, None] != loc[None])
        np.fill_diagonal(C, True)
        M = np.where(C, np.exp(-(c**2) / (2 * cfg.sigma**2)), 0.0)
        alive = np.arange(len(assoc))
        groups: list[Group] = []
        for _ in range(cfg.rounds):
            if len(alive) == 0:
                break
            sub = dense_cluster(M[np.ix_(alive, alive)], C[np.ix_(alive, alive)].astype(float), cfg)
            members = alive[sub]
            score = float(M[np.ix_(members, members)].sum() - len(members)) / 2
            if len(members) >= 2:
                groups.append((score, [(int(g[i]), int(loc[i])) for i in members]))
            alive = np.setdiff1d(alive, members)
        groups.sort(key=lambda item: (-len(item[1]), -item[0]))
        return groups
