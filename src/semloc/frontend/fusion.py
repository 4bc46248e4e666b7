"""Object-level fusion: per-frame 3D instance segments -> a local object map with stable ids.

Feed `ObjectFusion.integrate` the segments of one keyframe (label, points, optional score) in
the odometry frame, or in the camera frame together with the frame pose `T_odom_camera`.  Each
segment joins the existing object it overlaps most (share of its points within `match_radius`
of the object's points; a same-label partial view inside the object's box counts too), with a
bonus for agreeing labels, or starts a new object.  Objects keep voxel-downsampled points, a
centre (mean of the fused points), a score-weighted label vote and `seen` (the keyframe of the
first detection).  An object is published once seen `min_observations` times; each call
reports which published objects are new and which changed, which is exactly what
`Localizer.update` wants.  Works the same for simulated and real detections.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np
from pydantic import BaseModel, ConfigDict, Field
from scipy.spatial import cKDTree

from semloc.maps import MapError, ObjectMap, SemanticObject
from semloc.pointsets import voxel_accumulate, voxel_downsample


class FusionConfig(BaseModel):
    """Parameters of the object fusion."""

    model_config = ConfigDict(extra="forbid")

    voxel_size: float = Field(0.05, gt=0, description="Voxel size of the fused object points (m).")
    match_radius: float = Field(
        0.1, gt=0, description="A segment point overlaps an object if this close to it (m)."
    )
    min_overlap: float = Field(
        0.25, ge=0, le=1, description="Share of a segment's points that must overlap an object."
    )
    label_bonus: float = Field(0.15, ge=0, description="Added to the overlap when labels agree.")
    outlier_factor: float = Field(
        2.5,
        ge=0,
        description="Drop points beyond this many median distances from the median (0: off).",
    )
    min_points: int = Field(15, ge=1, description="Segments with fewer points are ignored.")
    min_observations: int = Field(
        2, ge=1, description="Detections needed before an object is published."
    )
    min_shift: float = Field(
        0.02,
        ge=0,
        description="A published object counts as updated when its centre moves more (m).",
    )


@dataclass(frozen=True)
class Segment:
    """One detected instance in one frame: label, points (N, 3), optional detector score."""

    label: str
    points: np.ndarray
    score: float | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.label, str) or not self.label.strip():
            raise MapError(f"segment label must be a non-empty string, got {self.label!r}")
        points = np.asarray(self.points, dtype=float)
        if points.ndim != 2 or points.shape[1] != 3:
            raise MapError(f"segment points must have shape (N, 3), got {points.shape}")
        if not np.all(np.isfinite(points)):
            raise MapError("segment points have non-finite values")
        object.__setattr__(self, "points", points)


@dataclass(frozen=True)
class FusionUpdate:
    """What one `integrate` call changed: published ids that are new or updated, and where each
    input segment went (`assignments[i]` = object id, or None if the segment was ignored)."""

    keyframe: int
    new: list[str]
    updated: list[str]
    assignments: list[str | None]

    @property
    def changed(self) -> list[str]:
        return self.new + self.updated


@dataclass
class _Track:
    id: str
    first_seen: int
    keys: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    sums: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    counts: np.ndarray = field(default_factory=lambda: np.zeros(0))
    tree: cKDTree | None = None
    lo: np.ndarray | None = None
    hi: np.ndarray | None = None
    votes: dict[str, float] = field(default_factory=lambda: defaultdict(float))
    observations: int = 0
    score_sum: float = 0.0
    scored: int = 0
    published_centre: np.ndarray | None = None
    published_label: str | None = None

    @property
    def points(self) -> np.ndarray:
        return self.sums / self.counts[:, None]

    def refresh(self) -> None:
        """Rebuild the search structures after the points changed."""
        points = self.points
        self.tree = cKDTree(points)
        self.lo, self.hi = points.min(axis=0), points.max(axis=0)

    @property
    def centre(self) -> np.ndarray:
        return self.points.mean(axis=0)

    @property
    def label(self) -> str:
        return max(sorted(self.votes), key=lambda k: self.votes[k])


class ObjectFusion:
    """Incremental object map from per-frame segments (see the module docstring)."""

    def __init__(
        self,
        config: FusionConfig | None = None,
        *,
        up: Sequence[float] = (0, 0, 1),
        name: str = "local",
    ):
        self.config = config or FusionConfig()
        self.up = np.asarray(up, float)
        self.name = name
        self._tracks: dict[str, _Track] = {}
        self._next_id = 0
        self._keyframe = -1
        self.poses: list[np.ndarray | None] = []

    @property
    def keyframe(self) -> int:
        """Index of the last integrated keyframe (-1 before the first)."""
        return self._keyframe

    def integrate(
        self,
        segments: Iterable[Segment],
        pose: np.ndarray | None = None,
        *,
        frame: str = "odom",
        keyframe: int | None = None,
    ) -> FusionUpdate:
        """Fuse one keyframe's segments.

        `frame="odom"`: points are already in the odometry frame (`pose` is only recorded);
        `frame="camera"`: points are in the camera frame and `pose` (T_odom_camera) is required.
        """
        if frame not in ("odom", "camera"):
            raise ValueError(f"frame must be 'odom' or 'camera', got {frame!r}")
        T = None if pose is None else np.asarray(pose, dtype=float)
        if T is not None and (T.shape != (4, 4) or not np.all(np.isfinite(T))):
            raise MapError(f"frame pose must be a finite 4 x 4 matrix, got shape {T.shape}")
        if frame == "camera" and T is None:
            raise MapError("segments in the camera frame need the frame pose T_odom_camera")
        self._keyframe = self._keyframe + 1 if keyframe is None else int(keyframe)
        self.poses.append(T)
        touched: dict[str, None] = {}
        assignments: list[str | None] = []
        for seg in segments:
            points = seg.points if frame == "odom" else seg.points @ T[:3, :3].T + T[:3, 3]  # type: ignore[index]
            points = self._drop_outliers(points)
            if len(points) < self.config.min_points:
                assignments.append(None)
                continue
            track = self._associate(points, seg.label)
            self._fuse(track, points, seg)
            touched[track.id] = None
            assignments.append(track.id)
        new, updated = self._publish(touched)
        return FusionUpdate(self._keyframe, new, updated, assignments)

    def _drop_outliers(self, points: np.ndarray) -> np.ndarray:
        """Remove stray points (mask bleeding onto far background) by distance to the median."""
        if self.config.outlier_factor <= 0 or len(points) < 4:
            return points
        d = np.linalg.norm(points - np.median(points, axis=0), axis=1)
        return points[d <= self.config.outlier_factor * np.median(d) + self.config.voxel_size]

    def _associate(self, points: np.ndarray, label: str) -> _Track:
        query = voxel_downsample(points, self.config.voxel_size)
        lo, hi, centre = query.min(axis=0), query.max(axis=0), query.mean(axis=0)
        best, best_score = None, self.config.min_overlap
        for track in self._tracks.values():
            if np.any(track.lo > hi + 0.3) or np.any(track.hi < lo - 0.3):
                continue
            distances, _ = track.tree.query(query, distance_upper_bound=self.config.match_radius)
            overlap = np.count_nonzero(np.isfinite(distances)) / len(query)
            same_label = track.label == label
            r = self.config.match_radius
            if same_label and (
                _inside(centre, track.lo, track.hi, r) or _inside(track.centre, lo, hi, r)
            ):
                overlap = max(overlap, self.config.min_overlap)  # a partial view of the same object
            if overlap <= 0:
                continue
            score = overlap + (self.config.label_bonus if same_label else 0.0)
            if score >= best_score:
                best, best_score = track, score
        if best is None:
            best = _Track(id=str(self._next_id), first_seen=self._keyframe)
            self._tracks[best.id] = best
            self._next_id += 1
        return best

    def _fuse(self, track: _Track, points: np.ndarray, seg: Segment) -> None:
        keys, sums, counts = voxel_accumulate(points, self.config.voxel_size)
        all_keys = np.concatenate([track.keys, keys])
        unique, inverse = np.unique(all_keys, return_inverse=True)
        new_sums = np.zeros((len(unique), 3))
        np.add.at(new_sums, inverse, np.concatenate([track.sums, sums]))
        track.keys, track.sums = unique, new_sums
        track.counts = np.bincount(
            inverse, weights=np.concatenate([track.counts, counts]), minlength=len(unique)
        )
        track.refresh()
        weight = 1.0 if seg.score is None else float(seg.score)
        track.votes[seg.label] += weight
        track.observations += 1
        if seg.score is not None:
            track.score_sum += float(seg.score)
            track.scored += 1

    def _publish(self, touched: dict[str, None]) -> tuple[list[str], list[str]]:
        new, updated = [], []
        for object_id in touched:
            track = self._tracks[object_id]
            if track.observations < self.config.min_observations:
                continue
            centre, label = track.centre, track.label
            if track.published_centre is None:
                new.append(object_id)
            elif (
                np.linalg.norm(centre - track.published_centre) > self.config.min_shift
                or label != track.published_label
            ):
                updated.append(object_id)
            else:
                continue
            track.published_centre, track.published_label = centre, label
        return new, updated

    # Output ----------------------------------------------------------------------------------
    def object(self, object_id: str) -> SemanticObject:
        """The current state of one object."""
        track = self._tracks[object_id]
        points = track.points
        return SemanticObject(
            id=track.id,
            label=track.label,
            position=points.mean(axis=0),
            size=points.max(axis=0) - points.min(axis=0),
            points=points,
            seen=track.first_seen,
            score=round(track.score_sum / track.scored, 4) if track.scored else None,
            extra={"observations": track.observations},
        )

    def objects(self, ids: Iterable[str]) -> list[SemanticObject]:
        return [self.object(i) for i in ids]

    def published_ids(self) -> list[str]:
        return [t.id for t in self._tracks.values() if t.published_centre is not None]

    def local_map(self, include_unconfirmed: bool = False) -> ObjectMap:
        """The local object map (odometry frame, `up` set); only published objects by default."""
        ids = list(self._tracks) if include_unconfirmed else self.published_ids()
        return ObjectMap(self.objects(ids), up=self.up, name=self.name)


def _inside(point: np.ndarray, lo: np.ndarray, hi: np.ndarray, margin: float) -> bool:
    return bool(np.all(point >= lo - margin) and np.all(point <= hi + margin))
