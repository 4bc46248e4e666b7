"""Seeded procedural indoor worlds: rooms on a grid with walls and doors, furnished by room kind.

`generate_world(seed, size)` returns a `World`: rooms (office, classroom, meeting room, bedroom,
kitchen, living room, bathroom), object instances (class, style, 4x4 pose in the world frame)
and background meshes (floor, walls with door openings).  Classrooms and meeting rooms hold rows
of identical chairs and desks; offices, kitchens and bedrooms repeat identical instances too, so
labels alone never identify an object.  Same seed and size give the same world, always.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np

from semloc.sim.shapes import STYLES, Mesh, ObjectModel, box, model

SIZES: dict[str, int] = {"tiny": 1, "small": 3, "medium": 6, "large": 12, "building": 24}
"""Number of rooms per named world size (tiny: one room of ~15 objects; building: hundreds)."""

ROOM_KINDS = ("classroom", "meeting", "office", "bedroom", "kitchen", "living", "bathroom")
WALL_HEIGHT = 2.6
WALL_THICKNESS = 0.1
DOOR_WIDTH = 1.0
MAX_ROOMS = 200
"""Most rooms of a generated world."""


def yaw_pose(x: float, y: float, yaw: float, z: float = 0.0) -> np.ndarray:
    """4x4 pose: rotation `yaw` about +z, translation (x, y, z)."""
    c, s = math.cos(yaw), math.sin(yaw)
    T = np.eye(4)
    T[:2, :2] = [[c, -s], [s, c]]
    T[:3, 3] = (x, y, z)
    return T


@dataclass(frozen=True)
class Room:
    """An axis-aligned room: interior bounds `lo`..`hi` (x, y) in metres."""

    index: int
    kind: str
    lo: tuple[float, float]
    hi: tuple[float, float]
    cell: tuple[int, int]

    @property
    def center(self) -> np.ndarray:
        return (np.asarray(self.lo) + np.asarray(self.hi)) / 2

    @property
    def extent(self) -> np.ndarray:
        return np.asarray(self.hi) - np.asarray(self.lo)

    def contains(self, xy: np.ndarray, margin: float = 0.0) -> bool:
        return bool(
            np.all(xy >= np.asarray(self.lo) + margin)
            and np.all(xy <= np.asarray(self.hi) - margin)
        )


@dataclass(frozen=True)
class Door:
    """An opening between two rooms: centre (x, y) and the axis the wall runs along (0=x, 1=y)."""

    center: tuple[float, float]
    axis: int
    rooms: tuple[int, int]


@dataclass(frozen=True)
class ObjectInstance:
    """One object in the world: class, style, pose (world frame), room, and what it stands on."""

    id: str
    label: str
    style: int
    pose: np.ndarray
    room: int
    support: str | None = None

    @property
    def model(self) -> ObjectModel:
        return model(self.label, self.style)

    @property
    def mesh(self) -> Mesh:
        return self.model.mesh.transformed(self.pose)

    @property
    def yaw(self) -> float:
        return math.atan2(self.pose[1, 0], self.pose[0, 0])

    @property
    def box_center(self) -> np.ndarray:
        """Centre of the oriented bounding box, world frame."""
        return self.pose[:3, :3] @ self.model.box_center + self.pose[:3, 3]

    def footprint(self, margin: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned (x, y) bounds of the rotated model footprint, grown by `margin`."""
        lo, hi = self.model.mesh.bounds
        corners = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]])
        xy = corners @ self.pose[:2, :2].T + self.pose[:2, 3]
        return xy.min(axis=0) - margin, xy.max(axis=0) + margin


