"""Real scans as simulator worlds: ray-cast a real mesh, walk a camera through its free space.

`load_real_scan(folder)` reads a ScanNet scene folder (mesh, `.segs.json`, `.aggregation.json`)
or a Scan2CAD scene folder (mesh, label mesh, `scan2cad_annotation.json`, ShapeNet models beside
it) into a `RealScan`: the mesh, one instance per face (the scan's own labels: the importers'
objects, whose un-downsampled points are mesh vertices, give each vertex its instance; a face
takes the instance two or three of its vertices share, else it is background), and the global
maps of the scene as the importers build them (ScanNet: `reconstruction`; Scan2CAD:
`reconstruction` from the labelled scan and `cad` from the aligned models).  Instance `i` of
the images is `scan.objects[i]`, whose `id` is the object's id in those maps.

Scans whose mesh has vertex colours (ScanNet's `_vh_clean_2.ply`) keep them (`colours`):
`colour_sensor` renders colour images of the scan for the image methods, and
`map_keyframes(scan)` the scan's reconstruction map as keyframes: a mapping walk of its own
(seed `MAP_WALK_SEED`), rendered by day.

`walk_path(scan, n_keyframes, seed)` is a path a person would take: waypoints spread over the
free floor (floor below, nothing between knee and head height within `clearance`), joined by
shortest grid paths, at eye height, heading between the way ahead and the middle of the room
while looking left and right.  `simulate_walk` renders, "detects" (the simulator's noise model)
and fuses the keyframes exactly like `simulate_sequence`, so `replay`, the demo and the
benchmark's attempts work on real scans unchanged.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import shortest_path
from scipy.spatial import cKDTree

from semloc.frontend.frames import KeyframeMap
from semloc.frontend.fusion import FusionConfig
from semloc.io.importers.scan2cad import load_scan2cad
from semloc.io.importers.scannet import load_scannet, scene_files
from semloc.io.ply import read_ply
from semloc.maps import MapError, ObjectMap
from semloc.pointsets import voxel_downsample
from semloc.sim.colour import ColourSensor, VertexColours
from semloc.sim.noise import Detection, DetectionNoise, detect, drift
from semloc.sim.scenario import Recording, SimulatedSequence
from semloc.sim.sensor import DepthSensor, Intrinsics
from semloc.sim.shapes import Mesh
from semloc.sim.trajectory import keyframes_from_samples, odometry_origin

CELL = 0.1
"""Edge of the free-space grid cells (m)."""
MAP_WALK_SEED = 9001
"""Seed of the walk whose keyframes make a scan's keyframe map (not one of the query walks)."""


@dataclass(frozen=True)
class ScanInstance:
    """One labelled instance of a scan: its id in the scene's global maps and its label."""

    id: str
    label: str


