"""The image side of the evaluation: keyframe maps and query keyframes of simulated sequences.

Image methods (SIFT) localize query keyframes against the global map's keyframes.  For a
simulated sequence, `keyframe_map(world, kind)` renders the mapping sweep of the global map
`kind` by day (`semloc.sim.colour.map_keyframes`) and `query_frame(world, keyframe, light)` the
keyframe of a (replayed) sequence at its true pose, posed at its odometry pose (the local
frame), lit by `light` ("day" or "night", `semloc.sim.illumination`).  A walk through a real
scan with vertex colours works the same way for its reconstruction map (the scan's own mapping
walk, `semloc.sim.realscan.map_keyframes`); its CAD map has no images.  Both are
deterministic (seeded by the world's seed and the keyframe index) and cached per process:
every method, start and illumination of a worker shares the renderings (maps: the last 6;
daylight keyframes: the last 400; relighting is cheap and not cached).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from semloc.baselines.recent import Recent
from semloc.frontend.frames import KeyframeMap, RGBDFrame
from semloc.maps import MapError
from semloc.sim import realscan
from semloc.sim.colour import ColourSensor, map_keyframes
from semloc.sim.illumination import ILLUMINATIONS, relight
from semloc.sim.realscan import RealScan
from semloc.sim.world import World

Scene = World | RealScan

_MAPS = Recent(6)  # (world, map kind) -> its keyframes
_SENSORS = Recent(2)  # world -> its colour sensor
_FRAMES = Recent(400)  # (world, keyframe) -> the daylight frame


def has_images(world: Any, kind: str) -> bool:
    """Whether the global map `kind` of `world` can be rendered as keyframes."""
    if isinstance(world, RealScan):
        return kind == "reconstruction" and world.colours is not None
    return isinstance(world, World)


def _seed(world: Scene) -> int:
    return world.seed if isinstance(world, World) else 0


def keyframe_map(world: Scene, kind: str) -> KeyframeMap:
    """The global map `kind` of `world` as day keyframes (cached)."""
    if not has_images(world, kind):
        raise MapError(f"the {kind} map of {type(world).__name__} {getattr(world, 'name', '')} "
                       "has no images for image methods")  # fmt: skip
    if isinstance(world, RealScan):
        make = lambda: realscan.map_keyframes(world)  # noqa: E731
    else:
        make = lambda: map_keyframes(world, kind)  # noqa: E731
    return _MAPS.get((id(world), kind), make, owner=world)


def _sensor(world: Scene) -> ColourSensor:
    return world.colour_sensor() if isinstance(world, RealScan) else ColourSensor(world)


def _daylight(world: Scene, index: int, T_world_camera: np.ndarray) -> RGBDFrame:
    sensor = _SENSORS.get(id(world), lambda: _sensor(world), owner=world)

    def render() -> RGBDFrame:
        rng = np.random.default_rng([_seed(world), index, 31])
        return sensor.render(T_world_camera, index, rng)

    return _FRAMES.get((id(world), index), render, owner=world)


def query_frame(world: Scene, keyframe, light: str = "day") -> RGBDFrame:
    """Keyframe `keyframe` (a `semloc.sim.scenario.Keyframe`) in colour under `light`, posed
    in the local (odometry) frame."""
    if not has_images(world, "reconstruction"):
        raise MapError(f"{type(world).__name__} {getattr(world, 'name', '')} has no colour")
    if light not in ILLUMINATIONS:
        raise ValueError(f"unknown illumination {light!r}; use one of {list(ILLUMINATIONS)}")
    frame = _daylight(world, keyframe.index, keyframe.T_world_camera)
    frame = replace(frame, T_frame_camera=keyframe.T_odom_camera)
    rng = np.random.default_rng(
        [_seed(world), keyframe.index, 41, list(ILLUMINATIONS).index(light)]
    )
    return relight(frame, ILLUMINATIONS[light], rng)