@dataclass(frozen=True)
class World:
    """A generated indoor world: rooms, doors, objects and background (floor, walls)."""

    seed: int
    size: str
    rooms: tuple[Room, ...]
    doors: tuple[Door, ...]
    objects: tuple[ObjectInstance, ...]
    background: tuple[Mesh, ...] = field(repr=False)

    @cached_property
    def _index(self) -> dict[str, ObjectInstance]:
        return {o.id: o for o in self.objects}

    def object(self, object_id: str) -> ObjectInstance:
        return self._index[object_id]

    def with_objects(self, objects: Iterable[ObjectInstance]) -> World:
        """The same building with other furniture (used for the dynamic map)."""
        return replace(self, objects=tuple(objects))

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        lo = np.min([r.lo for r in self.rooms], axis=0)
        hi = np.max([r.hi for r in self.rooms], axis=0)
        return lo, hi

    def room_at(self, xy: np.ndarray) -> Room | None:
        for room in self.rooms:
            if room.contains(np.asarray(xy)):
                return room
        return None

    def walk_order(self) -> list[int]:
        """Rooms in snake order over the grid: consecutive rooms always share a door."""
        rows = sorted({r.cell[0] for r in self.rooms})
        order = []
        for k, row in enumerate(rows):
            cells = sorted((r for r in self.rooms if r.cell[0] == row), key=lambda r: r.cell[1])
            order += [r.index for r in (cells if k % 2 == 0 else cells[::-1])]
        return order

    def door_between(self, a: int, b: int) -> Door | None:
        for door in self.doors:
            if set(door.rooms) == {a, b}:
                return door
        return None

    def summary(self) -> dict:
        """A JSON-ready description (rooms, doors, objects with class, style and pose)."""
        return {
            "seed": self.seed,
            "size": self.size,
            "rooms": [
                {"index": r.index, "kind": r.kind, "lo": list(r.lo), "hi": list(r.hi)}
                for r in self.rooms
            ],
            "doors": [{"center": list(d.center), "rooms": list(d.rooms)} for d in self.doors],
            "objects": [
                {
                    "id": o.id, "label": o.label, "style": o.style, "room": o.room,
                    "support": o.support, "pose": np.round(o.pose, 6).tolist(),
                }
                for o in self.objects
            ],
        }  # fmt: skip


# Generation -----------------------------------------------------------------------------------
def generate_world(seed: int = 0, size: str | int = "small") -> World:
    """A furnished indoor world; `size` is a name in `SIZES` or a number of rooms."""
    n_rooms = _room_count(size)
    rng = np.random.default_rng([seed, n_rooms, 7])
    cols = math.ceil(math.sqrt(n_rooms)) if n_rooms > 3 else n_rooms
    n_rows = math.ceil(n_rooms / cols)
    widths = rng.uniform(6.0, 8.0, size=cols)
    depths = rng.uniform(5.5, 7.0, size=n_rows)
    xs, ys = np.concatenate([[0], np.cumsum(widths)]), np.concatenate([[0], np.cumsum(depths)])
    kinds = _room_kinds(n_rooms, rng)
    half = WALL_THICKNESS / 2
    rooms = []
    for i in range(n_rooms):
        r, c = divmod(i, cols)
        rooms.append(
            Room(
                i,
                kinds[i],
                (xs[c] + half, ys[r] + half),
                (xs[c + 1] - half, ys[r + 1] - half),
                (r, c),
            )
        )
    doors = _doors(rooms, rng)
    background = _background(rooms, doors)
    objects: list[ObjectInstance] = []
    for room in rooms:
        placer = _Placer(room, doors, rng, first_id=len(objects))
        _FURNISH[room.kind](placer)
        objects += placer.objects
    name = size if isinstance(size, str) else f"{n_rooms}-rooms"
    return World(seed, name, tuple(rooms), tuple(doors), tuple(objects), tuple(background))


def _room_count(size: str | int) -> int:
    if isinstance(size, str):
        if size.isdigit():
            return _room_count(int(size))
        if size not in SIZES:
            raise ValueError(
                f"unknown world size {size!r}; use one of {list(SIZES)} or a room count"
            )
        return SIZES[size]
    if not 1 <= int(size) <= MAX_ROOMS:
        raise ValueError(f"number of rooms must be between 1 and {MAX_ROOMS}, got {size}")
    return int(size)


def _room_kinds(n: int, rng: np.random.Generator) -> list[str]:
    if n == 1:
        return ["meeting"]
    first = str(rng.choice(["classroom", "meeting"]))
    others = [
        "office",
        "kitchen",
        "living",
        "bedroom",
        "classroom" if first == "meeting" else "meeting",
    ]
    kinds = [first]
    while len(kinds) < n:
        batch = list(others) + (["bathroom", "office"] if len(kinds) >= 5 else [])
        rng.shuffle(batch)
        kinds += batch
    return kinds[:n]


def _doors(rooms: list[Room], rng: np.random.Generator) -> list[Door]:
    by_cell = {r.cell: r for r in rooms}
    doors = []
    for room in rooms:
        r, c = room.cell
        right, up = by_cell.get((r, c + 1)), by_cell.get((r + 1, c))
        if right is not None:
            y = rng.uniform(room.lo[1] + 1.2, room.hi[1] - 1.2)
            doors.append(
                Door((room.hi[0] + WALL_THICKNESS / 2, float(y)), 1, (room.index, right.index))
            )
        if up is not None:
            x = rng.uniform(room.lo[0] + 1.2, room.hi[0] - 1.2)
            doors.append(
                Door((float(x), room.hi[1] + WALL_THICKNESS / 2), 0, (room.index, up.index))
            )
    return doors


