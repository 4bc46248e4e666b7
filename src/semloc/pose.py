"""TEMPORARY closed-form stand-in; replaced by the pose branch (same contract)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydantic import BaseModel, ConfigDict


class PoseConfig(BaseModel):
    model_config = ConfigDict(extra="forbid")
    refine: bool = True


@dataclass(frozen=True)
class PoseEstimate:
    T: np.ndarray
    fitness: float
    rmse: float
    method: str


def align_positions(local_xyz, global_xyz, up_local=None, up_global=None, weights=None):
    src, dst = np.asarray(local_xyz, float), np.asarray(global_xyz, float)
    if up_local is not None and up_global is not None and len(src) >= 2:
        cs, cd = src.mean(0), dst.mean(0)
        a, b = src[:, :2] - cs[:2], dst[:, :2] - cd[:2]
        yaw = np.arctan2(np.sum(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]), np.sum(a * b))
        c, s_ = np.cos(yaw), np.sin(yaw)
        T = np.eye(4)
        T[:3, :3] = [[c, -s_, 0], [s_, c, 0], [0, 0, 1]]
        T[:3, 3] = cd - T[:3, :3] @ cs
        return T
    if len(src) < 3:
        raise ValueError("need 3 points")
    cs, cd = src.mean(0), dst.mean(0)
    U, _, Vt = np.linalg.svd((src - cs).T @ (dst - cd))
    D = np.diag([1, 1, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, cd - R @ cs
    return T


def estimate_pose(
    local_positions,
    global_positions,
    local_points,
    global_points,
    up_local=None,
    up_global=None,
    config=None,
):
    try:
        T = align_positions(local_positions, global_positions, up_local, up_global)
    except ValueError:
        return None
    res = np.linalg.norm(
        np.asarray(local_positions) @ T[:3, :3].T + T[:3, 3] - global_positions, axis=1
    )
    return PoseEstimate(
        T, float(np.mean(res < 0.5)), float(np.sqrt(np.mean(res**2))), "closed-form-6dof"
    )
