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
A kidnap at keyframe `kidnap_at` (and at each of `more_kidnaps`) carries the robot at least
`kidnap_distance` away; odometry does not notice (the true `T_global_local` jumps).  A kidnap
at `lookalike_at` (and at each of `more_lookalikes`) carries it into the look-alike of where it stands: the same spot, facing the
same way, beside the map object of the nearest object's label whose surroundings repeat the
most labels (another copy of the room in a building of alike rooms).

An old map and a detector that errs (`World`): today's world differs from the map (a share of
the objects stand 1-3 m from where the map has them, a share are gone), a share of detections
carry another label of the map's vocabulary, objects the map does not hold appear (phantoms:
a bag on the floor), and the detector splits one object into two or merges two near ones of a
label into one.  Each keyframe also says what the sensor covered (`WalkKeyframe.coverage`: its
pose in the odometry frame, the view's range up to the farthest object it could see, and its
field of view), for negative evidence.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np

from semloc.coverage import Coverage
from semloc.maps import ObjectMap, SemanticObject

CAMERA_IN_ROBOT = np.array([[0.0, 0, 1, 0], [-1, 0, 0, 0], [0, -1, 0, 0], [0, 0, 0, 1]])
"""The sensor looks ahead along the robot's x axis (z forward, x right, y down, as a camera)."""


@dataclass(frozen=True)
class Drift:
    """Odometry error: translation random walk (fraction of the step), yaw random walk
    (degrees per √m) and yaw bias (degrees per m)."""

    translation: float = 0.01
    yaw_walk: float = 0.2
    yaw_bias: float = 0.05


