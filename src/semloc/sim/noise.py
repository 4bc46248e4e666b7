"""Detection noise: what a real instance segmenter and odometry do to perfect simulated frames.

`detect(frame, world, K, noise, rng)` turns a rendered frame into per-instance segments with
the usual failure modes: missed detections (objects with few visible pixels, small classes more
often, and a random miss rate), a label confusion model between similar classes, masks that
erode (lose their border) or bleed into the background (pick up wall, floor or neighbour
pixels), and scores.  `drift` perturbs odometry poses with errors that grow with motion.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from pydantic import BaseModel, ConfigDict, Field
from scipy import ndimage

from semloc.sim.sensor import Frame, Intrinsics, backproject
from semloc.sim.shapes import SMALL_CLASSES
from semloc.sim.world import World

CONFUSIONS: dict[str, tuple[str, ...]] = {
    "chair": ("armchair",), "armchair": ("chair", "sofa"), "sofa": ("armchair",),
    "table": ("desk", "coffee_table"), "desk": ("table",), "coffee_table": ("table",),
    "cabinet": ("bookshelf", "refrigerator"), "low_cabinet": ("cabinet", "nightstand"),
    "nightstand": ("low_cabinet",), "bookshelf": ("cabinet",),
    "monitor": ("tv",), "tv": ("monitor",),
    "refrigerator": ("cabinet",), "toilet": ("sink",), "sink": ("toilet",), "lamp": ("plant",),
    "plant": ("lamp",), "whiteboard": ("tv",), "bed": ("sofa",),
}  # fmt: skip
"""Which labels a detector may give an object of each class instead of the right one."""


class DetectionNoise(BaseModel):
    """How imperfect the simulated detector and odometry are (defaults: a decent detector)."""

    model_config = ConfigDict(extra="forbid")

    min_pixels_fraction: float = Field(
        0.002, ge=0, description="Masks smaller than this share of the image are missed."
    )
    miss_prob: float = Field(0.05, ge=0, le=1, description="Random miss rate per object and frame.")
    small_miss_prob: float = Field(
        0.3, ge=0, le=1, description="Miss rate for small classes (monitor, lamp, plant ...)."
    )
    confusion_prob: float = Field(
        0.06, ge=0, le=1, description="Chance that a detection carries a confusable label."
    )
    erode_prob: float = Field(0.3, ge=0, le=1, description="Chance that a mask loses its border.")
    bleed_prob: float = Field(
        0.3, ge=0, le=1, description="Chance that a mask bleeds into its surroundings."
    )
    mask_pixels: int = Field(2, ge=0, description="How many pixels masks erode or bleed by.")
    depth_noise: bool = Field(True, description="Add structured-light depth noise.")
    drift_translation: float = Field(
        0.0, ge=0, description="Odometry drift, metres per metre travelled (e.g. 0.01)."
    )
    drift_yaw_deg: float = Field(
        0.0, ge=0, description="Odometry heading drift, degrees per metre travelled."
    )

    @classmethod
    def perfect(cls) -> DetectionNoise:
        """No noise at all: every visible object found, exact masks and labels."""
        return cls(
            min_pixels_fraction=0.0005, miss_prob=0, small_miss_prob=0, confusion_prob=0,
            erode_prob=0, bleed_prob=0, depth_noise=False,
        )  # fmt: skip


@dataclass(frozen=True)
class Detection:
    """One detected segment: label, points in the camera frame, score, and the true instance."""

    label: str
    points: np.ndarray
    score: float
    instance: int


def detect(
    frame: Frame, world: World, K: Intrinsics, noise: DetectionNoise, rng: np.random.Generator
) -> list[Detection]:
    """Instance segments of one frame with misses, confusions and mask errors."""
    instances, counts = np.unique(frame.instance[frame.instance >= 0], return_counts=True)
    min_pixels = max(10, int(noise.min_pixels_fraction * frame.depth.size))
    detections = []
    for inst, count in zip(instances.tolist(), counts.tolist(), strict=True):
        label = world.objects[inst].label
        miss = noise.small_miss_prob if label in SMALL_CLASSES else noise.miss_prob
        if count < min_pixels or rng.random() < miss:
            continue
        mask = _noisy_mask(frame.instance == inst, noise, rng)
        points = backproject(frame.depth, K, mask)
        if len(points) < 10:
            continue
        score = float(rng.uniform(0.6, 1.0))
        if label in CONFUSIONS and rng.random() < noise.confusion_prob:
            label = str(rng.choice(CONFUSIONS[label]))
            score *= 0.7
        detections.append(Detection(label, points, round(score, 3), inst))
    return detections


def _noisy_mask(mask: np.ndarray, noise: DetectionNoise, rng: np.random.Generator) -> np.ndarray:
    n = noise.mask_pixels
    if n <= 0:
        return mask
    r = rng.random()
    if r < noise.erode_prob:
        eroded = ndimage.binary_erosion(mask, iterations=n)
        return eroded if eroded.sum() >= 10 else mask
    if r < noise.erode_prob + noise.bleed_prob:
        return ndimage.binary_dilation(mask, iterations=n)
    return mask


def drift(T_odom_camera: np.ndarray, noise: DetectionNoise, rng: np.random.Generator) -> np.ndarray:
    """Odometry estimates (n, 4, 4): each relative motion gets an error growing with its length."""
    if noise.drift_translation == 0 and noise.drift_yaw_deg == 0:
        return T_odom_camera.copy()
    out = [T_odom_camera[0].copy()]
    for prev, cur in zip(T_odom_camera[:-1], T_odom_camera[1:], strict=True):
        rel = np.linalg.inv(prev) @ cur
        length = float(np.linalg.norm(rel[:3, 3]))
        err = np.eye(4)
        a = math.radians(rng.normal(0, noise.drift_yaw_deg * length))
        err[:2, :2] = [[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]]
        err[:2, 3] = rng.normal(0, noise.drift_translation * length, size=2)
        # the error acts about gravity in the odometry frame, so `up` stays +z
        step = out[-1] @ rel
        out.append(_about_gravity(err, step))
    return np.stack(out)


def _about_gravity(err: np.ndarray, T: np.ndarray) -> np.ndarray:
    centre = np.eye(4)
    centre[:3, 3] = T[:3, 3]
    return centre @ err @ np.linalg.inv(centre) @ T
