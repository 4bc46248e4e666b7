"""What the sensor covered at an update, and the evidence of what it did not see there.

A detection says an object is there; a look that shows nothing where a place predicts an
object says the place may be wrong.  `Coverage(pose=T_odom_sensor, range_m, fov_deg)` is one
such look: the sensor's pose in the odometry (local) frame, looking along its +z axis as a
camera does, how far it sees and its horizontal / vertical field of view (None: all around
within the range).  The update that carries a look holds every detection of that look,
re-detections of known objects included: an object in view that is not sent reads as not
seen.  It is optional everywhere; without it semloc uses no negative evidence.

`expected_unseen(...)` is the negative evidence of one hypothesis: the map objects that its
pose puts well inside a recent look (`margin_deg` from the look's edges, closer than
`range_share` of its range, where a detector sees an object reliably) and that no local
object detected since that look accounts for.  A local object accounts for a map object when it is among
its candidates and lands within the tracking allowance of it, or within a plausible move of it
(`move_m`: an old map's moved objects are changes, not absences).

Choices where the method is silent (a robot's working day in a real building):
* Occlusion is not modelled from geometry (objects have no full shape): a look only counts up to
  `range_share` of its range, and a map object is expected only when it lies in front of no
  more than `max_in_front` other map objects along the sensor's ray (closer, within its
  object's half-diagonal of the ray), so furniture behind furniture is not demanded.
* An old map loses objects: `GONE_SHARE` of the expected objects may be absent without
  counting against a place (see `semloc.tracking`, which decides on the count).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

GONE_SHARE = 0.25
"""The share of the map objects a look should show that may be absent from a right place: an
old map's gone and moved objects (10-20 % in a day-old to weeks-old map) and a detector's
misses and mislabels."""


@dataclass(frozen=True)
class Coverage:
    """One look of the sensor: `pose` T_odom_sensor (4 x 4, +z is the viewing axis), `range_m`
    metres, `fov_deg` (horizontal, vertical) degrees or None for all around."""

    pose: np.ndarray
    range_m: float
    fov_deg: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        pose = np.asarray(self.pose, dtype=float)
        if pose.shape != (4, 4) or not np.all(np.isfinite(pose)):
            raise ValueError(f"coverage pose must be a finite 4x4 matrix, got shape {pose.shape}")
        rotation = pose[:3, :3]
        if not np.allclose(rotation @ rotation.T, np.eye(3), atol=1e-4) or not np.allclose(
            pose[3], [0, 0, 0, 1]
        ):
            raise ValueError("coverage pose must be a rigid transform (rotation and translation)")
        if not (isinstance(self.range_m, (int, float)) and math.isfinite(self.range_m)):
            raise ValueError(f"coverage range_m must be a finite number, got {self.range_m!r}")
        if self.range_m <= 0:
            raise ValueError(f"coverage range_m must be positive, got {self.range_m}")
        fov = self.fov_deg
        if fov is not None:
            fov = tuple(float(a) for a in fov)
            if len(fov) != 2 or not all(math.isfinite(a) and 0 < a <= 360 for a in fov):
                raise ValueError(f"coverage fov_deg must be (horizontal, vertical) in (0, 360], got {self.fov_deg!r}")  # fmt: skip
        object.__setattr__(self, "pose", pose)
        object.__setattr__(self, "range_m", float(self.range_m))
        object.__setattr__(self, "fov_deg", fov)

    def covers(self, points: np.ndarray, range_share: float = 1.0, margin_deg: float = 0.0):
        """Which of `points` (N, 3, odometry frame) the look shows: within `range_share` of the
        range and `margin_deg` inside the field of view's edges."""
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        inverse = np.linalg.inv(self.pose)
        in_sensor = points @ inverse[:3, :3].T + inverse[:3, 3]
        distance = np.linalg.norm(in_sensor, axis=1)
        inside = distance <= self.range_m * range_share
        if self.fov_deg is None:
            return inside
        x, y, z = in_sensor.T
        horizontal = np.degrees(np.abs(np.arctan2(x, z)))
        vertical = np.degrees(np.abs(np.arctan2(y, np.hypot(x, z))))
        half_h, half_v = self.fov_deg[0] / 2 - margin_deg, self.fov_deg[1] / 2 - margin_deg
        return inside & (horizontal <= half_h) & (vertical <= half_v)

    @property
    def origin(self) -> np.ndarray:
        return self.pose[:3, 3]

    def to_dict(self) -> dict[str, Any]:
        fov = None if self.fov_deg is None else list(self.fov_deg)
        return {"pose": self.pose.tolist(), "range_m": self.range_m, "fov_deg": fov}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Coverage:
        """A Coverage from `to_dict()`'s shape (the service's session body); ValueError when
        it does not fit."""
        if not isinstance(data, Mapping):
            raise ValueError(f"coverage must be an object, got {type(data).__name__}")
        unknown = set(data) - {"pose", "range_m", "fov_deg"}
        if unknown:
            raise ValueError(f"coverage has unknown fields: {sorted(unknown)}")
        try:
            return cls(np.asarray(data["pose"], dtype=float), data["range_m"], data.get("fov_deg"))
        except KeyError as exc:
            raise ValueError(f"coverage needs {exc.args[0]!r}") from None
        except TypeError as exc:
            raise ValueError(f"coverage is malformed ({exc})") from None


