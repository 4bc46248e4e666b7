"""semloc with your own detector: depth + instance masks + camera poses -> objects -> pose.

Per frame your pipeline has a depth image, instance masks with labels (any segmenter) and the
camera pose from odometry (`T_odom_camera`).  `segments_from_masks` turns them into 3D
segments, `ObjectFusion` fuses the segments of all frames into local objects with stable ids,
and `Localizer.update` takes the objects that are new or changed after each frame.  The
answer is `T_global_odom`: where your odometry frame lies in the prior map.

Here the frames are made up by projecting the points of a small prior map into a camera that
turns around in the room, so the example runs anywhere with the core install:

    python examples/use_with_your_detector.py
"""

from __future__ import annotations

import numpy as np

import semloc
from semloc.frontend import ObjectFusion, segments_from_masks
from semloc.transforms import pose_error

rng = np.random.default_rng(0)


def box_points(centre, size, n=600):
    """Points on the surface of an axis-aligned box (a stand-in for a scanned object)."""
    points = rng.uniform(-0.5, 0.5, size=(n, 3))
    face = rng.integers(0, 3, size=n)
    points[np.arange(n), face] = np.sign(points[np.arange(n), face]) * 0.5
    return points * size + centre


# 1. The prior map (yours: `semloc.load_map("scene.json")`, e.g. from `semloc convert`).
ROOM = [
    ("table", (3.0, 2.0, 0.38), (1.6, 0.9, 0.76)), ("chair", (2.4, 1.2, 0.45), (0.5, 0.5, 0.9)),
    ("chair", (3.6, 1.2, 0.45), (0.5, 0.5, 0.9)), ("chair", (3.0, 2.9, 0.45), (0.5, 0.5, 0.9)),
    ("sofa", (0.7, 3.6, 0.4), (2.0, 0.9, 0.8)), ("lamp", (0.3, 0.4, 0.8), (0.35, 0.35, 1.6)),
    ("cabinet", (5.6, 3.5, 0.9), (0.6, 1.2, 1.8)), ("plant", (5.5, 0.4, 0.5), (0.5, 0.5, 1.0)),
    ("tv", (2.9, 4.4, 1.2), (1.2, 0.1, 0.7)), ("bookshelf", (0.2, 2.0, 1.0), (0.35, 1.0, 2.0)),
]  # fmt: skip
global_map = semloc.ObjectMap(
    [semloc.SemanticObject(f"g{i}", label, points=box_points(np.array(c), np.array(s)))
     for i, (label, c, s) in enumerate(ROOM)],
    up=[0, 0, 1],
)  # fmt: skip

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
    for index, obj in enumerate(global_map):
        p = (obj.points - t) @ R  # camera frame
        p = p[p[:, 2] > 0.3]
        u = np.round(K[0, 0] * p[:, 0] / p[:, 2] + K[0, 2]).astype(int)
        v = np.round(K[1, 1] * p[:, 1] / p[:, 2] + K[1, 2]).astype(int)
        inside = (u >= 0) & (u < WIDTH) & (v >= 0) & (v < HEIGHT)
        for uu, vv, z in zip(u[inside], v[inside], p[inside, 2]):
            if depth[vv, uu] == 0 or z < depth[vv, uu]:
                depth[vv, uu], owner[vv, uu] = z, index
    depth[depth > 0] += rng.normal(0.0, 0.01, size=int((depth > 0).sum()))  # sensor noise
    seen = [i for i in range(len(global_map)) if (owner == i).sum() >= 30]
    return depth, [owner == i for i in seen], [global_map[i].label for i in seen]


# 3. Your odometry frame is not the map's: semloc finds T_global_odom.
yaw = np.radians(35.0)
T_global_odom = np.eye(4)
T_global_odom[:3, :3] = [[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]]
T_global_odom[:3, 3] = [1.5, -0.8, 0.0]

fusion = ObjectFusion()
localizer = semloc.Localizer(global_map, local_up=[0, 0, 1])
result = None
for frame, heading in enumerate(np.radians(np.arange(0, 360, 20))):
    T_world_camera = camera_pose(heading)
    depth, masks, labels = detect(T_world_camera)
    T_odom_camera = np.linalg.inv(T_global_odom) @ T_world_camera  # from your odometry
    segments = segments_from_masks(depth, masks, labels, K)
    update = fusion.integrate(segments, T_odom_camera, frame="camera")
    if update.changed:  # objects that are new or moved
        result = localizer.update(fusion.objects(update.changed))
        print(f"frame {frame:2d}: {len(localizer.local_map)} local objects, {result.status}")

assert result is not None and result.pose is not None
rotation, translation = pose_error(result.pose, T_global_odom)
print(f"T_global_odom found: {result.status}, error {rotation:.2f} deg / {translation:.3f} m")
