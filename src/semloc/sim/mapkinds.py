"""Global object maps of a world in the three kinds of the paper's evaluation.

- `reconstruction_map`: what a scan of the world sees: per-object points gathered by ray casting
  from a mapping sweep through every room (partial: no undersides, occluded parts missing).
- `cad_map`: every object replaced by another style of its class (same pose), points sampled
  over the whole model surface, so shapes and point distributions differ from any scan.
- `dynamic_map`: the CAD map of a changed world: some objects deleted and at least 30 % of the
  remaining ones moved to new places and headings (`dynamic_world` says which).

Object ids are the world's instance ids; positions are the mean of the object points; boxes
(`size`, `rotation`) are the model's.  All maps are in the world frame with `up` = +z.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from semloc.maps import ObjectMap, SemanticObject
from semloc.pointsets import voxel_downsample
from semloc.sim.sensor import DepthSensor, Intrinsics, backproject, look_at
from semloc.sim.shapes import model, other_style
from semloc.sim.world import ObjectInstance, World, yaw_pose

VOXEL = 0.05


def _map_object(
    inst: ObjectInstance, points: np.ndarray, style: int | None = None
) -> SemanticObject:
    m = model(inst.label, inst.style if style is None else style)
    return SemanticObject(
        id=inst.id,
        label=inst.label,
        position=points.mean(axis=0),
        size=m.extent,
        rotation=inst.pose[:3, :3],
        points=points,
        extra={"style": m.style},
    )


def _cad_style(world: World, inst: ObjectInstance) -> int:
    """The replacement style of an object: fixed per (world seed, object id), never its own."""
    return other_style(
        inst.label, inst.style, np.random.default_rng([world.seed, int(inst.id), 11])
    )


def cad_points(inst: ObjectInstance, style: int, seed: int, density: float = 600.0) -> np.ndarray:
    """Points over the whole surface of `inst` rendered in `style` (voxel-downsampled)."""
    mesh = model(inst.label, style).mesh.transformed(inst.pose)
    n = int(np.clip(mesh.areas().sum() * density, 200, 20000))
    rng = np.random.default_rng([seed, int(inst.id), 13])
    return voxel_downsample(mesh.sample_surface(n, rng), VOXEL)


def cad_map(world: World) -> ObjectMap:
    """Every object replaced by another style of its class; whole-surface points."""
    objects = []
    for inst in world.objects:
        style = _cad_style(world, inst)
        objects.append(_map_object(inst, cad_points(inst, style, world.seed), style))
    return ObjectMap(objects, up=[0, 0, 1], name=f"{world.size}-{world.seed}-cad")


def scan_poses(world: World) -> list[np.ndarray]:
    """Mapping viewpoints: per room a ring looking inwards and a centre spin looking outwards."""
    poses = []
    for room in world.rooms:
        c, r = room.center, room.extent / 2
        for k in range(12):
            a = 2 * math.pi * k / 12
            eye = np.array([c[0] + 0.6 * r[0] * math.cos(a), c[1] + 0.6 * r[1] * math.sin(a), 1.6])
            poses.append(look_at(eye, np.array([c[0], c[1], 0.4])))
        for k in range(8):
            a = 2 * math.pi * k / 8
            eye = np.array([c[0], c[1], 1.3])
            target = eye + np.array([math.cos(a), math.sin(a), -0.45])
            poses.append(look_at(eye, target))
    return poses


def reconstruction_map(world: World, resolution: tuple[int, int] = (160, 120)) -> ObjectMap:
    """Per-object points as a mapping scan sees them (partial), with light depth noise."""
    K = Intrinsics.scannet(*resolution)
    sensor = DepthSensor(world, K)
    rng = np.random.default_rng([world.seed, 17])
    gathered: dict[int, list[np.ndarray]] = defaultdict(list)
    for T in scan_poses(world):
        frame = sensor.render(T, rng)
        for inst in np.unique(frame.instance[frame.instance >= 0]).tolist():
            pts = backproject(frame.depth, K, frame.instance == inst)
            gathered[inst].append(pts @ T[:3, :3].T + T[:3, 3])
    objects = []
    for i, inst in enumerate(world.objects):
        pts = (
            voxel_downsample(np.concatenate(gathered[i]), VOXEL)
            if gathered[i]
            else np.zeros((0, 3))
        )
        if len(pts) < 20:  # never scanned: fall back to the model surface
            pts = cad_points(inst, inst.style, world.seed, density=200.0)
        objects.append(_map_object(inst, pts))
    return ObjectMap(objects, up=[0, 0, 1], name=f"{world.size}-{world.seed}-reconstruction")


@dataclass(frozen=True)
class DynamicChanges:
    """How the dynamic world differs: deleted ids and moved ids (with their supported objects)."""

    deleted: tuple[str, ...]
    moved: tuple[str, ...]


def dynamic_world(
    world: World, delete_fraction: float = 0.1, move_fraction: float = 0.35
) -> tuple[World, DynamicChanges]:
    """Delete some objects and move at least `move_fraction` of the rest (new place and heading).

    Objects standing on others (monitors) go with their support.  Moves stay inside the
    object's room, at least 1 m away or turned by at least 45 degrees, without collisions.
    """
    rng = np.random.default_rng([world.seed, 19])
    children: dict[str, list[str]] = defaultdict(list)
    for o in world.objects:
        if o.support is not None:
            children[o.support].append(o.id)
    floor = [o for o in world.objects if o.support is None]
    n_delete = max(1, round(delete_fraction * len(world.objects)))
    deleted: set[str] = set()
    for o in rng.permutation(len(floor)).tolist():
        if len(deleted) >= n_delete:
            break
        if not children[floor[o].id]:
            deleted.add(floor[o].id)
    remaining = {o.id: o for o in world.objects if o.id not in deleted}
    target = math.ceil(move_fraction * len(remaining))
    moved: set[str] = set()
    for o in rng.permutation(len(floor)).tolist():
        inst = floor[o]
        if len(moved) >= target:
            break
        if inst.id in deleted:
            continue
        new = _move(world, inst, remaining, rng)
        if new is None:
            continue
        remaining[inst.id] = new
        moved.add(inst.id)
        for child_id in children[inst.id]:
            child = remaining[child_id]
            remaining[child_id] = replace(
                child, pose=new.pose @ np.linalg.inv(inst.pose) @ child.pose
            )
            moved.add(child_id)
    objects = [remaining[o.id] for o in world.objects if o.id in remaining]
    order = [o.id for o in world.objects]
    changes = DynamicChanges(
        tuple(sorted(deleted, key=order.index)), tuple(sorted(moved, key=order.index))
    )
    return world.with_objects(objects), changes


def _move(
    world: World, inst: ObjectInstance, others: dict[str, ObjectInstance], rng: np.random.Generator
) -> ObjectInstance | None:
    room = world.rooms[inst.room]
    boxes = [o.footprint(0.05) for o in others.values() if o.id != inst.id and o.support is None]
    for _ in range(60):
        xy = rng.uniform(room.lo, room.hi)
        yaw = rng.uniform(-math.pi, math.pi)
        turned = abs(math.remainder(yaw - inst.yaw, 2 * math.pi)) > math.radians(45)
        if np.linalg.norm(xy - inst.pose[:2, 3]) < 1.0 and not turned:
            continue
        cand = replace(inst, pose=yaw_pose(xy[0], xy[1], yaw, inst.pose[2, 3]))
        lo, hi = cand.footprint()
        if np.any(lo < np.asarray(room.lo)) or np.any(hi > np.asarray(room.hi)):
            continue
        if any(np.all(lo < b_hi) and np.all(hi > b_lo) for b_lo, b_hi in boxes):
            continue
        return cand
    return None


def dynamic_map(world: World) -> tuple[ObjectMap, DynamicChanges]:
    """The CAD map of the changed world (same replacement styles as `cad_map`)."""
    changed, changes = dynamic_world(world)
    objects = []
    for inst in changed.objects:
        style = _cad_style(world, inst)
        objects.append(_map_object(inst, cad_points(inst, style, world.seed), style))
    objmap = ObjectMap(objects, up=[0, 0, 1], name=f"{world.size}-{world.seed}-dynamic")
    return objmap, changes


MAP_KINDS: dict[str, Callable[[World], ObjectMap]] = {
    "reconstruction": reconstruction_map,
    "cad": cad_map,
    "dynamic": lambda world: dynamic_map(world)[0],
}
"""The registry of global-map kinds (name -> builder), in the order reports show them."""


def global_map(world: World, kind: str) -> ObjectMap:
    """One global map of `world` by kind name."""
    if kind not in MAP_KINDS:
        raise ValueError(f"unknown map kind {kind!r}; use one of {list(MAP_KINDS)}")
    return MAP_KINDS[kind](world)


def map_world(world: World, kind: str) -> World:
    """The world as the global map `kind` shows it (for rendering its images): the world
    itself for `reconstruction`; for `cad` every object in its replacement style; for
    `dynamic` the changed world in the replacement styles."""
    if kind not in MAP_KINDS:
        raise ValueError(f"unknown map kind {kind!r}; use one of {list(MAP_KINDS)}")
    if kind == "reconstruction":
        return world
    source = dynamic_world(world)[0] if kind == "dynamic" else world
    return source.with_objects(
        replace(inst, style=_cad_style(world, inst)) for inst in source.objects
    )
