"""3D recordings with Rerun (`rerun-sdk`, the `viz` extra): maps, placed local objects, updates.

A recording (`.rrd`, opened with `rerun out.rrd`) holds, under `world/` (z up):
`global/points` (object points coloured by label), `global/boxes` (oriented boxes with their
labels) and `global/centres`; the local objects placed by the estimated pose under
`local_estimated/` and by the true pose under `local_true/` when it is known; `associations`,
lines between the paired centres of the best hypothesis.  `DemoRecording` adds, on the
`keyframe` timeline, the growing local map, `scores/top1`, `scores/top2` and `status`.
Entity paths are fixed; labels and ids are data, never part of a path.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import rerun as rr
from scipy.spatial.transform import Rotation

from semloc.maps import ObjectMap
from semloc.pictures.colors import label_colors, rgb
from semloc.results import Result

MAX_POINTS_PER_OBJECT = 400
"""Points kept per object (evenly strided), to keep recordings small."""

LOCAL_SHADE = 0.6
"""Local objects keep their label's hue at this brightness."""


class Recording:
    """A Rerun recording written to `path` (atomically, when closed)."""

    def __init__(self, path: str | os.PathLike[str], name: str = "semloc") -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._partial = self.path.with_name(f".{self.path.name}.partial")
        self.stream = rr.RecordingStream(name)
        self.stream.save(self._partial)
        self.stream.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)

    def discard(self) -> None:
        """Stop recording and remove the partial file (after a failure)."""
        self.stream.disconnect()
        self._partial.unlink(missing_ok=True)

    def close(self) -> Path:
        """Flush the recording and move it into place; returns its path."""
        self.stream.flush()
        self.stream.disconnect()
        os.replace(self._partial, self.path)
        return self.path

    def log_map(
        self, entity: str, objmap: ObjectMap, colors: dict[str, str], shade: float = 1.0,
        static: bool = True,
    ) -> None:  # fmt: skip
        """Points, boxes and labelled centres of `objmap` under `world/<entity>/`."""
        log = self.stream.log
        colour = {
            label: tuple(round(c * shade) for c in rgb(hex_)) for label, hex_ in colors.items()
        }
        points, point_colors = [], []
        for obj in objmap:
            if obj.points is not None and len(obj.points):
                kept = obj.points[:: max(1, len(obj.points) // MAX_POINTS_PER_OBJECT)]
                points.append(kept)
                point_colors.append(np.tile(colour[obj.label], (len(kept), 1)))
        if points:
            positions = np.concatenate(points)
            log(f"world/{entity}/points",
                rr.Points3D(positions, colors=np.concatenate(point_colors), radii=0.01),
                static=static)  # fmt: skip
        boxed = [o for o in objmap if o.size is not None]
        if boxed:
            quaternions = [
                rr.Quaternion(xyzw=Rotation.from_matrix(
                    o.rotation if o.rotation is not None else np.eye(3)).as_quat())
                for o in boxed
            ]  # fmt: skip
            log(f"world/{entity}/boxes",
                rr.Boxes3D(centers=[o.position for o in boxed],
                           half_sizes=[o.size / 2 for o in boxed], quaternions=quaternions,
                           colors=[colour[o.label] for o in boxed],
                           labels=[o.label for o in boxed]),
                static=static)  # fmt: skip
        log(f"world/{entity}/centres",
            rr.Points3D(objmap.positions, colors=[colour[o.label] for o in objmap], radii=0.05,
                        labels=[f"{o.label} {o.id}" for o in objmap], show_labels=not boxed),
            static=static)  # fmt: skip

    def log_associations(
        self, global_map: ObjectMap, placed: ObjectMap, pairs: Sequence[tuple[str, str]],
        static: bool = True,
    ) -> None:  # fmt: skip
        """Lines from each paired global centre to its placed local centre."""
        strips = [[global_map.get(g).position, placed.get(l).position]
                  for g, l in pairs if g in global_map and l in placed]  # fmt: skip
        self.stream.log("world/associations",
                        rr.LineStrips3D(strips, colors=[[20, 20, 20]], radii=0.015),
                        static=static)  # fmt: skip

    def log_moved(
        self, global_map: ObjectMap, placed: ObjectMap, moved: Sequence[tuple[str, str]]
    ) -> None:
        """Arrows from each moved object's place in the map to where it was observed."""
        starts, vectors = _moved_arrows(global_map, placed, moved)
        if starts:
            self.stream.log("world/moved", rr.Arrows3D(origins=starts, vectors=vectors,
                            colors=[[31, 119, 180]], radii=0.03), static=True)  # fmt: skip


def _moved_arrows(global_map, placed, moved):
    starts, vectors = [], []
    for g, l in moved:
        if g in global_map and l in placed:
            starts.append(global_map.get(g).position)
            vectors.append(placed.get(l).position - global_map.get(g).position)
    return starts, vectors


def write_localization(
    path: str | os.PathLike[str],
    global_map: ObjectMap,
    local_map: ObjectMap | None = None,
    pose: np.ndarray | None = None,
    pairs: Sequence[tuple[str, str]] = (),
    true_pose: np.ndarray | None = None,
    moved: Sequence[tuple[str, str]] = (),
) -> Path:
    """A recording of `global_map`, `local_map` placed by `pose` (and `true_pose`), the pairs,
    and arrows from the map's place of each `moved` object to where it was observed."""
    labels = [*global_map.labels, *([] if local_map is None else local_map.labels)]
    colors = label_colors(labels)
    recording = Recording(path)
    recording.log_map("global", global_map, colors)
    if local_map is not None and pose is not None:
        placed = local_map.transformed(pose)
        recording.log_map("local_estimated", placed, colors, LOCAL_SHADE)
        recording.log_associations(global_map, placed, pairs)
        recording.log_moved(global_map, placed, moved)
    if local_map is not None and true_pose is not None:
        recording.log_map("local_true", local_map.transformed(true_pose), colors, 0.3)
    return recording.close()


class DemoRecording:
    """The demo's updates on the `keyframe` timeline: local map, top-2 scores, status."""

    def __init__(
        self, path: str | os.PathLike[str], global_map: ObjectMap, true_pose: np.ndarray,
        labels: Sequence[str],
    ) -> None:  # fmt: skip
        self.global_map, self.true_pose = global_map, true_pose
        self.colors = label_colors([*global_map.labels, *labels])
        self.recording = Recording(path, "semloc demo")
        self.recording.log_map("global", global_map, self.colors)

    def update(self, keyframe: int, local_map: ObjectMap, result: Result) -> None:
        """Log the state after the update at `keyframe`."""
        stream, rec = self.recording.stream, self.recording
        if set(local_map.labels) - set(self.colors):  # a label the final map does not have
            self.colors = label_colors(local_map.labels, self.colors)
        stream.set_time("keyframe", sequence=keyframe)
        rec.log_map("local_true", local_map.transformed(self.true_pose), self.colors, 0.3, False)
        step = result.steps[-1] if result.steps else None
        for rank, score in enumerate((step.top_scores if step else [])[:2], start=1):
            stream.log(f"scores/top{rank}", rr.Scalars(float(score)))
        stream.log("status", rr.TextLog(f"keyframe {keyframe}: {result.status}, "
                                        f"{len(local_map)} local objects"))  # fmt: skip
        if result.pose is None:
            stream.log("world/local_estimated", rr.Clear(recursive=True))
            stream.log("world/associations", rr.Clear(recursive=True))
            return
        placed = local_map.transformed(result.pose)
        rec.log_map("local_estimated", placed, self.colors, LOCAL_SHADE, False)
        pairs = result.best.pairs if result.best else []
        rec.log_associations(self.global_map, placed, pairs, False)

    def close(self) -> Path:
        return self.recording.close()

    def discard(self) -> None:
        self.recording.discard()
