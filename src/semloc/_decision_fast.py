"""Compiled inner loop of the decision (`decision.py`; numba, cached on disk).

`first_same_place` is `decision.same_place`'s pose test against many poses at once: the
rotation angle between the rotations and the distance the two poses put the anchor apart
(or their translations' distance without an anchor), both below their bounds.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def first_same_place(pose, poses, count, anchor, has_anchor, max_degrees, max_translation):
    """The first of `poses[:count]` at the same place as `pose` (rotation angle below
    `max_degrees` and translation below `max_translation`), or -1."""
    point = np.empty(4)
    point[:3] = anchor
    point[3] = 1.0
    for k in range(count):
        other = poses[k]
        trace = 0.0
        for i in range(3):
            for j in range(3):
                trace += pose[i, j] * other[i, j]
        cos = min(1.0, max(-1.0, (trace - 1.0) / 2.0))
        if math.degrees(math.acos(cos)) >= max_degrees:
            continue
        squares = 0.0
        for i in range(3):
            if has_anchor:
                d = 0.0
                for j in range(4):
                    d += (pose[i, j] - other[i, j]) * point[j]
            else:
                d = pose[i, 3] - other[i, 3]
            squares += d * d
        if math.sqrt(squares) < max_translation:
            return k
    return -1
