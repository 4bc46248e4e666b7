"""A robot's long walk through an object map: drifting odometry, partial views, a kidnap.

For the long-run benchmark and tests (object level, no rendering).  The robot walks at
`step` metres per keyframe towards random map objects in turn.  At each keyframe it sees the
objects within `view_range` and the field of view ahead (at most `max_visible`, nearest
first) and sends those it has not sent yet (a new local id; also for an object not seen for
`forget_after` keyframes, as a detector's tracker would) plus up to `redetections` of the
visible ones it has sent (same id, measured again).  A measured object carries the points of
its map object on the side facing the robot, with noise; its centre is their mean (partial
views bias it towards the robot).

Odometry integrates the true motion with noise: per keyframe a translation error of
`drift.translation` times the step (a random walk: 1 % per metre), a yaw error of
`drift.yaw_walk` degrees per √m, and a steady yaw bias of `drift.yaw_bias` degrees per metre.
Objects are sent in the odometry frame, so the true `T_global_local` of keyframe k is the true
robot pose times the inverse of the odometry pose, and changes slowly as drift accumulates.
A kidnap at keyframe `kidnap_at` carries the robot at least `kidnap_distance` away; odometry
does not notice (the true `T_global_local` jumps).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np

from semloc.maps import ObjectMap, SemanticObject


@dataclass(frozen=True)
class Drift:
    """Odometry error: translation random walk (fraction of the step), yaw random walk
    (degrees per √m) and yaw bias (degrees per m)."""

    translation: float = 0.01
    yaw_walk: float = 0.2
    yaw_bias: float = 0.05


@dataclass(frozen=True)
class WalkConfig:
    keyframes: int = 1000
    step: float = 0.5
    view_range: float = 4.0
    field_of_view: float = 120.0  # degrees
    max_visible: int = 10
    redetections: int = 2
    forget_after: int = 40
    points_per_object: int = 120  # 0: centres only
    point_noise: float = 0.01
    wrong_label_rate: float = 0.02
    drift: Drift = field(default_factory=Drift)
    kidnap_at: int | None = None
    kidnap_distance: float = 12.0


@dataclass(frozen=True)
class WalkKeyframe:
    """One keyframe: the objects sent (odometry frame), the robot's odometry pose, its true
    position in the map and the true T_global_local."""

    index: int
    objects: list[SemanticObject]
    T_odom_robot: np.ndarray
    robot_global: np.ndarray
    T_global_local: np.ndarray
    kidnapped: bool = False


def _pose2d(x: float, y: float, yaw: float, z: float = 0.0) -> np.ndarray:
    T = np.eye(4)
    c, s = np.cos(yaw), np.sin(yaw)
    T[:3, :3] = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    T[:3, 3] = [x, y, z]
    return T


class LongWalk:
    """The walk of `WalkConfig` through `global_map` (z up), seeded (see the module docstring)."""

    def __init__(self, global_map: ObjectMap, config: WalkConfig | None = None, seed: int = 0):
        self.map = global_map
        self.config = config or WalkConfig()
        self.rng = np.random.default_rng(seed)
        self._points = [self._object_points(o) for o in global_map]

    def _object_points(self, obj: SemanticObject) -> np.ndarray:
        if obj.points is not None and len(obj.points):
            return obj.points
        size = np.array(obj.size if obj.size is not None else (0.5, 0.5, 0.5))
        rotation = obj.rotation if obj.rotation is not None else np.eye(3)
        u = self.rng.uniform(-0.5, 0.5, (max(self.config.points_per_object, 60), 3))
        face = self.rng.integers(0, 3, len(u))
        u[np.arange(len(u)), face] = np.sign(u[np.arange(len(u)), face]) * 0.5
        return (u * size) @ rotation.T + obj.position

    def __iter__(self) -> Iterator[WalkKeyframe]:
        cfg, rng = self.config, self.rng
        xy = self.map.positions[:, :2]
        robot = xy[rng.integers(len(xy))] + rng.normal(0, 0.5, 2)
        yaw = float(rng.uniform(-np.pi, np.pi))
        odom = np.array([0.0, 0.0, 0.0])  # x, y, yaw of the odometry estimate
        target = robot
        sent: dict[int, tuple[str, int]] = {}  # global index -> (local id, last keyframe)
        next_id = 0
        for k in range(cfg.keyframes):
            kidnapped = cfg.kidnap_at is not None and k == cfg.kidnap_at
            if k > 0:
                while np.linalg.norm(target - robot) < cfg.step:
                    target = xy[rng.integers(len(xy))]
                heading = np.arctan2(*(target - robot)[::-1])
                turn = (heading - yaw + np.pi) % (2 * np.pi) - np.pi
                move = cfg.step
                yaw += turn
                robot = robot + move * np.array([np.cos(yaw), np.sin(yaw)])
                odom = self._odometry(odom, turn, move)
                if kidnapped:
                    robot, yaw = self._elsewhere(robot), float(rng.uniform(-np.pi, np.pi))
                    target = robot
            T_world_robot = _pose2d(*robot, yaw, z=1.2)
            T_odom_robot = _pose2d(*odom[:2], odom[2], z=1.2)
            T_true = T_world_robot @ np.linalg.inv(T_odom_robot)
            visible = self._visible(robot, yaw)
            objects, fresh = [], []
            for g in visible:
                known = sent.get(g)
                if known is None or k - known[1] > cfg.forget_after:
                    fresh.append((g, f"o{next_id}"))
                    next_id += 1
            again = [g for g in visible if g in sent and k - sent[g][1] <= cfg.forget_after]
            again = [again[i] for i in rng.permutation(len(again))[: cfg.redetections]]
            T_local_world = np.linalg.inv(T_true)
            for g, local_id in [*fresh, *((g, sent[g][0]) for g in again)]:
                objects.append(self._measure(g, local_id, robot, T_local_world, k))
                sent[g] = (local_id, k)
            yield WalkKeyframe(k, objects, T_odom_robot, T_world_robot[:3, 3], T_true, kidnapped)

    def _odometry(self, odom: np.ndarray, turn: float, move: float) -> np.ndarray:
        d, rng = self.config.drift, self.rng
        yaw = (
            odom[2]
            + turn
            + np.radians(rng.normal(0, d.yaw_walk * np.sqrt(move)) + d.yaw_bias * move)
        )
        step = move * np.array([np.cos(yaw), np.sin(yaw)]) + rng.normal(0, d.translation * move, 2)
        return np.array([odom[0] + step[0], odom[1] + step[1], yaw])

    def _elsewhere(self, robot: np.ndarray) -> np.ndarray:
        xy = self.map.positions[:, :2]
        far = np.flatnonzero(np.linalg.norm(xy - robot, axis=1) >= self.config.kidnap_distance)
        pick = far if len(far) else np.arange(len(xy))
        return xy[self.rng.choice(pick)] + self.rng.normal(0, 0.5, 2)

    def _visible(self, robot: np.ndarray, yaw: float) -> list[int]:
        cfg = self.config
        offsets = self.map.positions[:, :2] - robot
        distance = np.linalg.norm(offsets, axis=1)
        bearing = np.arctan2(offsets[:, 1], offsets[:, 0]) - yaw
        bearing = (bearing + np.pi) % (2 * np.pi) - np.pi
        inside = (distance <= cfg.view_range) & (
            np.abs(np.degrees(bearing)) <= cfg.field_of_view / 2
        )
        order = np.flatnonzero(inside)[np.argsort(distance[inside], kind="stable")]
        return order[: cfg.max_visible].tolist()

    def _measure(
        self, g: int, local_id: str, robot: np.ndarray, T_local_world: np.ndarray, k: int
    ) -> SemanticObject:
        cfg, rng, obj = self.config, self.rng, self.map[g]
        points = self._points[g]
        towards = np.append(robot, 1.2) - obj.position
        towards[2] = 0.0
        facing = (points - obj.position) @ towards >= 0
        seen = points[facing] if facing.sum() >= 3 else points
        take = rng.permutation(len(seen))[: max(cfg.points_per_object, 60)]
        seen = seen[take] + rng.normal(0, cfg.point_noise, (len(take), 3))
        local = seen @ T_local_world[:3, :3].T + T_local_world[:3, 3]
        label = obj.label
        if rng.random() < cfg.wrong_label_rate:
            label = str(rng.choice(sorted(set(self.map.labels.tolist()) - {label}) or [label]))
        points = local if cfg.points_per_object else None
        return SemanticObject(local_id, label, local.mean(axis=0), points=points, seen=k)


def tiled(
    room: ObjectMap, columns: int, rows: int, gap: float = 1.0, keep: float = 0.7, seed: int = 0
) -> ObjectMap:
    """A building of `columns` x `rows` copies of `room` side by side (z up), each keeping a
    random `keep` share of its objects (copies of a layout are alike, not identical)."""
    rng = np.random.default_rng(seed)
    low, high = room.positions.min(axis=0), room.positions.max(axis=0)
    pitch = (high - low)[:2] + gap
    objects = []
    for c in range(columns):
        for r in range(rows):
            T = np.eye(4)
            T[:3, 3] = [c * pitch[0], r * pitch[1], 0.0]
            kept = rng.random(len(room)) < keep
            for obj, use in zip(room, kept):
                if use:
                    moved = obj.transformed(T)
                    objects.append(moved.replace(id=f"{c}.{r}/{obj.id}"))
    return ObjectMap(objects, up=room.up, name=f"{room.name}-tiled-{columns}x{rows}")
