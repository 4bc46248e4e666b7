"""Scenes of tests/core/test_changes.py, shared with the CLI tests."""

from __future__ import annotations

import numpy as np

from semloc.maps import ObjectMap, SemanticObject
from semloc.transforms import yaw_pose

T = yaw_pose(0.7, [2.0, -1.0, 0.0])
LABELS = ["chair", "table", "lamp", "sofa", "shelf", "plant", "tv", "bin"]


def cube(centre, n=60, half=0.2, seed=0) -> np.ndarray:
    return np.asarray(centre) + np.random.default_rng(seed).uniform(-half, half, (n, 3))


def room() -> ObjectMap:
    xyz = [[0, 0, 0.5], [3, 0, 0.4], [3, 2.5, 0.8], [0, 2.2, 0.3], [1.5, 4, 1.0], [4.5, 4.2, 0.6],
           [6, 1, 0.5], [1.6, 1.2, 0.5]]  # fmt: skip
    return ObjectMap(
        [SemanticObject(f"g{i}", LABELS[i], points=cube(p, seed=i)) for i, p in enumerate(xyz)],
        up=[0, 0, 1],
    )


def seen_from_t(objects: list[SemanticObject]) -> list[SemanticObject]:
    inverse = np.linalg.inv(T)
    return [o.transformed(inverse).replace(id=o.id.replace("g", "l")) for o in objects]
