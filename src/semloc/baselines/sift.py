"""SIFT keypoints + RANSAC against the global map's keyframes: the paper's SIFT baseline.

The map side: SIFT keypoints (OpenCV's detector and descriptor, RootSIFT-normalised) of every
keyframe of the `KeyframeMap`, each with its depth back-projected to a 3D point in the world
frame (keypoints without depth are dropped).  The query side: at an answer, the keypoints of
the latest `window` query keyframes, back-projected with the query's depth into its local
(odometry) frame.

Retrieval (nearest keyframes): every query descriptor votes for the map keyframe of its nearest
map descriptor; the `retrieve` keyframes with most votes are registered.  Registration: the
query's descriptors matched to that keyframe's with Lowe's ratio test, then RANSAC over the
3D-3D matches with the shared closed-form alignment (`semloc.pose.align_positions`: 4-DoF about
`up`, the paper's known ground plane; 2-point samples), refined on its inliers.  Each
registration with at least `min_inliers` inliers is a hypothesis (pairs: the inlier matches,
score: their number); same places are merged and the decision made as for every baseline
(`semloc.decision.distinct` / `decide`).

What depends only on the map is cached per process (the last 4 maps), and so are the
features of the query frames (by index) within one baseline.  OpenCV is imported on first use.
"""

from __future__ import annotations

import time
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
from pydantic import Field

from semloc.baselines.base import BaselineConfig
from semloc.baselines.recent import Recent
from semloc.decision import decide, distinct
from semloc.frontend.frames import KeyframeMap, RGBDFrame
from semloc.maps import MapError
from semloc.pose import align_positions, align_positions_batch
from semloc.results import Hypothesis, Result, Step


class SiftConfig(BaselineConfig):
    features: int = Field(600, ge=10, description="Most SIFT keypoints per image.")
    contrast_threshold: float = Field(0.04, gt=0, description="SIFT's contrast threshold.")
    ratio: float = Field(0.8, gt=0, le=1, description="Lowe's ratio test.")
    window: int = Field(3, ge=1, description="Latest query keyframes pooled at an answer.")
    retrieve: int = Field(10, ge=1, description="Map keyframes registered per answer.")
    ransac_iterations: int = Field(300, ge=10, description="RANSAC samples per registration.")
    inlier_distance: float = Field(0.1, gt=0, description="RANSAC inlier distance (m).")
    min_inliers: int = Field(10, ge=3, description="Inliers a registration needs.")
    seed: int = Field(0, description="Seed of RANSAC.")


@dataclass(frozen=True)
class Features:
    """Keypoints with depth of one frame: 3D points (frame coordinates), RootSIFT descriptors."""

    xyz: np.ndarray  # (N, 3)
    descriptors: np.ndarray  # (N, 128) float32, unit length

    def __len__(self) -> int:
        return len(self.xyz)


def sift_features(frame: RGBDFrame, config: SiftConfig) -> Features:
    """SIFT keypoints of `frame` that have depth, as 3D points and RootSIFT descriptors."""
    import cv2  # optional dependency (the `bench` extra)

    cv2.setNumThreads(1)
    sift = cv2.SIFT_create(nfeatures=config.features, contrastThreshold=config.contrast_threshold)
    keypoints, desc = sift.detectAndCompute(frame.gray, None)
    if not keypoints or desc is None:
        return Features(np.zeros((0, 3)), np.zeros((0, 128), np.float32))
    xyz, valid = frame.points(np.array([k.pt for k in keypoints]))
    desc = desc[valid].astype(np.float32)
    desc /= np.maximum(desc.sum(axis=1, keepdims=True), 1e-9)  # RootSIFT: L1, then sqrt
    return Features(xyz[valid], np.sqrt(desc))


class MapIndex:
    """The map side: every keyframe's features, stacked (descriptors, points, owner keyframe)."""

    def __init__(self, keyframe_map: KeyframeMap, config: SiftConfig) -> None:
        per = [sift_features(kf, config) for kf in keyframe_map.keyframes]
        self.keyframes = [kf.index for kf in keyframe_map.keyframes]
        self.descriptors = np.concatenate([f.descriptors for f in per])
        self.xyz = np.concatenate([f.xyz for f in per])
        self.owner = np.concatenate([np.full(len(f), i) for i, f in enumerate(per)])
        self.starts = np.concatenate([[0], np.cumsum([len(f) for f in per])])

    def of(self, keyframe: int) -> slice:
        return slice(int(self.starts[keyframe]), int(self.starts[keyframe + 1]))