def _background(rooms: list[Room], doors: list[Door]) -> list[Mesh]:
    """Floor plus walls (every room's four sides, shared sides once, door gaps cut out)."""
    lo = np.min([r.lo for r in rooms], axis=0) - WALL_THICKNESS
    hi = np.max([r.hi for r in rooms], axis=0) + WALL_THICKNESS
    meshes = [box(((lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, -0.01), (*(hi - lo), 0.02))]
    t, h = WALL_THICKNESS, WALL_HEIGHT
    segments: set[tuple[float, float, float, int]] = set()  # (fixed coordinate, start, end, axis)
    for room in rooms:
        (x0, y0), (x1, y1) = room.lo, room.hi
        segments |= {
            (round(y0 - t / 2, 6), x0 - t, x1 + t, 0), (round(y1 + t / 2, 6), x0 - t, x1 + t, 0),
            (round(x0 - t / 2, 6), y0 - t, y1 + t, 1), (round(x1 + t / 2, 6), y0 - t, y1 + t, 1),
        }  # fmt: skip
    for fixed, start, end, axis in sorted(segments):
        cuts = [
            (d.center[axis] - DOOR_WIDTH / 2, d.center[axis] + DOOR_WIDTH / 2)
            for d in doors
            if d.axis == axis
            and abs(d.center[1 - axis] - fixed) < 1e-3
            and start < d.center[axis] < end
        ]
        pieces, cursor = [], start
        for a, b in sorted(cuts):
            pieces.append((cursor, a))
            cursor = b
        pieces.append((cursor, end))
        for a, b in pieces:
            if b - a < 1e-3:
                continue
            mid = (a + b) / 2
            center = (mid, fixed, h / 2) if axis == 0 else (fixed, mid, h / 2)
            size = (b - a, t, h) if axis == 0 else (t, b - a, h)
            meshes.append(box(center, size))
    return meshes


class _Placer:
    """Places objects in one room in a room-local frame (u right, v towards the 'front' wall).

    The room-local frame is the room rotated by a random multiple of 90 degrees, so recipes can
    say "desks face the front wall" and rooms still come out in every orientation.
    """

    def __init__(self, room: Room, doors: list[Door], rng: np.random.Generator, first_id: int):
        self.room, self.rng = room, rng
        self.k = int(rng.integers(4))
        ext = room.extent
        self.U, self.V = (ext[0] / 2, ext[1] / 2) if self.k % 2 == 0 else (ext[1] / 2, ext[0] / 2)
        self.objects: list[ObjectInstance] = []
        self.next_id = first_id
        self.blocked: list[tuple[np.ndarray, np.ndarray]] = []
        for door in doors:  # keep door passages free
            c = np.asarray(door.center)
            if room.contains(c, margin=-0.5):
                half = (
                    np.array([DOOR_WIDTH / 2 + 0.3, 1.2])
                    if door.axis == 0
                    else np.array([1.2, DOOR_WIDTH / 2 + 0.3])
                )
                self.blocked.append((c - half, c + half))
        self.styles = {label: int(rng.integers(len(s))) for label, s in STYLES.items()}

    def style(self, label: str, fresh: bool = False) -> int:
        """The room's style for a class (repeated instances share it); `fresh` draws another."""
        return int(self.rng.integers(len(STYLES[label]))) if fresh else self.styles[label]

    def to_world(self, u: float, v: float) -> np.ndarray:
        a = self.k * math.pi / 2
        c, s = math.cos(a), math.sin(a)
        return self.room.center + np.array([c * u - s * v, s * u + c * v])

    def place(
        self, label: str, u: float, v: float, yaw: float, style: int | None = None,
        support: ObjectInstance | None = None, check: bool = True, margin: float = 0.05,
    ) -> ObjectInstance | None:  # fmt: skip
        """Put an object at room-local (u, v) with local heading `yaw`; None if it does not fit."""
        xy = self.to_world(u, v)
        z = support.model.height if support is not None else 0.0
        style = self.style(label) if style is None else style
        inst = ObjectInstance(
            str(self.next_id), label, style, yaw_pose(xy[0], xy[1], yaw + self.k * math.pi / 2, z),
            self.room.index, None if support is None else support.id,
        )  # fmt: skip
        lo, hi = inst.footprint()
        inside = np.all(lo >= np.asarray(self.room.lo) - 1e-6) and np.all(
            hi <= np.asarray(self.room.hi) + 1e-6
        )
        if not inside or (check and support is None and self._collides(inst, margin)):
            return None
        self.objects.append(inst)
        self.next_id += 1
        if support is None:
            self.blocked.append(inst.footprint())
        return inst

    def _collides(self, inst: ObjectInstance, margin: float) -> bool:
        lo, hi = inst.footprint(margin)
        return any(np.all(lo < b_hi) and np.all(hi > b_lo) for b_lo, b_hi in self.blocked)

    def at_wall(
        self,
        label: str,
        wall: str,
        t: float | None = None,
        style: int | None = None,
        tries: int = 25,
    ) -> ObjectInstance | None:
        """Back against `wall` ('front', 'back', 'left', 'right'), at fraction `t` along it."""
        style = self.style(label) if style is None else style
        lo, hi = model(label, style).mesh.bounds
        depth_back, half_w = -lo[1] + 0.03, max(abs(lo[0]), abs(hi[0])) + 0.02
        U, V = self.U, self.V
        along, yaw = {
            "back": (U, 0.0), "front": (U, math.pi),
            "left": (V, -math.pi / 2), "right": (V, math.pi / 2),
        }[wall]  # fmt: skip
        for i in range(tries):
            frac = t if (t is not None and i == 0) else self.rng.uniform(0.05, 0.95)
            s = -along + half_w + frac * max(2 * along - 2 * half_w, 0.0)
            u, v = {
                "back": (s, -V + depth_back), "front": (-s, V - depth_back),
                "left": (-U + depth_back, -s), "right": (U - depth_back, s),
            }[wall]  # fmt: skip
            inst = self.place(label, u, v, yaw, style=style)
            if inst is not None:
                return inst
        return None

    def on_top(self, label: str, support: ObjectInstance, offset: float = -0.12) -> ObjectInstance:
        """An object standing on `support` (e.g. a monitor on a desk), facing the same way."""
        pose = support.pose @ yaw_pose(0.0, offset, 0.0, support.model.height)
        inst = ObjectInstance(
            str(self.next_id), label, self.style(label), pose, self.room.index, support.id
        )
        self.objects.append(inst)
        self.next_id += 1
        return inst

    def in_front(
        self, label: str, of: ObjectInstance, distance: float, style: int | None = None
    ) -> ObjectInstance:
        """An object `distance` in front of `of`, facing it (a chair at a desk)."""
        pose = of.pose @ yaw_pose(0.0, distance, math.pi)
        pose[2, 3] = 0.0
        style = self.style(label) if style is None else style
        inst = ObjectInstance(str(self.next_id), label, style, pose, self.room.index)
        self.objects.append(inst)
        self.next_id += 1
        self.blocked.append(inst.footprint())
        return inst

    def anywhere(
        self, label: str, walls: Iterable[str] = ("back", "front", "left", "right")
    ) -> ObjectInstance | None:
        walls = list(walls)
        for _ in range(3):
            inst = self.at_wall(label, str(self.rng.choice(walls)))
            if inst is not None:
                return inst
        return None


# Room recipes -----------------------------------------------------------------------------------
def _furnish_classroom(p: _Placer) -> None:
    desk_style, chair_style = p.style("desk"), p.style("chair")
    n_cols = max(2, min(4, int((2 * p.U - 1.0) // 1.6)))
    n_rows = max(2, min(4, int((2 * p.V - 2.6) // 1.7)))
    us = (np.arange(n_cols) - (n_cols - 1) / 2) * 1.6
    for r in range(n_rows):
        v = p.V - 2.3 - r * 1.7
        for u in us:
            if p.place("desk", u, v, math.pi, style=desk_style) is not None:
                p.place("chair", u, v - 0.62, 0.0, style=chair_style, check=False)
    teacher = p.place("desk", 0.0, p.V - 1.0, 0.0, style=p.style("desk", fresh=True))
    if teacher is not None:
        p.place("chair", 0.0, p.V - 0.45, math.pi, style=1, check=False)
        p.on_top("monitor", teacher)
    p.at_wall("whiteboard", "front", t=0.2)
    style = p.style("cabinet")
    first = p.at_wall("cabinet", "back", t=0.1, style=style)
    if first is not None:
        p.at_wall("cabinet", "back", t=0.35, style=style)
    p.anywhere("bookshelf", ("left", "right"))
    p.anywhere("plant")


def _furnish_meeting(p: _Placer) -> None:
    n_tables = 2 if p.U > 3.0 else 1
    style, chair_style = p.style("table"), p.style("chair")
    for i in range(n_tables):
        u = (i - (n_tables - 1) / 2) * 1.7
        if p.place("table", u, 0.0, 0.0, style=style, margin=0.0) is None:
            continue
        for du in (-0.4, 0.4):
            p.place("chair", u + du, 0.78, math.pi, style=chair_style, check=False)
            p.place("chair", u + du, -0.78, 0.0, style=chair_style, check=False)
    p.at_wall("tv", "right", t=0.5) or p.at_wall("tv", "left")
    p.at_wall("whiteboard", "front")
    p.at_wall("low_cabinet", "back")
    p.anywhere("bookshelf", ("back", "front"))
    p.anywhere("plant")
    p.anywhere("lamp")


def _furnish_office(p: _Placer) -> None:
    desk_style = p.style("desk")
    desks = 0
    for wall in ("back", "front", "left", "back", "front"):
        if desks >= 4:
            break
        desk = p.at_wall("desk", wall, style=desk_style)
        if desk is None:
            continue
        desks += 1
        p.on_top("monitor", desk)
        p.in_front("chair", desk, 0.65, style=1)
    style = p.style("cabinet")
    first = p.at_wall("cabinet", "right", t=0.3, style=style)
    if first is not None:
        p.at_wall("cabinet", "right", t=0.55, style=style)
    p.anywhere("bookshelf")
    p.anywhere("plant")
    p.anywhere("lamp")


def _furnish_bedroom(p: _Placer) -> None:
    bed = p.at_wall("bed", "back", t=0.5)
    style = p.style("nightstand")
    if bed is not None:
        half = bed.model.extent[0] / 2 + 0.3
        for du in (-half, half):
            uv = _local_of(p, bed.pose @ np.array([du, -0.8, 0.0, 1.0]))
            p.place("nightstand", uv[0], uv[1], 0.0, style=style)
    p.anywhere("cabinet", ("left", "right"))
    desk = p.anywhere("desk", ("front", "left", "right"))
    if desk is not None:
        p.in_front("chair", desk, 0.62)
    p.anywhere("lamp")
    p.anywhere("plant")


def _furnish_kitchen(p: _Placer) -> None:
    wall = "back"
    p.at_wall("refrigerator", wall, t=0.0)
    style = p.style("low_cabinet")
    for t in (0.3, 0.5, 0.7):
        p.at_wall("low_cabinet", wall, t=t, style=style, tries=1)
    p.at_wall("sink", wall, t=0.95, tries=3) or p.anywhere("sink")
    table = p.place("table", 0.0, 0.3, 0.0)
    if table is not None:
        for du in (-0.4, 0.4):
            p.place("chair", du, 0.3 + 0.78, math.pi, check=False)
            p.place("chair", du, 0.3 - 0.78, 0.0, check=False)
    p.anywhere("cabinet", ("left", "right", "front"))
    p.anywhere("plant")


def _furnish_living(p: _Placer) -> None:
    sofa = p.at_wall("sofa", "back", t=0.5)
    v0 = -p.V + 0.5 if sofa is None else _local_of(p, sofa.pose[:, 3])[1]
    p.place("coffee_table", 0.0, v0 + 1.25, 0.0)
    style = p.style("armchair")
    p.place("armchair", -1.7, v0 + 1.3, -math.pi / 2, style=style)
    p.place("armchair", 1.7, v0 + 1.3, math.pi / 2, style=style)
    p.at_wall("tv", "front", t=0.5)
    p.anywhere("bookshelf", ("left", "right"))
    p.anywhere("lamp")
    p.anywhere("plant")
    p.anywhere("plant")
    p.anywhere("low_cabinet")


def _furnish_bathroom(p: _Placer) -> None:
    for label in ("toilet", "toilet", "sink", "sink"):
        p.at_wall(label, "back")
    p.anywhere("cabinet", ("left", "right"))
    p.anywhere("plant")


def _local_of(p: _Placer, point: np.ndarray) -> np.ndarray:
    a = -p.k * math.pi / 2
    d = np.asarray(point[:2]) - p.room.center
    return np.array(
        [math.cos(a) * d[0] - math.sin(a) * d[1], math.sin(a) * d[0] + math.cos(a) * d[1]]
    )


_FURNISH = {
    "classroom": _furnish_classroom, "meeting": _furnish_meeting, "office": _furnish_office,
    "bedroom": _furnish_bedroom, "kitchen": _furnish_kitchen, "living": _furnish_living,
    "bathroom": _furnish_bathroom,
}  # fmt: skip
