"""The paper's success criterion: rotation error below 15 degrees and translation below 0.5 m.

Shared by the evaluation protocol, the benchmarks, the demo, `semloc localize --gt` and tests.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

import numpy as np

from semloc.transforms import pose_error

ROTATION_TOLERANCE_DEG = 15.0
TRANSLATION_TOLERANCE_M = 0.5


class HasPose(Protocol):
    rank: int
    pose: np.ndarray | None


def is_success(
    estimate: np.ndarray | None,
    truth: np.ndarray,
    rotation_deg: float = ROTATION_TOLERANCE_DEG,
    translation_m: float = TRANSLATION_TOLERANCE_M,
) -> bool:
    """Whether `estimate` is within the tolerances of `truth` (False for no estimate)."""
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


def ground_truth_report(
    pose: np.ndarray | None, hypotheses: Sequence[HasPose], truth: np.ndarray
) -> dict[str, float | bool | int | None]:
    """The errors of `pose` against `truth`, success at 15° / 0.5 m and the rank of the first
    hypothesis within them (errors None without a pose; rank None when none is right)."""
    rotation = translation = None
    if pose is not None:
        rotation, translation = (round(v, 6) for v in pose_error(pose, truth))
    return {
        "rotation_deg": rotation,
        "translation_m": translation,
        "success": is_success(pose, truth),
        "rank_of_first_correct": first_correct_rank(hypotheses, truth),
    }
