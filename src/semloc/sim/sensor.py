"""A pinhole RGB-D sensor by ray casting (Open3D `RaycastingScene`): depth + instance-id images.

Camera convention (OpenCV): x right, y down, z forward; `T_world_camera` maps camera
coordinates to world coordinates.  Depth is the z-depth in metres (0 = no return: nothing hit,
or beyond `max_depth`), as RGB-D sensors report it.  The instance image holds the index of the
world object hit (into `World.objects`) or -1 for background (walls, floor) and no return.
Depth noise follows the usual structured-light model, sigma(z) = a + b (z - 0.4)^2.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from semloc.frontend.segments import backproject as backproject_matrix
from semloc.io.interrupts import signals_held
from semloc.sim.shapes import Mesh
from semloc.sim.world import World

RESOLUTION_RANGE = ((16, 12), (1280, 960))
"""Smallest and largest depth image (width, height) the simulator's commands accept."""


def check_resolution(width: int, height: int) -> tuple[int, int]:
    """(width, height) if within `RESOLUTION_RANGE`, else a ValueError saying the range."""
    (w0, h0), (w1, h1) = RESOLUTION_RANGE
    if not (w0 <= width <= w1 and h0 <= height <= h1):
        raise ValueError(
            f"--resolution must be between {w0}x{h0} and {w1}x{h1}, got {width}x{height}"
        )
    return width, height


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics; `Intrinsics.scannet(w, h)` scales ScanNet's depth camera to w x h."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    @classmethod
    def scannet(cls, width: int = 240, height: int = 180) -> Intrinsics:
        if width < 8 or height < 8:
            raise ValueError(f"resolution must be at least 8 x 8, got {width} x {height}")
        sx, sy = width / 640.0, height / 480.0
        return cls(width, height, 577.87 * sx, 577.87 * sy, 319.5 * sx, 239.5 * sy)

    @property
    def matrix(self) -> np.ndarray:
        return np.array([[self.fx, 0, self.cx], [0, self.fy, self.cy], [0, 0, 1.0]])

    def ray_directions(self) -> np.ndarray:
        """(H, W, 3) camera-frame directions with z = 1 (so hit distance along them = z-depth)."""
        u, v = np.meshgrid(np.arange(self.width) + 0.0, np.arange(self.height) + 0.0)
        return np.stack(
            [(u - self.cx) / self.fx, (v - self.cy) / self.fy, np.ones_like(u)], axis=-1
        )


def backproject(depth: np.ndarray, K: Intrinsics, mask: np.ndarray | None = None) -> np.ndarray:
    """Camera-frame points (N, 3) of the valid depth pixels (inside `mask` if given)."""
    return backproject_matrix(depth, K.matrix, mask)


def look_at(
    eye: np.ndarray, target: np.ndarray, up: tuple[float, float, float] = (0.0, 0.0, 1.0)
) -> np.ndarray:
    """T_world_camera for a camera at `eye` looking at `target` (OpenCV axes, image up ~ `up`)."""
    z = np.asarray(target, float) - np.asarray(eye, float)
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    if np.linalg.norm(x) < 1e-6:
        x = np.cross(z, [1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([x, y, z])
    T[:3, 3] = eye
    return T


def camera_pose(position: np.ndarray, yaw: float, pitch: float = -0.3) -> np.ndarray:
    """T_world_camera for a camera at `position` heading `yaw` (about +z), tilted by `pitch`."""
    d = np.array(
        [math.cos(yaw) * math.cos(pitch), math.sin(yaw) * math.cos(pitch), math.sin(pitch)]
    )
    return look_at(np.asarray(position, float), np.asarray(position, float) + d)


@dataclass(frozen=True)
class Frame:
    """One rendered frame: depth (H, W) float32 metres, instance (H, W) int32, and the pose."""

    depth: np.ndarray
    instance: np.ndarray
    T_world_camera: np.ndarray


class DepthSensor:
    """Renders depth and instance images of a world (or of any meshes) by ray casting."""

    def __init__(
        self,
        world: World | None = None,
        intrinsics: Intrinsics | None = None,
        *,
        meshes: list[Mesh] | None = None,
        background: list[Mesh] | None = None,
        max_depth: float = 8.0,
        noise: tuple[float, float] = (0.0012, 0.0019),
    ) -> None:
        self.K = intrinsics or Intrinsics.scannet()
        self.max_depth = max_depth
        self.noise = noise
        objects = [o.mesh for o in world.objects] if world is not None else list(meshes or [])
        bg = list(world.background) if world is not None else list(background or [])
        with signals_held():  # an interrupt inside its initialisation would break open3d
            import open3d as o3d  # heavy optional dependency (the `sim` extra)

        self._o3d = o3d
        self._scene = o3d.t.geometry.RaycastingScene()
        self._instance_of: list[int] = []
        for i, mesh in enumerate(objects):
            self._add(mesh)
            self._instance_of.append(i)
        for mesh in bg:
            self._add(mesh)
            self._instance_of.append(-1)
        self._lookup = np.array(self._instance_of + [-1], dtype=np.int32)
        self._dirs = self.K.ray_directions().reshape(-1, 3)

    def _add(self, mesh: Mesh) -> None:
        self._scene.add_triangles(
            mesh.vertices.astype(np.float32), mesh.triangles.astype(np.uint32)
        )

    def cast(self, T_world_camera: np.ndarray) -> dict[str, np.ndarray]:
        """The raw ray cast of every pixel (row-major, flat): `depth` (0 = no return),
        `geometry` (index of the mesh hit in the order added: the world's objects, then its
        background; `len(meshes)` for no return), `primitive` (triangle index, its mesh's),
        `uv` (barycentric coordinates in it), `normal` (world frame) and `dirs` (world-frame
        ray directions with camera z = 1)."""
        R, t = T_world_camera[:3, :3], T_world_camera[:3, 3]
        dirs = self._dirs @ R.T
        rays = np.concatenate([np.broadcast_to(t, dirs.shape), dirs], axis=1).astype(np.float32)
        hits = self._scene.cast_rays(self._o3d.core.Tensor(rays))
        depth = hits["t_hit"].numpy().astype(np.float32)  # |dir| has z = 1: t is the z-depth
        geometry = hits["geometry_ids"].numpy().astype(np.int64)
        invalid = ~np.isfinite(depth) | (depth > self.max_depth)
        geometry[invalid] = len(self._lookup) - 1
        depth[invalid] = 0.0
        return {"depth": depth, "geometry": geometry, "dirs": dirs,
                "primitive": hits["primitive_ids"].numpy().astype(np.int64),
                "uv": hits["primitive_uvs"].numpy(),
                "normal": hits["primitive_normals"].numpy()}  # fmt: skip

    def noisy(self, depth: np.ndarray, rng: np.random.Generator | None) -> np.ndarray:
        """`depth` with the sensor's noise drawn from `rng` (unchanged without `rng`)."""
        if rng is None or self.noise == (0.0, 0.0):
            return depth
        a, b = self.noise
        sigma = a + b * (depth - 0.4) ** 2
        noisy = np.where(depth > 0, depth + rng.normal(size=depth.shape) * sigma, 0.0)
        return noisy.astype(np.float32)

    def render(self, T_world_camera: np.ndarray, rng: np.random.Generator | None = None) -> Frame:
        """Depth and instance image from `T_world_camera`; with `rng`, depth noise is added."""
        hits = self.cast(T_world_camera)
        depth, geometry = self.noisy(hits["depth"], rng), hits["geometry"]
        H, W = self.K.height, self.K.width
        return Frame(depth.reshape(H, W), self._lookup[geometry].reshape(H, W), T_world_camera)
