"""A whole simulated sequence: world, global maps, camera keyframes, fused local map, ground truth.

`simulate_sequence(seed, size, map_kinds, path, ...)` is the one entry point used by
`semloc demo`, `semloc simulate` and the evaluation: it generates the world, builds the
requested global maps (world frame), walks the camera, renders and "detects" every keyframe,
fuses the segments into a local map in the odometry frame (origin = first camera pose made
gravity-aligned, so the true `T_global_local` is not the identity) and records what changed at
each keyframe plus the ground truth (true transform, which global object each local one is).
The detections are recorded, so `seq.replay(start, stop)` fuses the local map again from any
keyframe (new odometry origin, new ground truth): relocalization attempts from random starts.
"""

from __future__ import annotations

from collections import Counter, defaultdict
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from semloc.frontend.fusion import FusionConfig, ObjectFusion, Segment
from semloc.maps import ObjectMap, SemanticObject
from semloc.pointsets import voxel_downsample
from semloc.sim.mapkinds import MAP_KINDS, DynamicChanges, cad_map, dynamic_map, reconstruction_map
from semloc.sim.noise import Detection, DetectionNoise, detect, drift
from semloc.sim.sensor import DepthSensor, Intrinsics
from semloc.sim.trajectory import camera_path, odometry_origin
from semloc.sim.world import World, generate_world


@dataclass(frozen=True)
class Keyframe:
    """One keyframe: true and estimated camera poses, detections, the local objects it changed."""

    index: int
    T_world_camera: np.ndarray
    T_odom_camera: np.ndarray
    n_detections: int
    new: list[str]
    updated: list[str]
    objects: list[SemanticObject] = field(repr=False)

    @property
    def changed(self) -> list[SemanticObject]:
        """New and updated local objects: what to hand to `Localizer.update`."""
        return self.objects


@dataclass(frozen=True)
class Recording:
    """What the camera recorded: true and odometry poses and the detections of every keyframe
    (camera frame), so the local map can be fused again from any start keyframe."""

    T_world_camera: np.ndarray
    T_odom_camera: np.ndarray
    detections: list[list[Detection]] = field(repr=False)
    fusion: FusionConfig = field(default_factory=FusionConfig)


@dataclass
class SimulatedSequence:
    """Everything a simulated run produced; global maps in the world frame, local in odometry."""

    world: World
    global_maps: dict[str, ObjectMap]
    keyframes: list[Keyframe]
    local_map: ObjectMap
    T_global_local: np.ndarray
    local_truth: dict[str, str | None]
    dynamic_changes: DynamicChanges | None = None
    recording: Recording | None = field(default=None, repr=False)

    def replay(self, start: int = 0, stop: int | None = None, name: str = "") -> SimulatedSequence:
        """The same world and maps, with the local map fused from keyframe `start` to `stop`.

        The odometry origin moves to keyframe `start` (gravity-aligned), so `T_global_local`
        changes too: this is how relocalization attempts from random keyframes are made.
        """
        if self.recording is None:
            raise ValueError("this sequence has no recording to replay")
        n = len(self.recording.detections)
        stop = n if stop is None else stop
        if not 0 <= start < stop <= n:
            raise ValueError(f"need 0 <= start < stop <= {n}, got start={start}, stop={stop}")
        name = name or f"{self.local_map.name or 'local'}-from{start}"
        keyframes, local_map, T, truth = fuse_recording(
            self.world, self.recording, start, stop, name
        )
        return replace(
            self, keyframes=keyframes, local_map=local_map, T_global_local=T, local_truth=truth
        )

    def correspondences(self, kind: str) -> list[tuple[str, str]]:
        """True (global_id, local_id) pairs for a map kind (deleted objects have none)."""
        gmap = self.global_maps[kind]
        return [(g, lid) for lid, g in self.local_truth.items() if g is not None and g in gmap]

    def local_map_at(self, k: int) -> ObjectMap:
        """The local map as it was after keyframe `k` (published objects only)."""
        latest: dict[str, SemanticObject] = {}
        for kf in self.keyframes:
            if kf.index <= k:
                latest.update({o.id: o for o in kf.objects})
        return ObjectMap(latest.values(), up=self.local_map.up, name=f"{self.local_map.name}-kf{k}")

    def ground_truth(self) -> dict:
        """JSON-ready ground truth: transform, keyframe poses, correspondences per map kind."""
        out = {
            "T_global_local": _rounded(self.T_global_local),
            "local_to_world_object": self.local_truth,
            "keyframes": [
                {
                    "index": kf.index,
                    "T_world_camera": _rounded(kf.T_world_camera),
                    "T_odom_camera": _rounded(kf.T_odom_camera),
                    "new": kf.new,
                    "updated": kf.updated,
                }
                for kf in self.keyframes
            ],
            "correspondences": {
                kind: [{"global": g, "local": lid} for g, lid in self.correspondences(kind)]
                for kind in self.global_maps
            },
        }
        if self.dynamic_changes is not None:
            out["dynamic"] = {
                "deleted": list(self.dynamic_changes.deleted),
                "moved": list(self.dynamic_changes.moved),
            }
        return out


