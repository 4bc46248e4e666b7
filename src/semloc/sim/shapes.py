"""Object models built from primitives: triangle meshes, object classes and their styles.

A `Mesh` is plain numpy (vertices (V, 3), triangles (F, 3)).  An `ObjectModel` is one style of
one class (e.g. "chair", style 1 = office chair), expressed in its own frame: footprint centred
on the origin, standing on z = 0, front facing +y (back towards -y, e.g. a chair's backrest).
Every model of a class has a roughly similar size, so replacing one style by another (as a CAD
map does) keeps the object plausible but changes its shape and point distribution.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import cache

import numpy as np

_BOX_FACES = np.array(
    [
        [0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4],
        [2, 3, 7], [2, 7, 6], [1, 2, 6], [1, 6, 5], [0, 4, 7], [0, 7, 3],
    ]
)  # fmt: skip


@dataclass(frozen=True)
class Mesh:
    """A triangle mesh: vertices (V, 3) float64 and triangles (F, 3) int."""

    vertices: np.ndarray
    triangles: np.ndarray

    @staticmethod
    def concat(meshes: list[Mesh]) -> Mesh:
        offsets = np.cumsum([0] + [len(m.vertices) for m in meshes[:-1]])
        return Mesh(
            np.concatenate([m.vertices for m in meshes]),
            np.concatenate([m.triangles + o for m, o in zip(meshes, offsets, strict=True)]),
        )

    def transformed(self, T: np.ndarray) -> Mesh:
        return Mesh(self.vertices @ T[:3, :3].T + T[:3, 3], self.triangles)

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return self.vertices.min(axis=0), self.vertices.max(axis=0)

    def areas(self) -> np.ndarray:
        a, b, c = (self.vertices[self.triangles[:, i]] for i in range(3))
        return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)

    def sample_surface(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """`n` points uniformly distributed over the whole surface (area-weighted)."""
        areas = self.areas()
        tri = rng.choice(len(areas), size=n, p=areas / areas.sum())
        u, v = rng.random(n), rng.random(n)
        flip = u + v > 1
        u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
        a, b, c = (self.vertices[self.triangles[tri, i]] for i in range(3))
        return a + u[:, None] * (b - a) + v[:, None] * (c - a)


def box(center: tuple[float, float, float], size: tuple[float, float, float]) -> Mesh:
    """An axis-aligned box."""
    c, h = np.asarray(center, float), np.asarray(size, float) / 2
    corners = np.array(
        [[-1, -1, -1], [1, -1, -1], [1, 1, -1], [-1, 1, -1],
         [-1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1]], dtype=float
    )  # fmt: skip
    return Mesh(c + corners * h, _BOX_FACES.copy())


def cylinder(
    base: tuple[float, float, float], radius: float, height: float, segments: int = 16
) -> Mesh:
    """A vertical closed cylinder standing on `base`."""
    angles = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    ring = np.stack([radius * np.cos(angles), radius * np.sin(angles)], axis=1)
    bottom = np.column_stack([ring, np.zeros(segments)])
    top = np.column_stack([ring, np.full(segments, height)])
    centres = np.array([[0, 0, 0], [0, 0, height]], dtype=float)
    vertices = np.concatenate([bottom, top, centres]) + np.asarray(base, float)
    i = np.arange(segments)
    j = (i + 1) % segments
    cb, ct = 2 * segments, 2 * segments + 1
    sides = np.concatenate(
        [np.stack([i, j, j + segments], 1), np.stack([i, j + segments, i + segments], 1)]
    )
    caps = np.concatenate(
        [
            np.stack([np.full(segments, cb), j, i], 1),
            np.stack([np.full(segments, ct), i + segments, j + segments], 1),
        ]
    )  # noqa: E501
    return Mesh(vertices, np.concatenate([sides, caps]))


@dataclass(frozen=True)
class ObjectModel:
    """One style of one object class, in its own frame (base at z = 0, front towards +y)."""

    label: str
    style: int
    mesh: Mesh

    @property
    def extent(self) -> np.ndarray:
        """Size of the axis-aligned bounding box in the model frame."""
        lo, hi = self.mesh.bounds
        return hi - lo

    @property
    def box_center(self) -> np.ndarray:
        lo, hi = self.mesh.bounds
        return (lo + hi) / 2

    @property
    def height(self) -> float:
        return float(self.mesh.bounds[1][2])


def _legs(w: float, d: float, h: float, t: float = 0.04, z0: float = 0.0) -> list[Mesh]:
    xs, ys = (w / 2 - t / 2), (d / 2 - t / 2)
    return [box((sx * xs, sy * ys, z0 + h / 2), (t, t, h)) for sx in (-1, 1) for sy in (-1, 1)]


# Styles per class: functions returning the parts of the model. -------------------------------
def _chair_legs() -> list[Mesh]:
    return [
        *_legs(0.44, 0.44, 0.45),
        box((0, 0, 0.47), (0.46, 0.46, 0.04)),
        box((0, -0.21, 0.7), (0.44, 0.04, 0.45)),
    ]


def _chair_office() -> list[Mesh]:
    star = [box((0, 0, 0.03), (0.6, 0.06, 0.05)), box((0, 0, 0.03), (0.06, 0.6, 0.05))]
    return [
        *star,
        cylinder((0, 0, 0.05), 0.03, 0.4),
        box((0, 0, 0.48), (0.5, 0.48, 0.08)),
        box((0, -0.24, 0.85), (0.46, 0.06, 0.6)),
    ]


def _chair_sled() -> list[Mesh]:
    return [
        box((-0.22, 0, 0.22), (0.03, 0.46, 0.44)),
        box((0.22, 0, 0.22), (0.03, 0.46, 0.44)),
        box((0, 0.02, 0.46), (0.47, 0.42, 0.05)),
        box((0, -0.2, 0.66), (0.47, 0.05, 0.36)),
        box((0, -0.21, 0.92), (0.47, 0.03, 0.1)),
    ]


def _table_rect() -> list[Mesh]:
    return [*_legs(1.5, 0.85, 0.72, 0.06), box((0, 0, 0.74), (1.6, 0.9, 0.04))]


def _table_pedestal() -> list[Mesh]:
    return [
        box((0, 0, 0.03), (0.9, 0.5, 0.06)),
        box((0, 0, 0.38), (0.12, 0.12, 0.66)),
        box((0, 0, 0.74), (1.5, 0.9, 0.05)),
    ]


def _table_frame() -> list[Mesh]:
    return [
        *_legs(1.5, 0.8, 0.7, 0.08),
        box((0, 0, 0.66), (1.45, 0.78, 0.08)),
        box((0, 0, 0.72), (1.6, 0.88, 0.04)),
    ]


def _coffee_low() -> list[Mesh]:
    return [*_legs(0.9, 0.5, 0.4, 0.05), box((0, 0, 0.42), (1.0, 0.55, 0.04))]


def _coffee_block() -> list[Mesh]:
    return [box((0, 0, 0.06), (0.8, 0.45, 0.12)), box((0, 0, 0.38), (1.0, 0.6, 0.06))]


def _desk_panels() -> list[Mesh]:
    return [
        box((-0.58, 0, 0.37), (0.04, 0.6, 0.74)),
        box((0.58, 0, 0.37), (0.04, 0.6, 0.74)),
        box((0, -0.25, 0.45), (1.12, 0.02, 0.4)),
        box((0, 0, 0.75), (1.2, 0.65, 0.03)),
    ]


def _desk_drawers() -> list[Mesh]:
    return [
        box((0.42, 0, 0.36), (0.38, 0.6, 0.72)),
        *[box((-0.57, sy * 0.27, 0.36), (0.04, 0.04, 0.72)) for sy in (-1, 1)],
        box((0, 0, 0.74), (1.25, 0.65, 0.04)),
    ]


def _desk_school() -> list[Mesh]:
    return [
        *_legs(1.1, 0.5, 0.72, 0.035),
        box((0, -0.05, 0.6), (1.05, 0.4, 0.02)),
        box((0, 0, 0.73), (1.15, 0.55, 0.025)),
    ]


def _sofa_block() -> list[Mesh]:
    return [
        box((0, 0.05, 0.22), (1.8, 0.8, 0.44)),
        box((0, -0.38, 0.6), (2.0, 0.2, 0.5)),
        box((-0.92, 0.05, 0.32), (0.16, 0.8, 0.64)),
        box((0.92, 0.05, 0.32), (0.16, 0.8, 0.64)),
    ]


def _sofa_legs() -> list[Mesh]:
    cushions = [box((x, 0.07, 0.38), (0.62, 0.66, 0.12)) for x in (-0.63, 0, 0.63)]
    return [
        *_legs(1.9, 0.8, 0.12, 0.05),
        box((0, 0, 0.22), (1.95, 0.85, 0.2)),
        *cushions,
        box((0, -0.35, 0.65), (1.95, 0.15, 0.55)),
    ]


def _armchair_block() -> list[Mesh]:
    return [
        box((0, 0.05, 0.22), (0.7, 0.75, 0.44)),
        box((0, -0.35, 0.6), (0.9, 0.2, 0.5)),
        box((-0.38, 0.05, 0.3), (0.14, 0.75, 0.6)),
        box((0.38, 0.05, 0.3), (0.14, 0.75, 0.6)),
    ]


def _armchair_legs() -> list[Mesh]:
    return [
        *_legs(0.7, 0.7, 0.2, 0.04),
        box((0, 0.02, 0.3), (0.8, 0.75, 0.18)),
        box((0, -0.33, 0.7), (0.8, 0.1, 0.65)),
    ]


def _bed_headboard() -> list[Mesh]:
    return [
        box((0, 0.05, 0.18), (1.5, 2.0, 0.36)),
        box((0, 0.05, 0.46), (1.4, 1.95, 0.2)),
        box((0, -1.0, 0.55), (1.6, 0.08, 1.1)),
    ]


def _bed_platform() -> list[Mesh]:
    return [
        *_legs(1.55, 2.05, 0.25, 0.08),
        box((0, 0, 0.3), (1.6, 2.1, 0.1)),
        box((0, 0, 0.45), (1.45, 2.0, 0.22)),
        box((0, -1.04, 0.5), (1.6, 0.05, 0.9)),
        box((0, 1.04, 0.35), (1.6, 0.05, 0.5)),
    ]


def _nightstand_box() -> list[Mesh]:
    return [box((0, 0, 0.27), (0.45, 0.4, 0.54))]


def _nightstand_legs() -> list[Mesh]:
    return [*_legs(0.45, 0.38, 0.25, 0.03), box((0, 0, 0.4), (0.48, 0.4, 0.3))]


def _cabinet_tall() -> list[Mesh]:
    return [box((0, 0, 0.95), (0.9, 0.5, 1.9)), box((0, 0.255, 1.0), (0.02, 0.01, 1.6))]


def _cabinet_plinth() -> list[Mesh]:
    return [box((0, -0.02, 0.05), (0.85, 0.42, 0.1)), box((0, 0, 1.0), (0.95, 0.48, 1.8))]


def _cabinet_low() -> list[Mesh]:
    return [box((0, 0, 0.45), (0.9, 0.55, 0.9)), box((0, 0.02, 0.92), (0.95, 0.6, 0.04))]


def _cabinet_low_legs() -> list[Mesh]:
    return [*_legs(0.85, 0.5, 0.15, 0.04), box((0, 0, 0.53), (0.9, 0.55, 0.76))]


def _shelf_open() -> list[Mesh]:
    boards = [box((0, 0, z), (0.9, 0.35, 0.025)) for z in (0.05, 0.45, 0.85, 1.25, 1.65, 1.98)]
    sides = [box((sx * 0.46, 0, 1.0), (0.03, 0.35, 2.0)) for sx in (-1, 1)]
    return boards + sides


def _shelf_backed() -> list[Mesh]:
    boards = [box((0, 0.02, z), (0.95, 0.32, 0.03)) for z in (0.1, 0.55, 1.0, 1.45, 1.85)]
    return [*boards, box((0, -0.16, 0.95), (1.0, 0.02, 1.9)), box((0, 0, 0.05), (1.0, 0.36, 0.1))]


def _monitor_stand() -> list[Mesh]:
    return [
        box((0, 0, 0.01), (0.22, 0.18, 0.02)),
        box((0, -0.03, 0.15), (0.05, 0.03, 0.28)),
        box((0, 0, 0.38), (0.58, 0.04, 0.36)),
    ]


def _monitor_pole() -> list[Mesh]:
    return [
        cylinder((0, 0, 0), 0.1, 0.02),
        cylinder((0, -0.02, 0.02), 0.015, 0.25),
        box((0, 0, 0.4), (0.62, 0.03, 0.38)),
    ]


def _tv_stand() -> list[Mesh]:
    return [
        box((0, 0, 0.3), (0.5, 0.3, 0.6)),
        box((0, 0, 0.62), (0.3, 0.2, 0.04)),
        box((0, 0, 0.98), (1.25, 0.06, 0.72)),
    ]


def _tv_legs() -> list[Mesh]:
    feet = [box((sx * 0.5, 0, 0.55), (0.05, 0.25, 0.06)) for sx in (-1, 1)]
    return [*feet, box((0, 0, 0.3), (1.3, 0.35, 0.5)), box((0, 0, 0.95), (1.2, 0.05, 0.7))]


def _lamp_disc() -> list[Mesh]:
    return [
        cylinder((0, 0, 0), 0.16, 0.03),
        cylinder((0, 0, 0.03), 0.015, 1.4),
        cylinder((0, 0, 1.35), 0.2, 0.3),
    ]


def _lamp_tripod() -> list[Mesh]:
    legs = [
        box((0.12 * np.cos(a), 0.12 * np.sin(a), 0.4), (0.03, 0.03, 0.8)) for a in (0, 2.1, 4.2)
    ]
    return [*legs, cylinder((0, 0, 0.8), 0.02, 0.6), box((0, 0, 1.5), (0.35, 0.35, 0.28))]


def _plant_round() -> list[Mesh]:
    return [
        cylinder((0, 0, 0), 0.18, 0.35),
        cylinder((0, 0, 0.35), 0.3, 0.35),
        cylinder((0, 0, 0.7), 0.22, 0.35),
        cylinder((0, 0, 1.05), 0.12, 0.25),
    ]


def _plant_column() -> list[Mesh]:
    return [box((0, 0, 0.2), (0.35, 0.35, 0.4)), box((0, 0, 0.9), (0.25, 0.25, 1.0))]


def _fridge_single() -> list[Mesh]:
    return [box((0, 0, 0.9), (0.7, 0.68, 1.8)), box((0.3, 0.35, 1.0), (0.03, 0.03, 0.5))]


def _fridge_double() -> list[Mesh]:
    return [
        box((0, 0, 0.55), (0.72, 0.7, 1.1)),
        box((0, 0, 1.47), (0.72, 0.7, 0.7)),
        box((0, 0.36, 1.11), (0.7, 0.02, 0.02)),
    ]


def _toilet_floor() -> list[Mesh]:
    return [
        cylinder((0, 0.12, 0), 0.15, 0.3),
        cylinder((0, 0.12, 0.3), 0.2, 0.1),
        box((0, -0.2, 0.6), (0.42, 0.16, 0.38)),
    ]


def _toilet_wall() -> list[Mesh]:
    return [box((0, 0.05, 0.35), (0.38, 0.5, 0.2)), box((0, -0.23, 0.5), (0.5, 0.06, 0.9))]


def _sink_vanity() -> list[Mesh]:
    return [box((0, 0, 0.4), (0.7, 0.48, 0.8)), box((0, 0, 0.84), (0.6, 0.42, 0.08))]


def _sink_pedestal() -> list[Mesh]:
    return [box((0, -0.05, 0.4), (0.18, 0.18, 0.8)), box((0, 0, 0.85), (0.6, 0.45, 0.16))]


def _whiteboard_wall() -> list[Mesh]:
    return [box((0, -0.02, 1.45), (2.0, 0.03, 1.0)), box((0, 0.04, 0.93), (1.8, 0.08, 0.04))]


def _whiteboard_stand() -> list[Mesh]:
    feet = [box((sx * 0.85, 0, 0.03), (0.06, 0.55, 0.06)) for sx in (-1, 1)]
    posts = [box((sx * 0.85, 0, 0.9), (0.04, 0.04, 1.8)) for sx in (-1, 1)]
    return [*feet, *posts, box((0, 0.03, 1.3), (1.8, 0.03, 0.9))]


STYLES: dict[str, list[Callable[[], list[Mesh]]]] = {
    "chair": [_chair_legs, _chair_office, _chair_sled],
    "table": [_table_rect, _table_pedestal, _table_frame],
    "coffee_table": [_coffee_low, _coffee_block],
    "desk": [_desk_panels, _desk_drawers, _desk_school],
    "sofa": [_sofa_block, _sofa_legs],
    "armchair": [_armchair_block, _armchair_legs],
    "bed": [_bed_headboard, _bed_platform],
    "nightstand": [_nightstand_box, _nightstand_legs],
    "cabinet": [_cabinet_tall, _cabinet_plinth],
    "low_cabinet": [_cabinet_low, _cabinet_low_legs],
    "bookshelf": [_shelf_open, _shelf_backed],
    "monitor": [_monitor_stand, _monitor_pole],
    "tv": [_tv_stand, _tv_legs],
    "lamp": [_lamp_disc, _lamp_tripod],
    "plant": [_plant_round, _plant_column],
    "refrigerator": [_fridge_single, _fridge_double],
    "toilet": [_toilet_floor, _toilet_wall],
    "sink": [_sink_vanity, _sink_pedestal],
    "whiteboard": [_whiteboard_wall, _whiteboard_stand],
}
"""Object classes and their styles (every class has at least two, so CAD maps can swap)."""

SMALL_CLASSES = frozenset({"monitor", "lamp", "plant", "nightstand"})
"""Classes that detectors miss more often (small or thin)."""


@cache
def model(label: str, style: int) -> ObjectModel:
    """The model of one style of a class (cached: identical instances share the mesh)."""
    try:
        styles = STYLES[label]
    except KeyError:
        raise ValueError(f"unknown object class {label!r}; known: {sorted(STYLES)}") from None
    if not 0 <= style < len(styles):
        raise ValueError(f"class {label!r} has styles 0..{len(styles) - 1}, got {style}")
    return ObjectModel(label, style, Mesh.concat(styles[style]()))


def other_style(label: str, style: int, rng: np.random.Generator) -> int:
    """A different style of the same class (for CAD replacement)."""
    choices = [s for s in range(len(STYLES[label])) if s != style]
    return int(rng.choice(choices))
