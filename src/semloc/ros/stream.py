"""The logic of a streaming relocalizer fed by a 3D object detector: what a ROS 2 node (or a
recorded bag) hands semloc, and what it gets back.  No ROS packages: the bag command and a
live node wrap this in a few lines.

A `DetectionFrame` is one message of detections (oriented boxes with a label and score, and
the points of each where the detector gives them) in one frame at one stamp.
`StreamLocalizer.step(frame, T_odom_frame)` puts them into the odometry frame, fuses them
into local objects with the front end (`semloc.frontend.ObjectFusion`: association by
overlap and label) and, when local objects were added or changed, runs one incremental
`Localizer.update` (with the frame's position, which measures the travel that bounds the
Localizer's window) and returns its `Result`.  A detection without points is fused as points
sampled on its box surface (so boxes associate by overlap; `box_surface`); when no detection of the run
carries points (`use_points=False`) the local objects reach the Localizer as centres and boxes
only.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from semloc.coverage import Coverage
from semloc.frontend.fusion import FusionConfig, ObjectFusion, Segment
from semloc.localizer import Localizer, LocalizerConfig
from semloc.maps import MapError, ObjectMap, SemanticObject
from semloc.results import Result

BOX_GRID = 3
"""Points per box edge sampled for a detection without points: the corners, edge middles and
face centres (26 points).  A track keeps the union of what it was fused from, so denser samples
of boxes that differ a little from view to view would pile up voxels without adding anything."""


@dataclass(frozen=True)
class BoxDetection:
    """One detected object: label, oriented box (centre, size, rotation in the frame), detector
    score and, when the detector gives them, its points (N, 3) in the same frame."""

    label: str
    centre: np.ndarray
    size: np.ndarray
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    score: float | None = None
    points: np.ndarray | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.label, str) or not self.label.strip():
            raise MapError(f"detection label must be a non-empty string, got {self.label!r}")
        centre = np.asarray(self.centre, dtype=float).reshape(3)
        size = np.abs(np.asarray(self.size, dtype=float).reshape(3))
        rotation = np.asarray(self.rotation, dtype=float).reshape(3, 3)
        if not all(np.all(np.isfinite(a)) for a in (centre, size, rotation)):
            raise MapError(f"detection '{self.label}': box is not finite")
        object.__setattr__(self, "centre", centre)
        object.__setattr__(self, "size", size)
        object.__setattr__(self, "rotation", rotation)
        if self.points is not None:
            points = np.asarray(self.points, dtype=float).reshape(-1, 3)
            if not np.all(np.isfinite(points)):
                raise MapError(f"detection '{self.label}': points are not finite")
            object.__setattr__(self, "points", points)

    def samples(self) -> np.ndarray:
        """Its points, or points on its box surface when it has none."""
        if self.points is not None and len(self.points):
            return self.points
        return box_surface(self.centre, self.size, self.rotation)


@dataclass(frozen=True)
class DetectionFrame:
    """The detections of one message: stamp (ns), frame id, detections."""

    stamp: int
    frame: str
    detections: Sequence[BoxDetection]


def box_surface(
    centre: np.ndarray, size: np.ndarray, rotation: np.ndarray, count: int = BOX_GRID
) -> np.ndarray:
    """Points on the surface of an oriented box: the surface of a grid of `count` (>= 2) points
    per edge."""
    axes = [np.linspace(-s / 2, s / 2, max(2, count)) for s in size]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    shape = grid.shape[:3]
    index = np.indices(shape)
    border = np.zeros(shape, dtype=bool)
    for axis in range(3):
        border |= (index[axis] == 0) | (index[axis] == shape[axis] - 1)
    return grid[border] @ np.asarray(rotation).T + np.asarray(centre)


class StreamLocalizer:
    """Detections in, relocalization answers out (see the module docstring)."""

    def __init__(
        self,
        global_map: ObjectMap,
        config: LocalizerConfig | None = None,
        *,
        fusion: FusionConfig | None = None,
        up: Sequence[float] | None = (0.0, 0.0, 1.0),
        use_points: bool = True,
        localizer: Localizer | None = None,
    ) -> None:
        """`localizer`: one to use instead of a new one (anything with `update(objects,
        position=)`, `local_map` and `global_map`, e.g. `semloc.ros2.remote.RemoteLocalizer`)."""
        self.fusion = ObjectFusion(fusion, up=(0.0, 0.0, 1.0) if up is None else up)
        self.localizer = localizer or Localizer(global_map, config, local_up=up)
        self.use_points = use_points
        self.updates = 0

    @property
    def global_map(self) -> ObjectMap:
        return self.localizer.global_map

    def step(
        self, frame: DetectionFrame, T_odom_frame: np.ndarray, coverage: Coverage | None = None
    ) -> Result | None:
        """Fuse one message's detections (in `frame.frame`, whose pose in the odometry frame is
        `T_odom_frame`); the Localizer's answer if local objects changed, else None.
        `coverage`: what the sensor covered at this message (the local objects its detections
        fused into are that look's detections)."""
        segments = [Segment(d.label, d.samples(), d.score) for d in frame.detections]
        update = self.fusion.integrate(segments, T_odom_frame, frame="camera")
        if not update.changed and coverage is None:  # (a look that found nothing still tells)
            return None
        objects = self.fusion.objects(update.changed)
        if not self.use_points:
            objects = [boxed(o) for o in objects]
        self.updates += 1
        if coverage is None:  # (a remote Localizer may take no coverage)
            return self.localizer.update(objects, position=T_odom_frame)
        return self.localizer.update(objects, position=T_odom_frame, coverage=coverage)

    def local_map(self) -> ObjectMap:
        """The local objects as the Localizer has them (odometry frame)."""
        return self.localizer.local_map


def boxed(obj: SemanticObject) -> SemanticObject:
    """The object as centre and box only (its points were sampled on detection boxes)."""
    return replace(obj, points=None)