@dataclass(frozen=True)
class RealScan:
    """A real mesh with per-face instances and the scene's global maps (mesh frame, z up)."""

    name: str
    source: str  # "scannet" or "scan2cad"
    mesh: Mesh = field(repr=False)
    face_instance: np.ndarray = field(repr=False)  # (F,) index into `objects`, -1 background
    objects: tuple[ScanInstance, ...]
    global_maps: dict[str, ObjectMap] = field(repr=False)
    colours: np.ndarray | None = field(default=None, repr=False)  # (V, 3) in [0, 1]

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(x, y) bounds of the mesh."""
        return self.mesh.vertices[:, :2].min(axis=0), self.mesh.vertices[:, :2].max(axis=0)

    @property
    def floor_height(self) -> float:
        return float(np.percentile(self.mesh.vertices[:, 2], 1.0))

    def sensor(self, intrinsics: Intrinsics | None = None, **kwargs) -> DepthSensor:
        """A ray-casting sensor whose instance image holds indices into `objects`."""
        meshes = [self._submesh(self.face_instance == i) for i in range(len(self.objects))]
        background = [self._submesh(self.face_instance < 0)]
        return DepthSensor(intrinsics=intrinsics, meshes=meshes, background=background, **kwargs)

    def colour_sensor(self, intrinsics: Intrinsics | None = None, **kwargs) -> ColourSensor:
        """A sensor of colour (the vertex colours) and depth; MapError without colours."""
        if self.colours is None:
            raise MapError(f"{self.name}: the scan's mesh has no vertex colours")
        surface = VertexColours(self.colours, self.mesh.triangles)
        return ColourSensor.of_meshes([self.mesh], [surface], intrinsics, **kwargs)

    def _submesh(self, faces: np.ndarray) -> Mesh:
        triangles = self.mesh.triangles[faces]
        used, compact = np.unique(triangles, return_inverse=True)
        return Mesh(self.mesh.vertices[used], compact.reshape(-1, 3))


# Loading ---------------------------------------------------------------------------------------
def load_real_scan(
    folder: str | os.PathLike[str], *, shapenet: str | os.PathLike[str] | None = None
) -> RealScan:
    """A ScanNet or Scan2CAD scene folder as a `RealScan` (see the module docstring)."""
    path = Path(folder)
    if not path.is_dir():
        raise MapError(f"{path}: no such scene folder")
    if (path / "scan2cad_annotation.json").exists():
        return _scan2cad(path, shapenet)
    if any(path.glob("*.aggregation.json")):
        return _scannet(path)
    raise MapError(
        f"{path}: neither a ScanNet scene (*.aggregation.json) nor a Scan2CAD scene "
        "(scan2cad_annotation.json)"
    )


def _scannet(path: Path) -> RealScan:
    files = scene_files(path)
    full = load_scannet(path, voxel=0)
    maps = {"reconstruction": load_scannet(path)}
    return _labelled(files["name"], "scannet", files["mesh"], full, maps)


def _scan2cad(path: Path, shapenet: str | os.PathLike[str] | None) -> RealScan:
    full = load_scan2cad(path, shapenet=shapenet, voxel=0)
    if full.scan is None:
        raise MapError(f"{path}: the scan's *_vh_clean_2.labels.ply is missing")
    name = full.scan.name.removesuffix("_scan")
    maps = load_scan2cad(path, shapenet=shapenet)
    mesh = path / f"{name}_vh_clean_2.ply"
    if not mesh.exists():
        mesh = path / f"{name}_vh_clean_2.labels.ply"
    return _labelled(
        name, "scan2cad", mesh, full.scan, {"reconstruction": maps.scan, "cad": maps.cad}
    )


def _labelled(
    name: str, source: str, mesh_path: Path, full: ObjectMap, maps: dict[str, ObjectMap]
) -> RealScan:
    """Per-face instances from a map whose object points are the mesh's own vertices."""
    ply = read_ply(mesh_path)
    vertices = np.column_stack([ply.vertices[c] for c in "xyz"]).astype(float)
    if len(ply.faces) == 0:
        raise MapError(f"{mesh_path}: the mesh has no faces")
    owner = np.full(len(vertices), -1)
    tree = cKDTree(vertices)
    for index, obj in enumerate(full):
        distance, nearest = tree.query(obj.points)
        owner[nearest[distance < 1e-6]] = index
    a, b, c = (owner[ply.faces[:, i]] for i in range(3))
    faces = np.where((a == b) | (a == c), a, np.where(b == c, b, -1))
    objects = tuple(ScanInstance(o.id, o.label) for o in full)
    colours = None
    names = ply.vertices.dtype.names or ()
    if not mesh_path.name.endswith(".labels.ply") and {"red", "green", "blue"} <= set(names):
        colours = np.column_stack([ply.vertices[c] for c in ("red", "green", "blue")]) / 255.0
    return RealScan(name, source, Mesh(vertices, ply.faces), faces, objects, maps, colours)


