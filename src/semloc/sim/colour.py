"""Colour images of the simulated worlds by ray casting: RGB-D keyframes for image methods.

`ColourSensor(world)` casts the same rays as `DepthSensor` and colours each hit from its
surface: objects by the solid texture of their model (`texture_for("label/style")`, in the
object's frame, so a moved object keeps its look), floor and walls by a texture of their own
(world frame), shaded Lambertian under a fixed daylight direction plus ambient light.  Real
scans (`ColourSensor.of_meshes` with `VertexColours`) take the mesh's vertex colours,
interpolated over the triangle hit, unshaded (the scan's colours hold its lighting).  Rays
that hit nothing are black.  The output is "daylight" colour, 8-bit; other illuminations are
applied to it afterwards (`semloc.sim.illumination`).

`map_keyframes(world, kind)` renders the mapping sweep of a global map kind (the viewpoints
`semloc.sim.mapkinds.scan_poses` uses for the reconstruction map) through the world as that
map shows it (`map_world`), as a `KeyframeMap` in the world frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from semloc.frontend.frames import KeyframeMap, RGBDFrame
from semloc.sim.mapkinds import map_world, scan_poses
from semloc.sim.sensor import DepthSensor, Intrinsics
from semloc.sim.shapes import Mesh
from semloc.sim.textures import Texture, texture_for
from semloc.sim.world import World

LIGHT = np.array([0.35, 0.55, 0.76])
"""Direction towards the daylight (world frame, unit length)."""
AMBIENT = 0.45


@dataclass(frozen=True)
class Solid:
    """A surface coloured by a solid texture in its own frame (`T_surface_world`), shaded."""

    texture: Texture
    T_surface_world: np.ndarray
    shaded = True

    def colour(self, points: np.ndarray, primitive: np.ndarray, uv: np.ndarray) -> np.ndarray:
        T = self.T_surface_world
        return self.texture.colour(points @ T[:3, :3].T + T[:3, 3])


@dataclass(frozen=True)
class VertexColours:
    """A mesh surface coloured by its vertex colours (V, 3) in [0, 1], unshaded."""

    colours: np.ndarray
    triangles: np.ndarray
    shaded = False

    def colour(self, points: np.ndarray, primitive: np.ndarray, uv: np.ndarray) -> np.ndarray:
        corners = self.colours[self.triangles[primitive]]  # (N, 3 corners, 3)
        u, v = uv[:, :1], uv[:, 1:2]
        return (1 - u - v) * corners[:, 0] + u * corners[:, 1] + v * corners[:, 2]


Surface = Solid | VertexColours


def surface_textures(world: World) -> list[Surface]:
    """The surface of every mesh of `world`, in `DepthSensor`'s order: objects, background."""
    out: list[Surface] = [Solid(texture_for(f"{o.label}/{o.style}"), np.linalg.inv(o.pose))
                          for o in world.objects]  # fmt: skip
    out += [Solid(texture_for(f"{world.size}-{world.seed}/background{i}"), np.eye(4))
            for i in range(len(world.background))]  # fmt: skip
    return out


class ColourSensor:
    """Renders colour and depth images of a world (see the module docstring)."""

    def __init__(self, world: World, intrinsics: Intrinsics | None = None, **kwargs) -> None:
        self.depth_sensor = DepthSensor(world, intrinsics, **kwargs)
        self.K = self.depth_sensor.K
        self.surfaces = surface_textures(world)

    @classmethod
    def of_meshes(
        cls,
        meshes: list[Mesh],
        surfaces: list[Surface],
        intrinsics: Intrinsics | None = None,
        **kwargs,
    ) -> ColourSensor:
        """A sensor of any meshes (all background: instance -1) with one surface each."""
        if len(meshes) != len(surfaces):
            raise ValueError(f"{len(meshes)} meshes but {len(surfaces)} surfaces")
        sensor = cls.__new__(cls)
        sensor.depth_sensor = DepthSensor(intrinsics=intrinsics, background=meshes, **kwargs)
        sensor.K = sensor.depth_sensor.K
        sensor.surfaces = list(surfaces)
        return sensor

    def render(
        self,
        T_world_camera: np.ndarray,
        index: int = 0,
        rng: np.random.Generator | None = None,
        T_frame_camera: np.ndarray | None = None,
    ) -> RGBDFrame:
        """The keyframe seen from `T_world_camera` (posed at `T_frame_camera`, default the
        world pose); with `rng`, the depth gets the sensor's noise."""
        hits = self.depth_sensor.cast(T_world_camera)
        depth, geometry = hits["depth"], hits["geometry"]
        points = T_world_camera[:3, 3] + hits["dirs"] * depth[:, None]
        rgb = np.zeros((len(depth), 3))
        shade = AMBIENT + (1 - AMBIENT) * np.abs(hits["normal"] @ LIGHT)
        for g in np.unique(geometry[depth > 0]).tolist():
            surface, sel = self.surfaces[g], geometry == g
            colour = surface.colour(points[sel], hits["primitive"][sel], hits["uv"][sel])
            rgb[sel] = colour * shade[sel, None] if surface.shaded else colour
        rgb = np.clip(rgb, 0.0, 1.0)
        depth = self.depth_sensor.noisy(depth, rng)
        H, W = self.K.height, self.K.width
        return RGBDFrame(
            index, np.round(rgb * 255).astype(np.uint8).reshape(H, W, 3),
            depth.astype(np.float32).reshape(H, W), self.K.matrix,
            T_world_camera if T_frame_camera is None else T_frame_camera,
        )  # fmt: skip


def map_keyframes(
    world: World, kind: str = "reconstruction", resolution: tuple[int, int] = (240, 180)
) -> KeyframeMap:
    """The global map `kind` of `world` as day keyframes of its mapping sweep (world frame)."""
    sensor = ColourSensor(map_world(world, kind), Intrinsics.scannet(*resolution))
    rng = np.random.default_rng([world.seed, 37])
    frames = [sensor.render(T, i, rng) for i, T in enumerate(scan_poses(world))]
    return KeyframeMap.of(frames, up=(0, 0, 1), name=f"{world.size}-{world.seed}-{kind}-keyframes")
