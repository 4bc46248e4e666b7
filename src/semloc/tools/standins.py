"""Stand-ins for a camera and a detector, for the README's "use it with your detector" example
(`examples/use_with_your_detector.py` runs it), importable from anywhere:

    from semloc.tools.standins import K, MAP_FILE, your_frames

`your_frames()` yields what your pipeline gives per frame (depth in metres, instance masks,
their labels and `T_odom_camera`), made up by projecting points on the surfaces of the example
room's objects (`MAP_FILE`) into a camera turning around in the room; `K` is its 3 x 3
pinhole intrinsics.  The odometry frame is `T_GLOBAL_ODOM` away from the map's: what semloc
finds.  Core install only (numpy).
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np

from semloc.io import load_map

MAP_FILE = Path(__file__).resolve().parent / "example_room.json"
"""The example room's map (the same as the checkout's `examples/global.json`)."""

rng = np.random.default_rng(0)


def box_points(centre, size, n=600):
    """Points on the surface of a box (a stand-in for a scanned object)."""
    points = rng.uniform(-0.5, 0.5, size=(n, 3))
    face = rng.integers(0, 3, size=n)
    points[np.arange(n), face] = np.sign(points[np.arange(n), face]) * 0.5
    return points * size + centre


# 1. The world the camera sees: dense points on the prior map's objects (their boxes).
WORLD = [(obj.label, box_points(obj.position, obj.size)) for obj in load_map(MAP_FILE)]

# 2. The camera: pinhole intrinsics, and poses turning around at (3, 2) (OpenCV axes).
K = np.array([[120.0, 0, 80], [0, 120.0, 60], [0, 0, 1]])
WIDTH, HEIGHT = 160, 120


def camera_pose(yaw: float) -> np.ndarray:
    """T_world_camera of a level camera at (3, 2, 1.3) looking along `yaw`."""
    forward = np.array([np.cos(yaw), np.sin(yaw), 0.0])
    right = np.cross(forward, [0, 0, 1])
    T = np.eye(4)
    T[:3, :3] = np.column_stack([right, np.cross(forward, right), forward])  # x right, y down
    T[:3, 3] = [3.0, 2.0, 1.3]
    return T


def detect(T_world_camera: np.ndarray):
    """What your detector gives for one frame: depth (m), instance masks and their labels.

    Made up here by projecting the map's points with a z-buffer."""
    depth = np.zeros((HEIGHT, WIDTH))
    owner = np.full((HEIGHT, WIDTH), -1)
    R, t = T_world_camera[:3, :3], T_world_camera[:3, 3]
    for index, (_, points) in enumerate(WORLD):
        p = (points - t) @ R  # camera frame
        p = p[p[:, 2] > 0.3]
        u = np.round(K[0, 0] * p[:, 0] / p[:, 2] + K[0, 2]).astype(int)
        v = np.round(K[1, 1] * p[:, 1] / p[:, 2] + K[1, 2]).astype(int)
        inside = (u >= 0) & (u < WIDTH) & (v >= 0) & (v < HEIGHT)
        for uu, vv, z in zip(u[inside], v[inside], p[inside, 2]):
            if depth[vv, uu] == 0 or z < depth[vv, uu]:
                depth[vv, uu], owner[vv, uu] = z, index
    depth[depth > 0] += rng.normal(0.0, 0.01, size=int((depth > 0).sum()))  # sensor noise
    seen = [i for i in range(len(WORLD)) if (owner == i).sum() >= 30]
    return depth, [owner == i for i in seen], [WORLD[i][0] for i in seen]


# 3. Your odometry frame is not the map's: semloc finds T_global_odom.
yaw = np.radians(35.0)
T_GLOBAL_ODOM = np.eye(4)
T_GLOBAL_ODOM[:3, :3] = [[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]]
T_GLOBAL_ODOM[:3, 3] = [1.5, -0.8, 0.0]


def your_frames() -> Iterator[tuple[np.ndarray, list[np.ndarray], list[str], np.ndarray]]:
    """Depth, masks, labels and `T_odom_camera` of each frame: what your pipeline gives."""
    for heading in np.radians(np.arange(0, 360, 20)):
        T_world_camera = camera_pose(heading)
        depth, masks, labels = detect(T_world_camera)
        yield depth, masks, labels, np.linalg.inv(T_GLOBAL_ODOM) @ T_world_camera