# Camera paths ----------------------------------------------------------------------------------
def free_space(scan: RealScan, clearance: float = 0.3) -> tuple[np.ndarray, np.ndarray]:
    """Boolean grid of free floor cells (largest connected region) and the grid's (x, y) origin.

    A cell is free floor when it lies inside the scan's footprint (holes of unscanned floor
    filled) and no geometry (3 vertices or more in a cell) between 0.2 m and 1.9 m above the
    floor is within `clearance`."""
    area = float(scan.mesh.areas().sum())
    samples = scan.mesh.sample_surface(int(area / 0.04**2), np.random.default_rng(0))
    v = np.concatenate([scan.mesh.vertices, samples])  # dense even where triangles are large
    lo = v[:, :2].min(axis=0)
    shape = tuple(np.ceil((v[:, :2].max(axis=0) - lo) / CELL).astype(int) + 1)
    cells = np.floor((v[:, :2] - lo) / CELL).astype(int)
    height = v[:, 2] - scan.floor_height
    inside = np.zeros(shape, bool)
    inside[tuple(cells.T)] = True
    inside = ndimage.binary_fill_holes(ndimage.binary_closing(inside, iterations=2))
    obstacle = cells[(height > 0.2) & (height < 1.9)]
    counts = np.zeros(shape, int)
    np.add.at(counts, tuple(obstacle.T), 1)
    blocked = counts >= 3  # a few stray samples (scanning noise) block nothing
    reach = int(math.ceil(clearance / CELL))
    disk = np.hypot(*np.mgrid[-reach : reach + 1, -reach : reach + 1]) <= reach
    free = ndimage.binary_erosion(inside, iterations=2) & ~ndimage.binary_dilation(blocked, disk)
    regions, count = ndimage.label(free)
    if count == 0:
        raise MapError(f"{scan.name}: no free floor to walk on")
    largest = 1 + int(np.argmax(np.bincount(regions.ravel())[1:]))
    return regions == largest, lo


def walk_path(
    scan: RealScan, n_keyframes: int = 60, seed: int = 0, waypoints: int = 6
) -> np.ndarray:
    """Keyframe poses T_world_camera (n, 4, 4) of a walk through the scan's free space."""
    free, origin = free_space(scan)
    cells = np.argwhere(free)
    rng = np.random.default_rng([seed, 5])
    stops = _spread(cells, waypoints, rng)
    route = _route(free, cells, stops)
    xy = origin + (cells[route] + 0.5) * CELL
    xy = _densify(_smooth(xy), 0.05)
    samples = np.column_stack([xy, _headings(xy, _room_centre(scan, free, origin))])
    poses = keyframes_from_samples(samples, n_keyframes, np.random.default_rng([seed, 3]))
    poses[:, 2, 3] += scan.floor_height
    return poses


def _spread(cells: np.ndarray, count: int, rng: np.random.Generator) -> list[int]:
    """Farthest-point sampling of `count` cells from a random one, visited nearest first."""
    chosen = [int(rng.integers(len(cells)))]
    distance = np.linalg.norm(cells - cells[chosen[0]], axis=1)
    for _ in range(min(count, len(cells)) - 1):
        chosen.append(int(np.argmax(distance)))
        distance = np.minimum(distance, np.linalg.norm(cells - cells[chosen[-1]], axis=1))
    order, rest = [chosen[0]], chosen[1:]
    while rest:
        here = cells[order[-1]]
        nearest = min(rest, key=lambda c: float(np.linalg.norm(cells[c] - here)))
        order.append(nearest)
        rest.remove(nearest)
    return order


def _route(free: np.ndarray, cells: np.ndarray, stops: list[int]) -> np.ndarray:
    """Cell indices of the shortest 8-connected grid paths joining the stops in turn."""
    index = -np.ones(free.shape, int)
    index[tuple(cells.T)] = np.arange(len(cells))
    rows, cols, weights = [], [], []
    for dx, dy in ((1, 0), (0, 1), (1, 1), (1, -1)):
        shifted = cells + (dx, dy)
        inside = np.all((shifted >= 0) & (shifted < free.shape), axis=1)
        target = np.full(len(cells), -1)
        target[inside] = index[tuple(shifted[inside].T)]
        ok = target >= 0
        rows.append(np.flatnonzero(ok))
        cols.append(target[ok])
        weights.append(np.full(ok.sum(), math.hypot(dx, dy)))
    graph = coo_matrix(
        (np.concatenate(weights), (np.concatenate(rows), np.concatenate(cols))),
        shape=(len(cells), len(cells)),
    ).tocsr()
    _, previous = shortest_path(graph, directed=False, indices=stops[:-1], return_predecessors=True)
    route = [stops[0]]
    for k, target in enumerate(stops[1:]):
        leg = [target]
        while leg[-1] != stops[k] and previous[k, leg[-1]] >= 0:
            leg.append(int(previous[k, leg[-1]]))
        route += leg[::-1][1:]
    return np.array(route)