_INDICES = Recent(4)


def map_index(keyframe_map: KeyframeMap, config: SiftConfig) -> MapIndex:
    """The `MapIndex` of a map, cached per process (the last 4 maps)."""
    key = (id(keyframe_map), config.features, config.contrast_threshold)
    return _INDICES.get(key, lambda: MapIndex(keyframe_map, config), owner=keyframe_map)


def nearest_votes(query: np.ndarray, index: MapIndex, chunk: int = 256) -> np.ndarray:
    """Per map keyframe, how many query descriptors have their nearest map descriptor there."""
    votes = np.zeros(len(index.keyframes))
    for lo in range(0, len(query), chunk):
        nearest = np.argmax(query[lo : lo + chunk] @ index.descriptors.T, axis=1)
        np.add.at(votes, index.owner[nearest], 1.0)
    return votes


def ratio_matches(query: np.ndarray, target: np.ndarray, ratio: float) -> np.ndarray:
    """(query index, target index) pairs passing Lowe's ratio test (L2 distances)."""
    if len(target) < 2 or not len(query):
        return np.zeros((0, 2), dtype=int)
    d2 = np.maximum(
        (query**2).sum(1)[:, None] + (target**2).sum(1)[None] - 2 * query @ target.T, 0.0
    )
    two = np.argpartition(d2, 1, axis=1)[:, :2]
    first, second = np.take_along_axis(d2, two, axis=1).T
    swap = second < first
    best = np.where(swap, two[:, 1], two[:, 0])
    near, far = np.minimum(first, second), np.maximum(first, second)
    keep = np.sqrt(near) < ratio * np.sqrt(far)
    return np.column_stack([np.flatnonzero(keep), best[keep]])


def ransac_align(
    src: np.ndarray, dst: np.ndarray, up_src, up_dst, config: SiftConfig, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray] | None:
    """RANSAC over 3D-3D matches `src` -> `dst` with the shared closed form (2-point samples
    with `up`s, 3 otherwise), refined twice on the inliers: (T, inlier mask) or None."""
    n, m = len(src), (2 if up_src is not None and up_dst is not None else 3)
    if n < max(m, config.min_inliers):
        return None
    samples = np.array([rng.choice(n, size=m, replace=False)
                        for _ in range(config.ransac_iterations)])  # fmt: skip
    T, ok = align_positions_batch(src[samples], dst[samples], up_src, up_dst)
    if not ok.any():
        return None
    T = T[ok]
    moved = np.einsum("sij,nj->sni", T[:, :3, :3], src) + T[:, None, :3, 3]
    inliers = np.linalg.norm(moved - dst[None], axis=2) < config.inlier_distance
    mask = inliers[int(np.argmax(inliers.sum(axis=1)))]
    best = None
    for _ in range(2):
        if mask.sum() < max(m, config.min_inliers):
            break
        try:
            best = align_positions(src[mask], dst[mask], up_src, up_dst)
        except ValueError:
            break
        moved = src @ best[:3, :3].T + best[:3, 3]
        mask = np.linalg.norm(moved - dst, axis=1) < config.inlier_distance
    if best is None or mask.sum() < config.min_inliers:
        return None
    return best, mask


