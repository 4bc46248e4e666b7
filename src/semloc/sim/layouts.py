"""Object-level synthetic layouts and observations (positions and boxes, no rendering).

For tests, the accuracy study and speed benchmarks of the core.  A *layout* is a building of
rooms on a grid — classrooms with rows of identical chairs and desks, meeting rooms with a ring
of chairs, offices, kitchens and living rooms — so repeated identical objects abound.  An
*observation* is what a robot has seen from somewhere in it: the nearest objects, centres
biased by partial views, an optional spurious detection, some wrong labels, all expressed in
a random gravity-aligned local frame.  (The rendered simulator with meshes and a depth
camera lives in `semloc.sim`.)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from semloc.maps import ObjectMap, SemanticObject

# label -> (size x, y, z in metres)
SIZES: dict[str, tuple[float, float, float]] = {
    "chair": (0.5, 0.5, 0.9),
    "desk": (1.2, 0.6, 0.75),
    "table": (1.6, 0.9, 0.75),
    "monitor": (0.55, 0.2, 0.4),
    "cabinet": (0.8, 0.45, 1.2),
    "shelf": (1.0, 0.35, 1.8),
    "sofa": (2.0, 0.9, 0.8),
    "tv": (1.2, 0.1, 0.7),
    "plant": (0.4, 0.4, 1.0),
    "lamp": (0.35, 0.35, 1.5),
    "fridge": (0.7, 0.7, 1.8),
    "sink": (0.6, 0.5, 0.9),
    "bed": (2.0, 1.6, 0.5),
    "whiteboard": (1.8, 0.05, 1.2),
}
LABELS = tuple(SIZES)
MOVABLE = {"chair", "plant", "lamp"}
MOVABLE_JITTER = (0.12, 0.3)  # (position std m, heading std rad): chairs are never in line
FIXED_JITTER = (0.04, 0.03)
ROOM = (8.0, 6.0)  # room footprint (m)


def _classroom(rng: np.random.Generator) -> list[tuple[str, float, float]]:
    rows, cols = rng.integers(2, 4), rng.integers(3, 5)
    dx, dy = rng.uniform(1.3, 1.7), rng.uniform(1.4, 1.8)
    x0, y0 = (ROOM[0] - (cols - 1) * dx) / 2, 1.2
    items = []
    for r in range(rows):
        for c in range(cols):
            x, y = x0 + c * dx, y0 + r * dy
            items += [("desk", x, y), ("chair", x, y - 0.55)]
    items += [("whiteboard", ROOM[0] / 2, ROOM[1] - 0.2), ("desk", ROOM[0] / 2, ROOM[1] - 1.2)]
    return items


def _meeting(rng: np.random.Generator) -> list[tuple[str, float, float]]:
    cx, cy = ROOM[0] / 2 + rng.uniform(-0.5, 0.5), ROOM[1] / 2 + rng.uniform(-0.5, 0.5)
    n = int(rng.integers(6, 11))
    items = [("table", cx, cy)]
    for k in range(n):
        angle = 2 * np.pi * k / n
        items.append(("chair", cx + 1.5 * np.cos(angle), cy + 1.1 * np.sin(angle)))
    items += [("tv", 0.2, cy), ("plant", ROOM[0] - 0.4, 0.4)]
    return items


def _office(rng: np.random.Generator) -> list[tuple[str, float, float]]:
    items = []
    for k in range(int(rng.integers(2, 5))):
        x = 1.2 + 1.8 * k
        items += [("desk", x, 1.0), ("chair", x, 1.6), ("monitor", x, 0.8)]
    items += [("cabinet", ROOM[0] - 0.5, ROOM[1] - 0.4), ("shelf", 0.6, ROOM[1] - 0.3)]
    items += [("plant", rng.uniform(1, 7), ROOM[1] - 0.5), ("lamp", ROOM[0] - 0.5, 2.5)]
    return items


def _kitchen(rng: np.random.Generator) -> list[tuple[str, float, float]]:
    items = [("fridge", 0.5, ROOM[1] - 0.5), ("sink", 2.0, ROOM[1] - 0.4)]
    items += [("cabinet", 3.0 + 0.9 * k, ROOM[1] - 0.4) for k in range(int(rng.integers(2, 4)))]
    tx, ty = rng.uniform(3, 5), rng.uniform(2, 3)
    items += [("table", tx, ty), ("chair", tx - 1.0, ty), ("chair", tx + 1.0, ty)]
    items += [("chair", tx, ty - 0.8), ("chair", tx, ty + 0.8)]
    return items


def _living(rng: np.random.Generator) -> list[tuple[str, float, float]]:
    items = [("sofa", ROOM[0] / 2, 1.0), ("tv", ROOM[0] / 2, ROOM[1] - 0.2)]
    items += [("table", ROOM[0] / 2, 2.4), ("lamp", 0.6, 0.6), ("plant", ROOM[0] - 0.5, 0.5)]
    items += [("shelf", 0.4, 3.5), ("chair", ROOM[0] - 1.5, 2.8)]
    if rng.random() < 0.5:
        items.append(("bed", 6.5, 4.5))
    return items


ROOM_TYPES = {
    "classroom": _classroom,
    "meeting": _meeting,
    "office": _office,
    "kitchen": _kitchen,
    "living": _living,
}


def _yaw(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _box_points(size: np.ndarray, rotation: np.ndarray, centre: np.ndarray, n: int,
                rng: np.random.Generator) -> np.ndarray:  # fmt: skip
    """Points sampled on the surface of an oriented box."""
    local = rng.uniform(-0.5, 0.5, (n, 3))
    axis = rng.integers(0, 3, n)
    local[np.arange(n), axis] = np.where(rng.random(n) < 0.5, -0.5, 0.5)
    return (local * size) @ rotation.T + centre


def layout(
    n_objects: int = 150,
    seed: int = 0,
    rooms: list[str] | None = None,
    points_per_object: int = 0,
) -> ObjectMap:
    """A building with about `n_objects` objects (rooms are added until it is reached)."""
    rng = np.random.default_rng(seed)
    kinds = rooms or ["classroom", "meeting", "office", "kitchen", "living"]
    objects: list[SemanticObject] = []
    room = 0
    while len(objects) < n_objects:
        kind = kinds[room % len(kinds)] if rooms else kinds[int(rng.integers(len(kinds)))]
        origin = np.array([(room % 4) * (ROOM[0] + 0.3), (room // 4) * (ROOM[1] + 0.3)])
        for label, x, y in ROOM_TYPES[kind](rng):
            if len(objects) == n_objects:
                break
            size = np.array(SIZES[label])
            heading = float(rng.choice([0.0, np.pi / 2, np.pi, -np.pi / 2]))
            jitter = MOVABLE_JITTER if label in MOVABLE else FIXED_JITTER
            heading += rng.normal(0, jitter[1])
            rotation = _yaw(heading)
            x, y = np.array([x, y]) + rng.normal(0, jitter[0], 2)
            centre = np.array([origin[0] + x, origin[1] + y, size[2] / 2])
            points = (
                _box_points(size, rotation, centre, points_per_object, rng)
                if points_per_object
                else None
            )
            objects.append(
                SemanticObject(f"{len(objects)}", label, centre, size=size, rotation=rotation,
                               points=points, extra={"room": room, "room_type": kind})
            )  # fmt: skip
        room += 1
    return ObjectMap(objects, up=[0, 0, 1], name=f"synthetic-{n_objects}-{seed}")


@dataclass(frozen=True)
class Observation:
    """A local map, the true pose T_global_local and the true (global id, local id) pairs."""

    local_map: ObjectMap
    T_global_local: np.ndarray
    true_pairs: list[tuple[str, str]]


def observe(
    global_map: ObjectMap,
    n_objects: int,
    seed: int,
    bias: tuple[float, float] = (0.1, 0.4),
    spurious: int = 1,
    wrong_label_rate: float = 0.05,
    position_noise: float = 0.02,
) -> Observation:
    """What a robot near a random object has seen: its `n_objects` nearest objects.

    Centres are biased towards the viewpoint by a length drawn from `bias` (partial views),
    `spurious` objects with random labels are added, labels are swapped at `wrong_label_rate`,
    and everything is expressed in a gravity-aligned frame at the viewpoint with a random yaw.
    """
    rng = np.random.default_rng(seed)
    positions = global_map.positions
    anchor = positions[rng.integers(len(global_map))]
    viewpoint = anchor + np.array([*rng.normal(0, 1.0, 2), 1.2 - anchor[2]])
    order = np.argsort(np.linalg.norm(positions[:, :2] - viewpoint[:2], axis=1))[:n_objects]
    local: list[tuple[str, np.ndarray]] = []
    for g in order:
        towards = viewpoint - positions[g]
        towards[2] = 0.0
        towards /= max(np.linalg.norm(towards), 1e-9)
        shift = towards * rng.uniform(*bias) + rng.normal(0, position_noise, 3)
        label = global_map[g].label
        if rng.random() < wrong_label_rate:
            label = str(rng.choice([x for x in LABELS if x != label]))
        local.append((label, positions[g] + shift))
    true_ids = [global_map[g].id for g in order]
    spread = positions[order].std(axis=0) + 0.5
    centre = positions[order].mean(axis=0)
    for _ in range(spurious):
        where = centre + rng.uniform(-1, 1, 3) * spread * np.array([1, 1, 0])
        local.append((str(rng.choice(LABELS)), where))
        true_ids.append("")
    seen_order = rng.permutation(len(local))  # detection order
    T = np.eye(4)
    T[:3, :3] = _yaw(rng.uniform(-np.pi, np.pi))
    T[:3, 3] = viewpoint  # the local (odometry) frame starts at the camera
    T_inv = np.linalg.inv(T)
    objects, pairs = [], []
    for rank, i in enumerate(seen_order):
        label, p = local[i]
        local_id = f"l{rank}"
        objects.append(SemanticObject(local_id, label, T_inv[:3, :3] @ p + T_inv[:3, 3],
                                      seen=rank))  # fmt: skip
        if true_ids[i]:
            pairs.append((true_ids[i], local_id))
    return Observation(ObjectMap(objects, up=[0, 0, 1], name="observation"), T, pairs)
