"""The image side of the evaluation: keyframe maps and query keyframes of simulated sequences.

Image methods (SIFT) localize query keyframes against the global map's keyframes.  For a
simulated sequence, `keyframe_map(world, kind)` renders the mapping sweep of the global map
`kind` by day (`semloc.sim.colour.map_keyframes`) and `query_frame(world, keyframe, light)` the
keyframe of a (replayed) sequence at its true pose, posed at its odometry pose (the local
frame), lit by `light` ("day" or "night", `semloc.sim.illumination`).  Both are deterministic
(seeded by the world's seed and the keyframe index) and cached per process: every method,
start and illumination of a worker shares the renderings (maps: the last 6; daylight
keyframes: the last 400; relighting is cheap and not cached).
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import replace
from typing import Any

import numpy as np

from semloc.frontend.frames import KeyframeMap, RGBDFrame
from semloc.sim.colour import ColourSensor, map_keyframes
from semloc.sim.illumination import ILLUMINATIONS, relight
from semloc.sim.world import World

_MAPS: OrderedDict[tuple, tuple[World, KeyframeMap]] = OrderedDict()
_SENSORS: OrderedDict[int, tuple[World, ColourSensor]] = OrderedDict()
_FRAMES: OrderedDict[tuple, tuple[World, RGBDFrame]] = OrderedDict()


def _cached(cache: OrderedDict, key: Any, world: World, make, size: int):
    hit = cache.pop(key, None)
    if hit is None or hit[0] is not world:  # an id can be reused by a new object
        hit = (world, make())
    cache[key] = hit
    while len(cache) > size:
        cache.popitem(last=False)
    return hit[1]


def _world(world: Any) -> World:
    if not isinstance(world, World):
        raise ValueError(
            f"image methods need colour images; {type(world).__name__} scenes have none "
            "(only the simulated worlds are rendered in colour)"
        )
    return world


def keyframe_map(world: World, kind: str) -> KeyframeMap:
    """The global map `kind` of `world` as day keyframes (cached)."""
    world = _world(world)
    return _cached(_MAPS, (id(world), kind), world, lambda: map_keyframes(world, kind), 6)


def _daylight(world: World, index: int, T_world_camera: np.ndarray) -> RGBDFrame:
    sensor = _cached(_SENSORS, id(world), world, lambda: ColourSensor(world), 2)

    def render() -> RGBDFrame:
        return sensor.render(T_world_camera, index, np.random.default_rng([world.seed, index, 31]))

    return _cached(_FRAMES, (id(world), index), world, render, 400)


def query_frame(world: World, keyframe, light: str = "day") -> RGBDFrame:
    """Keyframe `keyframe` (a `semloc.sim.scenario.Keyframe`) in colour under `light`, posed
    in the local (odometry) frame."""
    world = _world(world)
    if light not in ILLUMINATIONS:
        raise ValueError(f"unknown illumination {light!r}; use one of {list(ILLUMINATIONS)}")
    frame = _daylight(world, keyframe.index, keyframe.T_world_camera)
    frame = replace(frame, T_frame_camera=keyframe.T_odom_camera)
    rng = np.random.default_rng([world.seed, keyframe.index, 41, list(ILLUMINATIONS).index(light)])
    return relight(frame, ILLUMINATIONS[light], rng)