@dataclass(frozen=True)
class World:
    """How today's world and the detector differ from the map (all off by default)."""

    moved: float = 0.0  # share of map objects standing elsewhere today
    move_m: tuple[float, float] = (1.0, 3.0)
    gone: float = 0.0  # share of map objects gone today
    phantoms: float = 0.0  # chance per keyframe of a detection the map does not hold
    split: float = 0.0  # chance a detection is split in two
    merged: float = 0.0  # chance two near detections of a label are merged in one


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
    more_kidnaps: tuple[int, ...] = ()
    lookalike_at: int | None = None
    more_lookalikes: tuple[int, ...] = ()
    world: World = field(default_factory=World)


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
    coverage: Coverage | None = None
    truth: dict[str, int | None] = field(default_factory=dict)
    """The map object (index) each sent local object is, None for a phantom."""


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
        self.offsets, self.present = self._today()
        self.labels = sorted(set(global_map.labels.tolist()))

    def _today(self) -> tuple[np.ndarray, np.ndarray]:
        """Where each map object stands today relative to the map, and which are still there."""
        world, n = self.config.world, len(self.map)
        offsets = np.zeros((n, 3))
        if world.moved == 0 and world.gone == 0:  # (a clean walk draws nothing here)
            return offsets, np.ones(n, dtype=bool)
        moved = self.rng.random(n) < world.moved
        angle = self.rng.uniform(-np.pi, np.pi, n)
        reach = self.rng.uniform(*world.move_m, n)
        offsets[moved, 0] = (reach * np.cos(angle))[moved]
        offsets[moved, 1] = (reach * np.sin(angle))[moved]
        present = self.rng.random(n) >= world.gone
        return offsets, present

    @property
    def today(self) -> np.ndarray:
        """Where the map objects stand today (N, 3)."""
        return self.map.positions + self.offsets

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
        counter = iter(range(10**9))
        kidnaps = {*cfg.more_kidnaps, *((cfg.kidnap_at,) if cfg.kidnap_at is not None else ())}
        lookalikes = {*cfg.more_lookalikes}
        if cfg.lookalike_at is not None:
            lookalikes.add(cfg.lookalike_at)
        for k in range(cfg.keyframes):
            kidnapped = k in kidnaps or k in lookalikes
            if k > 0:
                while np.linalg.norm(target - robot) < cfg.step:
                    target = xy[rng.integers(len(xy))]
                heading = np.arctan2(*(target - robot)[::-1])
                turn = (heading - yaw + np.pi) % (2 * np.pi) - np.pi
                move = cfg.step
                yaw += turn
                robot = robot + move * np.array([np.cos(yaw), np.sin(yaw)])
                odom = self._odometry(odom, turn, move)
                if k in lookalikes:
                    robot = self._lookalike(robot)
                    target = robot
                elif kidnapped:
                    robot, yaw = self._elsewhere(robot), float(rng.uniform(-np.pi, np.pi))
                    target = robot
            T_world_robot = _pose2d(*robot, yaw, z=1.2)
            T_odom_robot = _pose2d(*odom[:2], odom[2], z=1.2)
            T_true = T_world_robot @ np.linalg.inv(T_odom_robot)
            visible, reach = self._visible(robot, yaw)
            fresh = [g for g in visible if g not in sent or k - sent[g][1] > cfg.forget_after]
            for g in fresh:
                sent[g] = (f"o{next(counter)}", k)
            again = [g for g in visible if g not in fresh and k - sent[g][1] <= cfg.forget_after]
            again = [again[i] for i in rng.permutation(len(again))[: cfg.redetections]]
            T_local_world = np.linalg.inv(T_true)
            measured = [(g, sent[g][0], self._measure(g, sent[g][0], robot, T_local_world, k))
                        for g in [*fresh, *again]]  # fmt: skip
            for g in again:
                sent[g] = (sent[g][0], k)
            objects, truth = self._detector(measured, robot, yaw, T_local_world, k, counter)
            coverage = Coverage(T_odom_robot @ CAMERA_IN_ROBOT, reach, (cfg.field_of_view, 150.0))
            yield WalkKeyframe(k, objects, T_odom_robot, T_world_robot[:3, 3], T_true, kidnapped,
                               coverage, truth)  # fmt: skip

    def _detector(self, measured, robot, yaw, T_local_world, k, counter):
        """The detector's errors over the measured objects: splits, merges, phantoms."""
        world, rng = self.config.world, self.rng
        objects: list[SemanticObject] = []
        truth: dict[str, int | None] = {}
        merged_away: set[str] = set()
        for i, (g, local_id, obj) in enumerate(measured):
            if local_id in merged_away:
                continue
            partner = next((m for m in measured[i + 1 :] if m[2].label == obj.label
                            and np.linalg.norm(m[2].position - obj.position) < 1.5), None)  # fmt: skip
            if partner is not None and world.merged and rng.random() < world.merged:
                merged_away.add(partner[1])
                obj = _merged(obj, partner[2])
            if (
                world.split
                and rng.random() < world.split
                and obj.points is not None
                and len(obj.points) >= 8
            ):
                first, second = _split(obj, f"o{next(counter)}")
                objects += [first, second]
                truth[first.id], truth[second.id] = g, g
                continue
            objects.append(obj)
            truth[obj.id] = g
        if world.phantoms and rng.random() < world.phantoms:
            phantom = self._phantom(robot, yaw, T_local_world, k, f"o{next(counter)}")
            objects.append(phantom)
            truth[phantom.id] = None
        return objects, truth

    def _phantom(self, robot, yaw, T_local_world, k, local_id) -> SemanticObject:
        """An object the map does not hold, in view, with a label of the map's vocabulary."""
        rng = self.rng
        distance = rng.uniform(1.0, self.config.view_range * 0.8)
        bearing = yaw + np.radians(rng.uniform(-0.4, 0.4) * self.config.field_of_view)
        centre = np.array([*(robot + distance * np.array([np.cos(bearing), np.sin(bearing)])), 0.4])
        size = rng.uniform(0.3, 0.8, 3)
        u = rng.uniform(-0.5, 0.5, (max(self.config.points_per_object, 60), 3)) * size
        points = u + centre
        local = points @ T_local_world[:3, :3].T + T_local_world[:3, 3]
        label = str(rng.choice(self.labels))
        return SemanticObject(local_id, label, local.mean(axis=0), points=local, seen=k)

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

    def _lookalike(self, robot: np.ndarray) -> np.ndarray:
        """The same spot in the look-alike of the robot's surroundings, `kidnap_distance` away
        at least: beside the object of the nearest object's label whose neighbours (4 m)
        repeat the most labels at the same offsets (0.5 m)."""
        positions, labels = self.map.positions, self.map.labels
        xy = positions[:, :2]
        nearest = int(np.argmin(np.linalg.norm(xy - robot, axis=1)))
        around = np.flatnonzero(np.linalg.norm(xy - xy[nearest], axis=1) < 4.0)
        best, best_count = None, -1
        for j in np.flatnonzero(labels == labels[nearest]):
            if np.linalg.norm(xy[j] - xy[nearest]) < self.config.kidnap_distance:
                continue
            shift = xy[j] - xy[nearest]
            count = 0
            for a in around:
                gaps = np.linalg.norm(xy - (xy[a] + shift), axis=1)
                count += bool(np.any((gaps < 0.5) & (labels == labels[a])))
            if count > best_count:
                best, best_count = j, count
        if best is None:
            return self._elsewhere(robot)
        return robot + (xy[best] - xy[nearest])

    def _visible(self, robot: np.ndarray, yaw: float) -> tuple[list[int], float]:
        """The objects in view today (nearest first, at most `max_visible`) and how far the
        view reached: its range, or the farthest object seen when more were in view."""
        cfg = self.config
        offsets = self.today[:, :2] - robot
        distance = np.linalg.norm(offsets, axis=1)
        bearing = np.arctan2(offsets[:, 1], offsets[:, 0]) - yaw
        bearing = (bearing + np.pi) % (2 * np.pi) - np.pi
        inside = (
            (distance <= cfg.view_range)
            & (np.abs(np.degrees(bearing)) <= cfg.field_of_view / 2)
            & self.present
        )
        order = np.flatnonzero(inside)[np.argsort(distance[inside], kind="stable")]
        if len(order) > cfg.max_visible:
            return order[: cfg.max_visible].tolist(), float(distance[order[cfg.max_visible - 1]])
        return order.tolist(), cfg.view_range

    def _measure(
        self, g: int, local_id: str, robot: np.ndarray, T_local_world: np.ndarray, k: int
    ) -> SemanticObject:
        cfg, rng, obj = self.config, self.rng, self.map[g]
        points = self._points[g] + self.offsets[g]
        centre = obj.position + self.offsets[g]
        towards = np.append(robot, 1.2) - centre
        towards[2] = 0.0
        facing = (points - centre) @ towards >= 0
        seen = points[facing] if facing.sum() >= 3 else points
        take = rng.permutation(len(seen))[: max(cfg.points_per_object, 60)]
        seen = seen[take] + rng.normal(0, cfg.point_noise, (len(take), 3))
        local = seen @ T_local_world[:3, :3].T + T_local_world[:3, 3]
        label = obj.label
        if rng.random() < cfg.wrong_label_rate:
            label = str(rng.choice(sorted(set(self.map.labels.tolist()) - {label}) or [label]))
        points = local if cfg.points_per_object else None
        return SemanticObject(local_id, label, local.mean(axis=0), points=points, seen=k)


def _merged(a: SemanticObject, b: SemanticObject) -> SemanticObject:
    """One detection of two objects: their points together."""
    if a.points is None or b.points is None:
        return a.replace(position=(a.position + b.position) / 2)
    points = np.vstack([a.points, b.points])
    return SemanticObject(a.id, a.label, points.mean(axis=0), points=points, seen=a.seen)


def _split(obj: SemanticObject, second_id: str) -> tuple[SemanticObject, SemanticObject]:
    """Two detections of one object: its points cut across their longest horizontal extent."""
    points = obj.points
    assert points is not None
    axis = int(np.argmax(np.ptp(points[:, :2], axis=0)))
    cut = points[:, axis] <= np.median(points[:, axis])
    halves = points[cut], points[~cut]
    if not len(halves[1]):
        halves = points[: len(points) // 2], points[len(points) // 2 :]
    return (
        SemanticObject(obj.id, obj.label, halves[0].mean(axis=0), points=halves[0], seen=obj.seen),
        SemanticObject(second_id, obj.label, halves[1].mean(axis=0), points=halves[1],
                       seen=obj.seen),
    )  # fmt: skip


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
