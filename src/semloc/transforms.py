"""Rigid transforms shared by every stage: building poses, comparing them, residuals of centres.

Convention: a pose is a 4x4 `T_global_local` with `p_global = R @ p_local + t`.  Pure numpy.
"""

from __future__ import annotations

import numpy as np


def rigid(rotation: np.ndarray, translation: np.ndarray) -> np.ndarray:
    """The 4x4 homogeneous transform [R t; 0 1]."""
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = rotation, translation
    return T


def yaw_rotation(theta: float) -> np.ndarray:
    """Rotation by `theta` radians about +z."""
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def yaw_pose(theta: float, translation=(0.0, 0.0, 0.0)) -> np.ndarray:
    """A gravity-aligned pose: yaw `theta` (radians) about +z, then `translation`."""
    return rigid(yaw_rotation(theta), np.asarray(translation, dtype=float))


def pose_error(estimate: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    """Rotation angle (degrees) and translation distance (m) between two 4x4 poses."""
    relative = estimate[:3, :3].T @ truth[:3, :3]
    cos = np.clip((np.trace(relative) - 1.0) / 2.0, -1.0, 1.0)
    return float(np.degrees(np.arccos(cos))), float(np.linalg.norm(estimate[:3, 3] - truth[:3, 3]))


def centre_residual(pose: np.ndarray, local_xyz: np.ndarray, global_xyz: np.ndarray) -> float:
    """RMS distance (m) between aligned local centres and their global partners."""
    return float(centre_residuals(pose[None], local_xyz[None], global_xyz[None])[0])


def centre_residuals(poses: np.ndarray, local_xyz: np.ndarray, global_xyz: np.ndarray):
    """`centre_residual` of S sets at once: (S, 4, 4) poses, (S, m, 3) centres -> (S,)."""
    aligned = local_xyz @ np.swapaxes(poses[:, :3, :3], 1, 2) + poses[:, None, :3, 3]
    return np.sqrt(np.mean(np.sum((aligned - global_xyz) ** 2, axis=2), axis=1))


def as_pose(value: object, what: str = "pose") -> np.ndarray:
    """`value` as a 4x4 rigid transform (finite, proper rotation, last row 0 0 0 1), or a
    ValueError naming `what` and the problem."""
    try:
        T = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{what} must be a 4x4 matrix (4 rows of 4 numbers)") from None
    if T.shape != (4, 4):
        raise ValueError(f"{what} must be a 4x4 matrix (4 rows of 4 numbers), got shape {T.shape}")
    if not np.all(np.isfinite(T)):
        raise ValueError(f"{what} has non-finite values")
    R = T[:3, :3]
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-4) or np.linalg.det(R) < 0:
        raise ValueError(f"{what}: the rotation part is not a proper rotation")
    if not np.allclose(T[3], [0, 0, 0, 1]):
        raise ValueError(f"{what}: the last row must be 0 0 0 1")
    return T
