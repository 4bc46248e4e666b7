"""Camera paths through a world: walks through rooms and orbits inside one room, as keyframes.

A path is a dense sequence of (x, y, heading) samples; keyframes are picked at equal steps of
"motion" (metres travelled + 0.5 m per radian turned), like a SLAM keyframe selector.  Inside a
room the camera circles the room looking across it; between rooms it walks through the door
looking ahead.  Returns `T_world_camera` poses (OpenCV camera axes) tilted down to see furniture.
"""

from __future__ import annotations

import math

import numpy as np

from semloc.sim.sensor import camera_pose
from semloc.sim.world import World

PATHS = ("walk", "orbit")
CAMERA_HEIGHT = 1.4
PITCH = -0.35


def _loop(world: World, room_index: int, start: float, sweep: float, scale: float) -> np.ndarray:
    """Samples (x, y, yaw) on an ellipse in a room, looking towards the far side of the room."""
    room = world.rooms[room_index]
    c, r = room.center, room.extent / 2 * scale
    angles = start + np.linspace(0.0, sweep, max(8, int(abs(sweep) / 0.05)))
    xy = c + np.column_stack([r[0] * np.cos(angles), r[1] * np.sin(angles)])
    yaw = np.arctan2(c[1] - xy[:, 1], c[0] - xy[:, 0])
    return np.column_stack([xy, yaw])


def _segment(a: np.ndarray, b: np.ndarray, step: float = 0.05) -> np.ndarray:
    """Straight walk from a to b (x, y), looking ahead."""
    n = max(2, int(np.linalg.norm(b - a) / step))
    xy = a + np.linspace(0, 1, n)[:, None] * (b - a)
    yaw = math.atan2(b[1] - a[1], b[0] - a[0])
    return np.column_stack([xy, np.full(n, yaw)])


def _angle_of(world: World, room_index: int, xy: np.ndarray) -> float:
    room = world.rooms[room_index]
    d = (np.asarray(xy) - room.center) / (room.extent / 2)
    return math.atan2(d[1], d[0])


def walk_samples(world: World, n_rooms: int = 2, scale: float = 0.33) -> np.ndarray:
    """Dense (x, y, yaw) samples: a loop in each of the first `n_rooms` rooms, through doors."""
    order = world.walk_order()[: max(1, n_rooms)]
    parts, entry = [], None
    for k, room in enumerate(order):
        start = 0.0 if entry is None else _angle_of(world, room, entry)
        sweep = 2 * math.pi if k == len(order) - 1 else 1.6 * math.pi
        loop = _loop(world, room, start, sweep, scale)
        if entry is not None:
            parts.append(_segment(entry, loop[0, :2]))
        parts.append(loop)
        if k + 1 < len(order):
            door = world.door_between(room, order[k + 1])
            if door is None:  # rooms of a partial last row: fall back to a straight walk
                nxt = world.rooms[order[k + 1]].center
                parts.append(_segment(loop[-1, :2], nxt))
                entry = nxt
                continue
            normal = np.array([0.0, 1.0]) if door.axis == 0 else np.array([1.0, 0.0])
            here = world.rooms[room].center
            side = np.sign(np.dot(np.asarray(door.center) - here, normal)) or 1.0
            before = np.asarray(door.center) - side * 0.8 * normal
            after = np.asarray(door.center) + side * 0.8 * normal
            parts += [_segment(loop[-1, :2], before), _segment(before, after)]
            entry = after
    return np.concatenate(parts)


def orbit_samples(
    world: World, room: int = 0, scale: float = 0.38, turns: float = 1.0
) -> np.ndarray:
    """Dense (x, y, yaw) samples circling one room, looking across it."""
    return _loop(world, room, 0.0, 2 * math.pi * turns, scale)


def keyframes_from_samples(
    samples: np.ndarray, n_keyframes: int, rng: np.random.Generator | None = None
) -> np.ndarray:
    """(n, 4, 4) T_world_camera at equal steps of motion along the samples."""
    if n_keyframes < 1:
        raise ValueError(f"need at least one keyframe, got {n_keyframes}")
    step = np.linalg.norm(np.diff(samples[:, :2], axis=0), axis=1)
    turn = np.abs(np.angle(np.exp(1j * np.diff(samples[:, 2]))))
    s = np.concatenate([[0.0], np.cumsum(step + 0.5 * turn)])
    picks = np.searchsorted(s, np.linspace(0, s[-1], n_keyframes)).clip(0, len(samples) - 1)
    poses = []
    for i in picks:
        x, y, yaw = samples[i]
        height, pitch = CAMERA_HEIGHT, PITCH
        if rng is not None:
            height += rng.normal(0, 0.03)
            pitch += rng.normal(0, 0.03)
            yaw += rng.normal(0, 0.05)
        poses.append(camera_pose(np.array([x, y, height]), yaw, pitch))
    return np.stack(poses)


def camera_path(
    world: World, kind: str = "walk", n_keyframes: int = 40, n_rooms: int = 2, seed: int = 0
) -> np.ndarray:
    """Keyframe poses T_world_camera (n, 4, 4) for a named path kind ('walk' or 'orbit')."""
    if kind == "walk":
        samples = walk_samples(world, n_rooms)
    elif kind == "orbit":
        samples = orbit_samples(world, world.walk_order()[0])
    else:
        raise ValueError(f"unknown camera path {kind!r}; use one of {list(PATHS)}")
    return keyframes_from_samples(samples, n_keyframes, np.random.default_rng([seed, 3]))


def odometry_origin(T_world_camera: np.ndarray) -> np.ndarray:
    """T_world_odom: the first camera pose made gravity-aligned (its heading, z up, same place).

    The local (odometry) frame therefore has `up` = +z like the world, but another origin and
    heading, so the true T_global_local is a non-trivial 4-DoF transform.
    """
    forward = T_world_camera[:3, 2]
    yaw = math.atan2(forward[1], forward[0])
    T = np.eye(4)
    T[:2, :2] = [[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]]
    T[:3, 3] = T_world_camera[:3, 3]
    return T
