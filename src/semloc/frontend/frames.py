"""RGB-D keyframes for the image-based methods: colour, depth, intrinsics and pose, as arrays.

An `RGBDFrame` is one keyframe (colour (H, W, 3) uint8, z-depth (H, W) float32 metres with
0 = no return, the 3x3 pinhole matrix and `T_frame_camera`, the camera's pose in the frame its
map lives in: the world for a global map's keyframes, the odometry frame for a query's).  A
`KeyframeMap` is what an image method localizes against: the global map's keyframes and its
`up`.  Pure numpy: no I/O, no OpenCV.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class RGBDFrame:
    """One RGB-D keyframe (see the module docstring); validated on construction."""

    index: int
    rgb: np.ndarray = field(repr=False)
    depth: np.ndarray = field(repr=False)
    K: np.ndarray = field(repr=False)
    T_frame_camera: np.ndarray = field(repr=False)

    def __post_init__(self) -> None:
        rgb, depth = np.asarray(self.rgb), np.asarray(self.depth)
        if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint8:
            raise ValueError(f"rgb must be an (H, W, 3) uint8 image, got {rgb.shape} {rgb.dtype}")
        if depth.shape != rgb.shape[:2]:
            raise ValueError(f"depth {depth.shape} and rgb {rgb.shape[:2]} differ in size")
        if np.asarray(self.K).shape != (3, 3) or np.asarray(self.T_frame_camera).shape != (4, 4):
            raise ValueError("K must be 3x3 and T_frame_camera 4x4")

    @property
    def gray(self) -> np.ndarray:
        """Luma (Rec. 601) as (H, W) uint8."""
        weights = np.array([0.299, 0.587, 0.114])
        return np.clip(self.rgb.astype(np.float32) @ weights + 0.5, 0, 255).astype(np.uint8)

    def points(self, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Frame-coordinate 3D points of pixel positions `uv` (N, 2) (x right, y down) with
        their depth (nearest pixel), and which of them had a depth return."""
        uv = np.asarray(uv, dtype=float).reshape(-1, 2)
        h, w = self.depth.shape
        col = np.clip(np.rint(uv[:, 0]).astype(int), 0, w - 1)
        row = np.clip(np.rint(uv[:, 1]).astype(int), 0, h - 1)
        z = self.depth[row, col].astype(float)
        valid = np.isfinite(z) & (z > 0)
        K = np.asarray(self.K, dtype=float)
        x = (uv[:, 0] - K[0, 2]) / K[0, 0] * z
        y = (uv[:, 1] - K[1, 2]) / K[1, 1] * z
        camera = np.stack([x, y, z], axis=1)
        T = np.asarray(self.T_frame_camera, dtype=float)
        return camera @ T[:3, :3].T + T[:3, 3], valid


@dataclass(frozen=True)
class KeyframeMap:
    """A global map as keyframes (world frame) for the image methods."""

    keyframes: tuple[RGBDFrame, ...]
    up: np.ndarray | None = None
    name: str = ""

    @classmethod
    def of(cls, frames: Iterable[RGBDFrame], up=(0.0, 0.0, 1.0), name: str = "") -> KeyframeMap:
        frames = tuple(frames)
        if not frames:
            raise ValueError("a keyframe map needs at least one keyframe")
        return cls(frames, None if up is None else np.asarray(up, dtype=float), name)

    def __len__(self) -> int:
        return len(self.keyframes)
