"""The training worlds of the scene-level learned baselines (SVL, FCGF-style) and simulated local
observations in them.

Training worlds are the simulator's "small" worlds of seeds `TRAIN_SEED`.. (disjoint from the
benchmark's seeds 0.., the descriptor evaluation's 500.. and the tests'), each with its
reconstruction and CAD global maps.  `local_view` imitates what a local map holds around an
object: the object and a random part of its neighbours, each seen from one side only (points
beyond a random vertical plane dropped), thinned, with 1 cm noise and a few wrong labels.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import numpy as np

from semloc.maps import ObjectMap
from semloc.sim.mapkinds import cad_map, reconstruction_map
from semloc.sim.world import generate_world

TRAIN_SEED = 700
CLASSES_FOR_NOISE = ("chair", "table", "desk", "cabinet", "sofa", "lamp", "bed", "monitor")


@dataclass(frozen=True)
class TrainingMap:
    """One global map of a training world, with what the samplers need."""

    name: str
    objects: ObjectMap
    positions: np.ndarray  # (N, 3)
    labels: list[str]
    points: list[np.ndarray]


def training_maps(worlds: int, log=print) -> list[TrainingMap]:
    """Reconstruction and CAD maps of `worlds` training worlds (seeded, the same every time;
    made once per process)."""
    maps = list(_training_maps(worlds))
    log(f"training worlds {TRAIN_SEED}..{TRAIN_SEED + worlds - 1}: {len(maps)} maps, "
        f"{sum(len(m.labels) for m in maps) // 2} objects")  # fmt: skip
    return maps


@cache
def _training_maps(worlds: int) -> tuple[TrainingMap, ...]:
    out = []
    for seed in range(TRAIN_SEED, TRAIN_SEED + worlds):
        world = generate_world(seed, "small")
        for gmap in (reconstruction_map(world), cad_map(world)):
            points = [np.asarray(o.points, dtype=float) for o in gmap]
            out.append(TrainingMap(gmap.name, gmap, gmap.positions, list(gmap.labels), points))
    return tuple(out)


def partial_points(points: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A one-sided, thinned, noisy view of one object's points (at least a few points)."""
    centre = points.mean(axis=0)
    direction = rng.normal(size=2)
    direction /= np.linalg.norm(direction)
    side = (points[:, :2] - centre[:2]) @ direction
    keep = side > rng.uniform(-0.5, 0.1) * max(float(np.ptp(side)), 1e-6)
    part = points[keep] if keep.sum() >= 8 else points
    n = max(8, int(len(part) * rng.uniform(0.4, 1.0)))
    part = part[rng.choice(len(part), size=min(n, len(part)), replace=False)]
    return part + rng.normal(scale=0.01, size=part.shape)


def local_view(
    tmap: TrainingMap, index: int, rng: np.random.Generator, radius: float = 3.0
) -> tuple[list[np.ndarray], list[str]]:
    """Points and labels of a simulated local map around object `index` (itself first)."""
    distance = np.linalg.norm(tmap.positions[:, :2] - tmap.positions[index, :2], axis=1)
    seen = rng.uniform(0.2, 1.0)
    points, labels = [], []
    for j in np.argsort(distance):
        if distance[j] > radius or (j != index and rng.random() > seen):
            continue
        if len(tmap.points[j]) < 8:
            continue
        points.append(partial_points(tmap.points[j], rng))
        wrong = j != index and rng.random() < 0.05
        labels.append(str(rng.choice(CLASSES_FOR_NOISE)) if wrong else tmap.labels[j])
    return points, labels
