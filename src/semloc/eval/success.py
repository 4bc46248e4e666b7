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
