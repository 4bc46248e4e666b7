"""Simulated training and evaluation objects: partial scans and CAD-style samples of the models.

Every (class, style) of `semloc.sim.shapes.STYLES` is one *instance*.  For an instance,
`partial_view` renders it standing on a floor from a random viewpoint with the simulator's
depth sensor (structured-light noise), then applies the detector's mask errors (erosion, or
bleeding into the floor) and sometimes an occlusion (points beyond a random vertical plane
dropped); `full_view` samples points over the whole model surface, like a CAD map object.
Views are returned in a random world pose (yaw and position), z up.

`HELD_OUT` styles are never used for training; the evaluation reports retrieval on them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from semloc.pointsets import voxel_downsample
from semloc.sim.sensor import DepthSensor, Intrinsics, backproject, look_at
from semloc.sim.shapes import STYLES, box, model

HELD_OUT: frozenset[tuple[str, int]] = frozenset(
    {
        ("chair", 2), ("table", 1), ("desk", 2), ("sofa", 1), ("bed", 0),
        ("cabinet", 1), ("lamp", 1), ("toilet", 0), ("monitor", 1),
    }
)  # fmt: skip
"""Instances kept out of training (one style of 9 classes)."""


def instances(split: str = "all") -> list[tuple[str, int]]:
    """(label, style) pairs: "all", "train" (not held out) or "held_out"."""
    every = [(label, s) for label in sorted(STYLES) for s in range(len(STYLES[label]))]
    if split == "all":
        return every
    if split == "train":
        return [i for i in every if i not in HELD_OUT]
    if split == "held_out":
        return [i for i in every if i in HELD_OUT]
    raise ValueError(f"split must be all, train or held_out, got {split!r}")


@dataclass(frozen=True)
class ViewConfig:
    """How partial views are taken."""

    resolution: tuple[int, int] = (120, 90)
    distance: tuple[float, float] = (1.2, 4.0)
    height: tuple[float, float] = (0.6, 2.0)
    erode_prob: float = 0.3
    bleed_prob: float = 0.3
    occlude_prob: float = 0.3


_SENSORS: dict[tuple[str, int, tuple[int, int]], DepthSensor] = {}


def _sensor(label: str, style: int, resolution: tuple[int, int]) -> DepthSensor:
    key = (label, style, resolution)
    if key not in _SENSORS:
        floor = box((0, 0, -0.01), (8.0, 8.0, 0.02))
        _SENSORS[key] = DepthSensor(
            intrinsics=Intrinsics.scannet(*resolution),
            meshes=[model(label, style).mesh],
            background=[floor],
        )
    return _SENSORS[key]


def _random_pose(points: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    a = rng.uniform(-math.pi, math.pi)
    c, s = math.cos(a), math.sin(a)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    return points @ R.T + np.array([*rng.uniform(-5, 5, 2), 0.0])


def partial_view(
    label: str, style: int, rng: np.random.Generator, config: ViewConfig | None = None
) -> np.ndarray:
    """Points (N, 3) of one noisy partial scan of an instance (random world pose, z up)."""
    cfg = config or ViewConfig()
    sensor = _sensor(label, style, cfg.resolution)
    m = model(label, style)
    centre = m.box_center
    for _ in range(20):
        a = rng.uniform(-math.pi, math.pi)
        r = rng.uniform(*cfg.distance) + 0.5 * float(np.max(m.extent[:2]))
        eye = np.array([r * math.cos(a), r * math.sin(a), rng.uniform(*cfg.height)])
        target = centre + rng.normal(0, 0.1, 3)
        T = look_at(eye, target)
        frame = sensor.render(T, rng)
        mask = frame.instance == 0
        if mask.sum() < 30:
            continue
        u = rng.random()
        if u < cfg.erode_prob:
            eroded = ndimage.binary_erosion(mask, iterations=int(rng.integers(1, 3)))
            mask = eroded if eroded.sum() >= 30 else mask
        elif u < cfg.erode_prob + cfg.bleed_prob:
            mask = ndimage.binary_dilation(mask, iterations=int(rng.integers(1, 4)))
        pts = backproject(frame.depth, sensor.K, mask)
        pts = pts @ T[:3, :3].T + T[:3, 3]
        if rng.random() < cfg.occlude_prob:
            n = rng.normal(size=2)
            n /= np.linalg.norm(n)
            proj = pts[:, :2] @ n
            cut = np.quantile(proj, rng.uniform(0.5, 0.9))
            pts = pts[proj <= cut]
        pts = voxel_downsample(pts, 0.02)
        if len(pts) >= 20:
            return _random_pose(pts, rng)
    return full_view(label, style, rng)


def full_view(label: str, style: int, rng: np.random.Generator, voxel: float = 0.05):
    """Points over the whole surface of an instance (like a CAD map object), random pose."""
    mesh = model(label, style).mesh
    n = int(np.clip(mesh.areas().sum() * 600, 200, 20000))
    return _random_pose(voxel_downsample(mesh.sample_surface(n, rng), voxel), rng)
