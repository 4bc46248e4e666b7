"""What the camera covered, from ROS messages: `sensor_msgs/CameraInfo` gives the field of view,
static TF (`/tf_static`) places the camera in the detections' frame, and the odometry places
that frame in the odometry frame; the result is the `semloc.Coverage` of each update.

Conventions: the camera frame is the optical frame of `CameraInfo.header.frame_id` (z forward,
x right, y down, as ROS's `*_optical_frame`), which is `Coverage`'s.  The horizontal field of
view is 2 atan(width / 2 fx), the vertical 2 atan(height / 2 fy) (`k` = [fx 0 cx 0 fy cy 0 0
1]).  CameraInfo holds no range: the caller says how far its detector finds objects
reliably.  Static transforms are chained through their common root; a camera frame no static
transform joins to the detections' frame is an error (`CameraError`).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np

from semloc.coverage import Coverage
from semloc.ros import messages as msgs


class CameraError(ValueError):
    """CameraInfo or static TF that cannot place the camera's look."""


@dataclass(frozen=True)
class Camera:
    """A camera's optical frame and field of view (degrees, horizontal and vertical)."""

    frame: str
    fov_deg: tuple[float, float]

    @classmethod
    def of(cls, info: Any) -> Camera:
        """The camera of a `sensor_msgs/CameraInfo` message; CameraError when its size or focal
        lengths cannot give a field of view."""
        width, height = int(info.width), int(info.height)
        k = [float(v) for v in info.k]
        fx, fy = (k[0], k[4]) if len(k) == 9 else (0.0, 0.0)
        if width <= 0 or height <= 0 or not (fx > 0 and fy > 0) or not math.isfinite(fx + fy):
            raise CameraError(
                f"camera info of frame '{info.header.frame_id}' has no field of view "
                f"(width {width}, height {height}, fx {fx:g}, fy {fy:g})"
            )
        fov = (2 * math.degrees(math.atan(width / (2 * fx))),
               2 * math.degrees(math.atan(height / (2 * fy))))  # fmt: skip
        return cls(str(info.header.frame_id), fov)


class StaticFrames:
    """The static transforms of a run (`tf2_msgs/TFMessage`s of `/tf_static`)."""

    def __init__(self, messages: Iterable[Any] = ()) -> None:
        self.parent: dict[str, tuple[str, np.ndarray]] = {}  # child -> (parent, T_parent_child)
        for message in messages:
            self.add(message)

    def add(self, message: Any) -> None:
        """The transforms of one more message (a later transform of a child replaces the
        earlier one, as tf2's buffer does)."""
        for t in message.transforms:
            T = msgs.matrix(t.transform)
            self.parent[str(t.child_frame_id)] = (str(t.header.frame_id), T)

    def _to_root(self, frame: str) -> tuple[str, np.ndarray]:
        """The root of `frame`'s static tree and T_root_frame."""
        T, seen = np.eye(4), {frame}
        while frame in self.parent:
            frame, T_parent_child = self.parent[frame]
            T = T_parent_child @ T
            if frame in seen:
                raise CameraError(f"static TF has a loop through '{frame}'")
            seen.add(frame)
        return frame, T

    def transform(self, target: str, source: str) -> np.ndarray:
        """T_target_source: `source` coordinates into `target`; CameraError when no static
        transform joins them."""
        if target == source:
            return np.eye(4)
        root_t, T_root_target = self._to_root(target)
        root_s, T_root_source = self._to_root(source)
        if root_t != root_s:
            raise CameraError(f"no static transform (/tf_static) joins '{target}' and '{source}'")
        return np.linalg.inv(T_root_target) @ T_root_source


@dataclass(frozen=True)
class CameraCoverage:
    """The coverage of a camera whose detections arrive in another (or the same) frame."""

    camera: Camera
    frames: StaticFrames
    range_m: float

    def at(self, T_odom_frame: np.ndarray, frame: str) -> Coverage:
        """The look of an update whose detections are in `frame`, at `T_odom_frame`."""
        T_frame_camera = self.frames.transform(frame, self.camera.frame)
        return Coverage(T_odom_frame @ T_frame_camera, self.range_m, self.camera.fov_deg)
