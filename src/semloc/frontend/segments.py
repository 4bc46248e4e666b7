"""From an RGB-D frame and instance masks (any segmenter) to `Segment`s for the object fusion.

`segments_from_masks(depth, masks, labels, K)` back-projects the valid depth pixels of each
mask with the pinhole intrinsics `K` (3x3) and returns camera-frame segments; pass them to
`ObjectFusion.integrate(segments, T_odom_camera, frame="camera")`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from semloc.frontend.fusion import Segment
from semloc.maps import MapError


def backproject(depth: np.ndarray, K: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
    """Camera-frame points (N, 3) of the pixels with depth > 0 (inside `mask` if given).

    `depth` is the z-depth in metres (H, W); `K` the 3x3 intrinsics; OpenCV camera axes.
    """
    valid = np.asarray(depth) > 0
    if mask is not None:
        valid &= np.asarray(mask, dtype=bool)
    v, u = np.nonzero(valid)
    z = depth[v, u].astype(float)
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    return np.stack([(u - cx) / fx * z, (v - cy) / fy * z, z], axis=1)


def segments_from_masks(
    depth: np.ndarray,
    masks: Sequence[np.ndarray] | np.ndarray,
    labels: Sequence[str],
    K: np.ndarray,
    scores: Sequence[float] | None = None,
    *,
    depth_scale: float = 1.0,
    max_depth: float = 8.0,
    min_points: int = 20,
) -> list[Segment]:
    """One camera-frame `Segment` per instance mask (masks with too few valid pixels are dropped).

    `masks`: a list of boolean (H, W) masks or an (M, H, W) array; `depth_scale` converts the
    depth image to metres (e.g. 0.001 for millimetre PNGs); `max_depth` drops far returns.
    """
    depth = np.asarray(depth, dtype=float) * depth_scale
    K = np.asarray(K, dtype=float)
    if depth.ndim != 2:
        raise MapError(f"depth must be an (H, W) image, got shape {depth.shape}")
    if K.shape != (3, 3):
        raise MapError(f"intrinsics must be a 3 x 3 matrix, got shape {K.shape}")
    if len(masks) != len(labels) or (scores is not None and len(scores) != len(labels)):
        raise MapError(f"{len(masks)} masks, {len(labels)} labels and scores do not match")
    depth = np.where(np.isfinite(depth) & (depth <= max_depth), depth, 0.0)
    segments = []
    for i, mask in enumerate(masks):
        mask = np.asarray(mask, dtype=bool)
        if mask.shape != depth.shape:
            raise MapError(f"mask {i} has shape {mask.shape}, the depth image {depth.shape}")
        points = backproject(depth, K, mask)
        if len(points) >= min_points:
            segments.append(Segment(labels[i], points, None if scores is None else scores[i]))
    return segments
