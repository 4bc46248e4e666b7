"""Pose errors and the success criterion shared by the localizer, tests and evaluation.

Success is the paper's: rotation error below 15 degrees and translation error below 0.5 m.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

import numpy as np

ROTATION_TOLERANCE_DEG = 15.0
TRANSLATION_TOLERANCE_M = 0.5


class HasPose(Protocol):
    rank: int
    pose: np.ndarray | None


def pose_error(estimate: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    """Rotation angle (degrees) and translation distance (m) between two 4x4 poses."""
    relative = estimate[:3, :3].T @ truth[:3, :3]
    cos = np.clip((np.trace(relative) - 1.0) / 2.0, -1.0, 1.0)
    return float(np.degrees(np.arccos(cos))), float(np.linalg.norm(estimate[:3, 3] - truth[:3, 3]))


def is_success(
    estimate: np.ndarray | None,
    truth: np.ndarray,
    rotation_deg: float = ROTATION_TOLERANCE_DEG,
    translation_m: float = TRANSLATION_TOLERANCE_M,
) -> bool:
    if estimate is None:
        return False
    rotation, translation = pose_error(estimate, truth)
    return rotation < rotation_deg and translation < translation_m


def first_correct_rank(
    hypotheses: Sequence[HasPose],
    truth: np.ndarray,
    rotation_deg: float = ROTATION_TOLERANCE_DEG,
    translation_m: float = TRANSLATION_TOLERANCE_M,
) -> int | None:
    """1-based rank of the first hypothesis within tolerance, or None."""
    for h in hypotheses:
        if is_success(h.pose, truth, rotation_deg, translation_m):
            return h.rank
    return None