class SiftBaseline:
    """SIFT + nearest-keyframe retrieval + RANSAC (see the module docstring); the
    `ImageRelocalizer` interface: `update_frames(frames, answer=True) -> Result` (its steps'
    `n_local` counts the query keyframes received)."""

    name = "sift"
    config_class = SiftConfig

    def __init__(
        self, keyframe_map: KeyframeMap, config: SiftConfig | None = None, local_up: Any = None
    ) -> None:
        if not isinstance(keyframe_map, KeyframeMap):
            raise MapError(
                f"{self.name} localizes images: it needs the global map's keyframes (a "
                f"KeyframeMap of colour, depth, intrinsics and poses), got "
                f"{type(keyframe_map).__name__}"
            )
        self.config = config or SiftConfig()
        self.keyframe_map = keyframe_map
        self.local_up = None if local_up is None else np.asarray(local_up, dtype=float)
        self._frames: dict[int, RGBDFrame] = {}
        self._features: dict[int, Features] = {}
        self._steps: list[Step] = []
        self._timing = {"association": 0.0, "pose": 0.0, "total": 0.0}

    def update_frames(self, frames: Iterable[RGBDFrame], answer: bool = True) -> Result | None:
        """Add query keyframes (local frame); with `answer`, localize the latest `window`."""
        start = time.perf_counter()
        for frame in frames:
            if not isinstance(frame, RGBDFrame):
                raise MapError(f"update_frames() takes RGBDFrame items, got {type(frame).__name__}")
            self._frames[frame.index] = frame
            self._features.pop(frame.index, None)  # a new version of a keyframe
        if not answer:
            return None
        index = map_index(self.keyframe_map, self.config)
        window = list(self._frames)[-self.config.window :]
        feats = [self._query_features(k) for k in window]
        tick = time.perf_counter()
        hypotheses, n_sets = self._hypotheses(feats, window, index)
        status, reason = decide(hypotheses, self.config.decision, "score")
        end = time.perf_counter()
        for key, value in (("association", tick - start), ("pose", end - tick)):
            self._timing[key] += value * 1e3
        self._timing["total"] += (end - start) * 1e3
        self._steps.append(Step(len(self._steps), len(self._frames), n_sets,
                                [h.score for h in hypotheses], (end - start) * 1e3, status))  # fmt: skip
        return Result.of(status, hypotheses, self._steps, self._timing, reason)

    def _query_features(self, k: int) -> Features:
        if k not in self._features:
            self._features[k] = sift_features(self._frames[k], self.config)
        return self._features[k]

    def _hypotheses(
        self, feats: list[Features], window: list[int], index: MapIndex
    ) -> tuple[list[Hypothesis], int]:
        cfg = self.config
        desc = np.concatenate([f.descriptors for f in feats])
        xyz = np.concatenate([f.xyz for f in feats])
        names = [f"{k}:{i}" for k, f in zip(window, feats, strict=True) for i in range(len(f))]
        if not len(desc) or not len(index.descriptors):
            return [], 0
        votes = nearest_votes(desc, index)
        order = [int(j) for j in np.argsort(-votes, kind="stable")[: cfg.retrieve] if votes[j]]
        rng = np.random.default_rng(cfg.seed)
        found = [fit for j in order
                 if (fit := self._register(desc, xyz, names, index, j, rng)) is not None]  # fmt: skip
        found.sort(key=lambda item: -item[0])
        anchor = xyz.mean(axis=0) if len(xyz) else None
        chosen = distinct(((p, T) for _, p, T, _ in found), cfg.top_k, cfg.decision, anchor)
        hypotheses = [
            Hypothesis(rank=rank, score=float(found[i][0]), pairs=found[i][1], pose=found[i][2],
                       residual=found[i][3], method=f"{self.name}+ransac")
            for rank, i in enumerate(chosen, 1)
        ]  # fmt: skip
        return hypotheses, len(found)

    def _register(
        self, desc: np.ndarray, xyz: np.ndarray, names: list[str], index: MapIndex, j: int, rng
    ) -> tuple[int, list[tuple[str, str]], np.ndarray, float] | None:
        """The query's matches with map keyframe `j` by RANSAC: (inliers, pairs, pose,
        RMS residual of the inliers), or None below `min_inliers`."""
        part = index.of(j)
        matches = ratio_matches(desc, index.descriptors[part], self.config.ratio)
        src, dst = xyz[matches[:, 0]], index.xyz[part][matches[:, 1]]
        fit = ransac_align(src, dst, self.local_up, self.keyframe_map.up, self.config, rng)
        if fit is None:
            return None
        T, mask = fit
        pairs = [(f"{index.keyframes[j]}:{b}", names[a]) for a, b in matches[mask]]
        moved = src[mask] @ T[:3, :3].T + T[:3, 3]
        residual = float(np.sqrt(np.mean(np.sum((moved - dst[mask]) ** 2, axis=1))))
        return len(pairs), pairs, T, residual
