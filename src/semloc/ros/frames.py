"""Frames and time for the bag commands: quaternions, odometry looked up at a stamp, and the
covariance of an answer.  Plain numpy / scipy (no ROS packages), so it is tested on its own.

`Trajectory` holds the odometry poses of a run by stamp and answers the pose at any stamp
between two of them (translation interpolated linearly, rotation spherically); outside the
recorded stamps, or across a gap longer than `max_gap`, it has no answer.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from semloc.results import Hypothesis


def quaternion_of(rotation: np.ndarray) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a rotation matrix, w >= 0."""
    q = Rotation.from_matrix(np.asarray(rotation, dtype=float)).as_quat()
    q = -q if q[3] < 0 else q
    return float(q[0]), float(q[1]), float(q[2]), float(q[3])


def matrix_of(translation: Sequence[float], quaternion: Sequence[float]) -> np.ndarray:
    """4x4 pose of a translation and an (x, y, z, w) quaternion (normalised; ValueError if
    it is zero or not finite)."""
    q = np.asarray(quaternion, dtype=float)
    t = np.asarray(translation, dtype=float)
    norm = float(np.linalg.norm(q))
    if not (np.all(np.isfinite(q)) and np.all(np.isfinite(t))) or norm < 1e-9:
        raise ValueError("pose is not finite or its quaternion is zero")
    T = np.eye(4)
    T[:3, :3] = Rotation.from_quat(q / norm).as_matrix()
    T[:3, 3] = t
    return T


class Trajectory:
    """Poses by stamp (nanoseconds, increasing after sorting); `at(stamp)` interpolates."""

    def __init__(self, stamps: Sequence[int], poses: Sequence[np.ndarray], max_gap_ns: int):
        order = np.argsort(np.asarray(stamps, dtype=np.int64), kind="stable")
        self.stamps = np.asarray(stamps, dtype=np.int64)[order]
        self.poses = np.asarray(poses, dtype=float).reshape(-1, 4, 4)[order]
        self.max_gap_ns = int(max_gap_ns)

    def __len__(self) -> int:
        return len(self.stamps)

    def at(self, stamp: int) -> np.ndarray | None:
        """The pose at `stamp`, or None when no recorded pose is near enough on both sides."""
        if not len(self.stamps):
            return None
        i = int(np.searchsorted(self.stamps, stamp))
        if i < len(self.stamps) and self.stamps[i] == stamp:
            return self.poses[i]
        if i == 0 or i == len(self.stamps):
            edge = 0 if i == 0 else len(self.stamps) - 1
            near = abs(int(self.stamps[edge]) - stamp) <= self.max_gap_ns // 2
            return self.poses[edge] if near else None
        t0, t1 = int(self.stamps[i - 1]), int(self.stamps[i])
        if t1 - t0 > self.max_gap_ns:
            return None
        return interpolate(self.poses[i - 1], self.poses[i], (stamp - t0) / (t1 - t0))


def interpolate(A: np.ndarray, B: np.ndarray, s: float) -> np.ndarray:
    """The pose a fraction `s` of the way from A to B."""
    rotations = Rotation.from_matrix(np.stack([A[:3, :3], B[:3, :3]]))
    T = np.eye(4)
    T[:3, :3] = Slerp([0.0, 1.0], rotations)([s]).as_matrix()[0]
    T[:3, 3] = (1 - s) * A[:3, 3] + s * B[:3, 3]
    return T


MIN_RESIDUAL_M = 0.02
"""Floor of the centre residual in the covariance (a perfect fit is not a perfect pose)."""
MIN_SPREAD_M = 0.1
"""Floor of the spread of the matched centres (a tight cluster turns badly)."""


def covariance(hypothesis: Hypothesis, local_centres: np.ndarray) -> np.ndarray:
    """6x6 covariance (x, y, z, roll, pitch, yaw; ROS order) of a hypothesis's pose from its fit.

    With n matched pairs whose aligned centres miss their partners by r (RMS, floored at
    2 cm) and local centres spread s about their mean (RMS, floored at 0.1 m): variance of
    the position r²/n per axis, of each angle r²/(n·s²) — the standard errors of a mean
    offset and of a rotation about the centroid.  Diagonal."""
    n = max(len(hypothesis.pairs), 1)
    r = max(hypothesis.residual or 0.0, MIN_RESIDUAL_M)
    centres = np.asarray(local_centres, dtype=float).reshape(-1, 3)
    spread = 0.0
    if len(centres) > 1:
        spread = float(np.sqrt(np.mean(np.sum((centres - centres.mean(0)) ** 2, axis=1))))
    s = max(spread, MIN_SPREAD_M)
    variances = [r**2 / n] * 3 + [r**2 / (n * s**2)] * 3
    return np.diag(variances)
