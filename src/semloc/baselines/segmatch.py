"""SegMatch-style segment matching (Dubé et al., "SegMatch: segment based place recognition in
3D point clouds", ICRA 2017), applied to objects.

Per object, shape features from its points: the eigenvalue features of SegMatch (linearity,
planarity, scattering, omnivariance, anisotropy, eigenentropy, change of curvature) and size
features (extents along the principal axes, height, log point count).  Candidate matches: the
`knn` nearest global objects of the same label in standardised feature space, kept when a
random forest, trained on the global map, says "same object" with probability >= `threshold`
(SegMatch's kNN retrieval + classifier).  The forest sees (|f_a - f_b|, f_a, f_b) like
SegMatch's and is trained on simulated partial views of every global object (random visible
half, subsampling, 1 cm noise, a few
bleeding points as from segmentation errors) paired with the object itself (positives) and with other
objects (negatives, half of them of the same label).  Geometric-consistency grouping of the
candidates (pairwise distances agree within `consistency`) gives association groups, and each
group a pose through the shared pose recovery.

Simplifications: the classifier is trained per global map on synthetic views instead of on
labelled real segment pairs (once per map object and settings in a process: training is
seeded); objects without points fall back to label-only candidates.
"""

from __future__ import annotations

import weakref

import numpy as np
from pydantic import Field

from semloc.association import canonical_label
from semloc.baselines.base import BaselineConfig, Group, ObjectBaseline, consistency_groups
from semloc.maps import ObjectMap, SemanticObject

N_FEATURES = 11


class SegMatchConfig(BaselineConfig):
    knn: int = Field(5, ge=1, description="Nearest global objects (same label) per local one.")
    threshold: float = Field(0.3, ge=0, le=1, description="Classifier probability to keep a match.")
    consistency: float = Field(0.5, gt=0, description="Distance agreement (m) when grouping.")
    views: int = Field(8, ge=1, description="Simulated partial views per global object.")
    trees: int = Field(60, ge=1, description="Trees of the random forest.")
    seed: int = Field(0, description="Seed of the training views and the forest.")


def shape_features(points: np.ndarray | None) -> np.ndarray:
    """Eigenvalue and size features of a point set (zeros when there are fewer than 4 points)."""
    if points is None or len(points) < 4:
        return np.zeros(N_FEATURES)
    p = np.asarray(points, dtype=float)
    centred = p - p.mean(axis=0)
    values, vectors = np.linalg.eigh(centred.T @ centred / len(p))
    l3, l2, l1 = np.maximum(values, 1e-12) / max(values.sum(), 1e-12)
    projected = centred @ vectors
    extents = (np.percentile(projected, 98, axis=0) - np.percentile(projected, 2, axis=0))[::-1]
    return np.array(
        [
            (l1 - l2) / l1,  # linearity
            (l2 - l3) / l1,  # planarity
            l3 / l1,  # scattering
            np.cbrt(l1 * l2 * l3),  # omnivariance
            (l1 - l3) / l1,  # anisotropy
            -sum(v * np.log(v) for v in (l1, l2, l3)),  # eigenentropy
            l3 / (l1 + l2 + l3),  # change of curvature
            *extents,  # sizes along the principal axes
            np.percentile(p[:, 2], 98) - np.percentile(p[:, 2], 2),  # height
        ]
    )


def partial_view(points: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A random visible part of an object: points on one side of a random plane, subsampled."""
    centre = points.mean(axis=0)
    direction = rng.normal(size=3)
    direction[2] = abs(direction[2]) * 0.3
    direction /= np.linalg.norm(direction)
    offset = rng.uniform(-0.3, 0.1) * np.ptp(points @ direction)
    keep = (points - centre) @ direction > offset
    part = points[keep] if keep.sum() >= 8 else points
    n = max(8, int(len(part) * rng.uniform(0.3, 1.0)))
    part = part[rng.choice(len(part), size=min(n, len(part)), replace=False)]
    part = part + rng.normal(scale=0.01, size=part.shape)
    # segmentation errors: a few points bleeding in from around the object
    n_out = int(len(part) * rng.uniform(0.0, 0.08))
    spill = part[rng.choice(len(part), size=n_out)] + rng.normal(scale=0.15, size=(n_out, 3))
    return np.vstack([part, spill])


def pair_features(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """SegMatch's classifier input for two feature rows (or matrices): |a - b|, a, b."""
    return np.concatenate([np.abs(a - b), a, b], axis=-1)


_TRAINED: weakref.WeakKeyDictionary[ObjectMap, dict[str, tuple]] = weakref.WeakKeyDictionary()


class SegMatchBaseline(ObjectBaseline):
    """Eigenvalue + size features, kNN + random forest candidates, consistency grouping."""

    name = "segmatch"
    config_class = SegMatchConfig
    config: SegMatchConfig

    def __init__(self, global_map, config: SegMatchConfig | None = None, local_up=None) -> None:
        super().__init__(global_map, config, local_up)
        self._labels = np.array([canonical_label(lb, {}) for lb in global_map.labels], dtype=object)
        trained = _TRAINED.setdefault(global_map, {})
        key = self.config.model_dump_json()
        if key not in trained:  # once per map and settings: seeded, so the same every time
            self._features = np.array([shape_features(o.points) for o in global_map])
            trained[key] = (self._features, self._train())
        self._features, self._forest = trained[key]
        self._scale = self._features.std(axis=0) + 1e-6

    def _train(self):
        from sklearn.ensemble import RandomForestClassifier

        cfg, gmap = self.config, self.global_map
        rng = np.random.default_rng(cfg.seed)
        X, y = [], []
        n = len(gmap)
        for i, obj in enumerate(gmap):
            if obj.points is None or len(obj.points) < 8:
                continue
            same = np.flatnonzero((self._labels == self._labels[i]) & (np.arange(n) != i))
            for _ in range(cfg.views):
                f = shape_features(partial_view(obj.points, rng))
                X.append(pair_features(f, self._features[i]))
                y.append(1)
                others = [int(rng.choice(same))] if len(same) else []
                if n > 1:
                    j = int(rng.integers(n - 1))
                    others.append(j + (j >= i))
                for j in others:
                    X.append(pair_features(f, self._features[j]))
                    y.append(0)
        if len(set(y)) < 2:
            return None
        forest = RandomForestClassifier(
            n_estimators=cfg.trees, max_depth=12, random_state=cfg.seed, n_jobs=1
        )
        return forest.fit(np.array(X), np.array(y))

    def _groups(self, local: list[SemanticObject]) -> list[Group]:
        cfg = self.config
        candidates = []
        for j, obj in enumerate(local):
            same = np.flatnonzero(self._labels == canonical_label(obj.label, {}))
            if len(same) == 0:
                continue
            if obj.points is None or len(obj.points) < 4 or self._forest is None:
                candidates += [(int(i), j, 0.5) for i in same[: cfg.knn]]
                continue
            f = shape_features(obj.points)
            distance = np.linalg.norm((self._features[same] - f) / self._scale, axis=1)
            nearest = same[np.argsort(distance)[: cfg.knn]]
            X = pair_features(np.repeat(f[None], len(nearest), axis=0), self._features[nearest])
            probability = self._forest.predict_proba(X)[:, 1]
            candidates += [
                (int(i), j, float(p))
                for i, p in zip(nearest, probability, strict=True)
                if p >= cfg.threshold
            ]
        xyz = np.array([o.position for o in local]).reshape(-1, 3)
        return consistency_groups(candidates, xyz, self.global_map.positions, cfg.consistency)