def _smooth(xy: np.ndarray, window: int = 7) -> np.ndarray:
    if len(xy) < window:
        return xy
    kernel = np.ones(window) / window
    padded = np.pad(xy, ((window // 2, window // 2), (0, 0)), mode="edge")
    return np.column_stack([np.convolve(padded[:, i], kernel, mode="valid") for i in (0, 1)])


def _densify(xy: np.ndarray, step: float) -> np.ndarray:
    length = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))])
    s = np.linspace(0.0, length[-1], max(2, int(length[-1] / step)))
    return np.column_stack([np.interp(s, length, xy[:, i]) for i in (0, 1)])


def _room_centre(scan: RealScan, free: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """Where a person looks when looking "into the room": the middle of the objects."""
    positions = scan.global_maps["reconstruction"].positions[:, :2]
    if len(positions):
        return np.median(positions, axis=0)
    return origin + (np.argwhere(free).mean(axis=0) + 0.5) * CELL


def _headings(xy: np.ndarray, centre: np.ndarray, sway: float = 0.6) -> np.ndarray:
    """Half way between the way ahead and the room centre, swaying left and right every 3 m."""
    ahead = np.gradient(xy, axis=0)
    ahead /= np.linalg.norm(ahead, axis=1, keepdims=True) + 1e-9
    inward = centre - xy
    inward /= np.linalg.norm(inward, axis=1, keepdims=True) + 1e-9
    look = ahead + inward
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))])
    return np.arctan2(look[:, 1], look[:, 0]) + sway * np.sin(2 * math.pi * s / 3.0)


# Sequences -------------------------------------------------------------------------------------
def simulate_walk(
    scan: RealScan,
    *,
    n_keyframes: int = 60,
    seed: int = 0,
    resolution: tuple[int, int] = (240, 180),
    noise: DetectionNoise | None = None,
    fusion: FusionConfig | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> SimulatedSequence:
    """Render, detect and fuse a walk through the scan (like `simulate_sequence`; seeded)."""
    noise = noise or DetectionNoise()
    T_world_camera = walk_path(scan, n_keyframes, seed)
    T_odom_true = np.linalg.inv(odometry_origin(T_world_camera[0])) @ T_world_camera
    rng = np.random.default_rng([seed, 23])
    T_odom_est = drift(T_odom_true, noise, rng)
    K = Intrinsics.scannet(*resolution)
    sensor = scan.sensor(K)
    detections = []
    for k, T in enumerate(T_world_camera):
        frame = sensor.render(T, rng if noise.depth_noise else None)
        found = detect(frame, scan, K, noise, rng)  # type: ignore[arg-type]  # objects: id, label
        detections.append([_thinned(d) for d in found])
        if progress is not None:
            progress(k + 1, len(T_world_camera))
    recording = Recording(T_world_camera, T_odom_est, detections, fusion or FusionConfig())
    empty = SimulatedSequence(
        scan, scan.global_maps, [], ObjectMap([]), np.eye(4), {}, None, recording
    )  # type: ignore[arg-type]  # noqa: E501
    return empty.replay(0, name=f"{scan.name}-walk{seed}-local")


def map_keyframes(
    scan: RealScan, n_keyframes: int = 60, resolution: tuple[int, int] = (240, 180)
) -> KeyframeMap:
    """The scan's reconstruction map as day keyframes of a mapping walk (mesh frame)."""
    sensor = scan.colour_sensor(Intrinsics.scannet(*resolution))
    rng = np.random.default_rng([MAP_WALK_SEED, 37])
    poses = walk_path(scan, n_keyframes, MAP_WALK_SEED)
    frames = [sensor.render(T, i, rng) for i, T in enumerate(poses)]
    return KeyframeMap.of(frames, up=(0, 0, 1), name=f"{scan.name}-keyframes")


def _thinned(det: Detection) -> Detection:
    """A detection with its points thinned to 2 cm (keeps recordings small)."""
    points = voxel_downsample(det.points, 0.02).astype(np.float32)
    return Detection(det.label, points, det.score, det.instance)