def checked_coverage(coverage: Any) -> Coverage | None:
    """`coverage` as a Coverage (a dict in `to_dict()`'s shape is read), or None."""
    if coverage is None or isinstance(coverage, Coverage):
        return coverage
    if isinstance(coverage, Mapping):
        return Coverage.from_dict(coverage)
    raise TypeError(f"coverage must be a semloc.Coverage, got {type(coverage).__name__}")


@dataclass(frozen=True)
class Looks:
    """The negative-evidence settings (`semloc.tracking.TrackingConfig` holds them)."""

    range_share: float = 0.8
    margin_deg: float = 5.0
    max_in_front: int = 1
    move_m: float = 3.0


def expected_unseen(
    pose: np.ndarray,
    looks: Sequence[Coverage],
    global_positions: np.ndarray,
    diagonals: np.ndarray,
    local: Iterable[tuple[np.ndarray, np.ndarray]],
    allowance: np.ndarray,
    settings: Looks = Looks(),
    near: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The map objects (indices) that `pose` (T_global_local) puts well inside one of `looks`
    and in nobody's shadow, and which of them no local object accounts for.

    `local`: (position in the local frame, candidate map indices) of each window object;
    `near`: the map indices worth testing (default: all)."""
    expected = expected_objects(pose, looks, global_positions, diagonals, settings, near)
    if not len(expected):
        return expected, expected
    accounting = Accounting(pose, global_positions, allowance, settings.move_m)
    accounted = accounting.accounted(list(enumerate(local)))
    return expected, expected[~accounted[expected]]


def expected_objects(
    pose: np.ndarray,
    looks: Sequence[Coverage],
    global_positions: np.ndarray,
    diagonals: np.ndarray,
    settings: Looks = Looks(),
    near: np.ndarray | None = None,
) -> np.ndarray:
    """The map objects (indices) that `pose` puts well inside one of `looks` and in nobody's
    shadow (`expected_unseen`'s first half)."""
    if not looks:
        return np.zeros(0, dtype=int)
    indices = np.arange(len(global_positions)) if near is None else np.asarray(near, dtype=int)
    inverse = np.linalg.inv(pose)
    in_local = global_positions[indices] @ inverse[:3, :3].T + inverse[:3, 3]
    covered = np.zeros(len(indices), dtype=bool)
    for look in looks:
        seen = look.covers(in_local, settings.range_share, settings.margin_deg)
        seen[seen] = _unshadowed(in_local[seen], look.origin, in_local, diagonals[indices],
                                 settings.max_in_front)  # fmt: skip
        covered |= seen
    return indices[covered]


class Accounting:
    """Which map objects local objects account for under one pose, one each: the nearest
    candidate within its allowance; failing that, the nearest one within `move_m` not yet
    accounted for.  Each local object's distances to its candidates are measured once (by
    its key), however many looks ask about it."""

    def __init__(
        self, pose: np.ndarray, global_positions: np.ndarray, allowance: np.ndarray,
        move_m: float,
    ) -> None:  # fmt: skip
        self._R, self._t = pose[:3, :3], pose[:3, 3]
        self._positions, self._allowance, self._move_m = global_positions, allowance, move_m
        self._measured: dict[Any, tuple[np.ndarray, np.ndarray, int] | None] = {}

    def accounted(self, local: Sequence[tuple[Any, tuple[np.ndarray, np.ndarray]]]) -> np.ndarray:
        """Per map object, whether one of `local` ((key, (position in the local frame,
        candidate map indices)), in their order) accounts for it."""
        accounted = np.zeros(len(self._positions), dtype=bool)
        farther: list[tuple[np.ndarray, np.ndarray]] = []
        for key, (position, candidates) in local:
            measured = self._measure(key, position, candidates)
            if measured is None:
                continue
            gaps, order, nearest = measured
            if gaps[nearest] <= self._allowance[candidates[nearest]]:
                accounted[candidates[nearest]] = True
            else:
                farther.append((gaps[order], candidates[order]))
        for gaps, candidates in farther:  # ascending by gap
            free = np.flatnonzero((gaps <= self._move_m) & ~accounted[candidates])
            if len(free):
                accounted[candidates[free[0]]] = True
        return accounted

    def _measure(self, key: Any, position: np.ndarray, candidates: np.ndarray):
        """(gaps to the candidates, their ascending order, the nearest); None: no candidates."""
        if key not in self._measured:
            measured = None
            if len(candidates):
                gaps = np.linalg.norm(self._positions[candidates] - (self._R @ position + self._t),
                                      axis=1)  # fmt: skip
                measured = (gaps, np.argsort(gaps), int(np.argmin(gaps)))
            self._measured[key] = measured
        return self._measured[key]


def _unshadowed(
    targets: np.ndarray, origin: np.ndarray, blockers: np.ndarray, sizes: np.ndarray, most: int
) -> np.ndarray:
    """Which `targets` have at most `most` of `blockers` in front of them: closer to `origin`
    and within half their diagonal of the ray from `origin` to the target."""
    if not len(targets):
        return np.zeros(0, dtype=bool)
    rays = targets - origin
    lengths = np.linalg.norm(rays, axis=1)
    directions = rays / np.maximum(lengths, 1e-9)[:, None]
    offsets = blockers - origin  # (M, 3)
    along = directions @ offsets.T  # (N, M)
    across = np.linalg.norm(offsets[None] - along[..., None] * directions[:, None], axis=2)
    radius = 0.5 * np.nan_to_num(sizes, nan=0.5)
    in_front = (along > 0.3) & (along < lengths[:, None] - 0.3) & (across < radius[None])
    return in_front.sum(axis=1) <= most