def _rounded(T: np.ndarray) -> list:
    return np.round(T, 6).tolist()


def simulate_sequence(
    seed: int = 0,
    size: str | int = "small",
    map_kinds: str | Sequence[str] = MAP_KINDS,
    path: str = "walk",
    *,
    n_keyframes: int = 40,
    n_rooms: int = 2,
    resolution: tuple[int, int] = (240, 180),
    noise: DetectionNoise | None = None,
    fusion: FusionConfig | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> SimulatedSequence:
    """Simulate one sequence (see the module docstring); deterministic for given arguments.

    `map_kinds`: "all", one kind, or several of "reconstruction", "cad", "dynamic".
    `progress(done, total)` is called after each rendered keyframe.
    """
    kinds = _kinds(map_kinds)
    noise = noise or DetectionNoise()
    world = generate_world(seed, size)
    global_maps, changes = _global_maps(world, kinds)
    T_world_camera = camera_path(world, path, n_keyframes, n_rooms, seed)
    T_odom_true = np.linalg.inv(odometry_origin(T_world_camera[0])) @ T_world_camera
    rng = np.random.default_rng([seed, 23])
    T_odom_est = drift(T_odom_true, noise, rng)
    K = Intrinsics.scannet(*resolution)
    sensor = DepthSensor(world, K)
    detections = []
    for k, T in enumerate(T_world_camera):
        frame = sensor.render(T, rng if noise.depth_noise else None)
        detections.append([_compact(d) for d in detect(frame, world, K, noise, rng)])
        if progress is not None:
            progress(k + 1, len(T_world_camera))
    recording = Recording(T_world_camera, T_odom_est, detections, fusion or FusionConfig())
    seq = SimulatedSequence(
        world, global_maps, [], ObjectMap([]), np.eye(4), {}, changes, recording
    )
    return seq.replay(0, name=f"{world.size}-{seed}-{path}-local")


def _compact(det: Detection) -> Detection:
    """A detection with its points thinned to 2 cm (keeps long recordings small)."""
    points = voxel_downsample(det.points, 0.02).astype(np.float32)
    return Detection(det.label, points, det.score, det.instance)


def fuse_recording(
    world: World, recording: Recording, start: int, stop: int, name: str
) -> tuple[list[Keyframe], ObjectMap, np.ndarray, dict[str, str | None]]:
    """Fuse keyframes start..stop-1 in an odometry frame whose origin is keyframe `start`.

    Returns the keyframes, the local map, the true T_global_local and local -> world ids.
    """
    T_world_odom = odometry_origin(recording.T_world_camera[start])
    T_est_origin = np.linalg.inv(odometry_origin(recording.T_odom_camera[start]))
    fuser = ObjectFusion(recording.fusion, up=(0, 0, 1), name=name)
    votes: dict[str, Counter] = defaultdict(Counter)
    keyframes = []
    for k in range(start, stop):
        detections = recording.detections[k]
        T_odom_camera = T_est_origin @ recording.T_odom_camera[k]
        segments = [Segment(d.label, d.points, d.score) for d in detections]
        update = fuser.integrate(segments, T_odom_camera, frame="camera", keyframe=k)
        for det, lid in zip(detections, update.assignments, strict=True):
            if lid is not None:
                votes[lid][world.objects[det.instance].id] += len(det.points)
        keyframes.append(
            Keyframe(
                k, recording.T_world_camera[k], T_odom_camera, len(segments), update.new,
                update.updated, fuser.objects(update.changed),
            )
        )  # fmt: skip
    local_map = fuser.local_map()
    truth = {lid: _majority(votes[lid]) for lid in local_map.ids}
    return keyframes, local_map, T_world_odom, truth


def _kinds(map_kinds: str | Sequence[str]) -> list[str]:
    if isinstance(map_kinds, str):
        map_kinds = list(MAP_KINDS) if map_kinds == "all" else [map_kinds]
    for kind in map_kinds:
        if kind not in MAP_KINDS:
            raise ValueError(f"unknown map kind {kind!r}; use one of {list(MAP_KINDS)} or 'all'")
    return list(map_kinds)


def _global_maps(
    world: World, kinds: list[str]
) -> tuple[dict[str, ObjectMap], DynamicChanges | None]:
    maps: dict[str, ObjectMap] = {}
    changes = None
    for kind in kinds:
        if kind == "reconstruction":
            maps[kind] = reconstruction_map(world)
        elif kind == "cad":
            maps[kind] = cad_map(world)
        else:
            maps[kind], changes = dynamic_map(world)
    return maps, changes


def _majority(counter: Counter) -> str | None:
    """The world object that gave most of a local object's points, if it gave at least half."""
    if not counter:
        return None
    world_id, n = counter.most_common(1)[0]
    return world_id if n >= 0.5 * sum(counter.values()) else None
