"""Pose recovery: the rigid transform of the local frame in the global frame from matched objects.

This module owns the last stage of the pipeline (paper, "Camera pose recovery"):

1. **Closed form** (`align_positions`): weighted least-squares alignment of matched object
   centres, 6-DoF (Kabsch/Umeyama without scale) or 4-DoF (yaw about gravity-up + translation)
   when both frames know their `up` direction; solved in compiled code (`semloc.closed_form`)
   in the z-up frames (`z_up_rotations`).
2. **Global search** when the centres alone do not determine the pose (1 pair, 2 pairs on the
   up axis in 4-DoF, 1-2 pairs or collinear centres in 6-DoF; with points, also centres spread
   less than `min_spread`, whose closed-form rotation would be noise): the free rotation is sampled
   (a 1-D sweep about the axis through the matched centres, or a coarse grid over SO(3) for a
   single 6-DoF pair) and scored by point-set fitness; the best few candidates are refined.
   This is the low-dimensional stand-in for the paper's Go-ICP.
3. **Robust ICP** of each matched pair's points: a local object's points are matched only to
   the points of its partner object (its KD-tree, built once per object, see `ObjectCloud`);
   Gauss-Newton on point-to-plane plus a little point-to-point error with Tukey weights
   (kernel annealed from `icp_kernel_start` to `icp_kernel`) and correspondences restricted
   to compatible normals.  The loop runs in compiled code (`semloc.registration`).
   The 4-DoF update is a rotation about the global `up` (plus a translation), and the result
   is snapped to a yaw in the z-up frames, so `R @ up_local == up_global` holds exactly;
   6-DoF updates the full rotation.  Coarse kernel levels move a thinned subset of the local
   points.  A refinement is kept only if it does not lower fitness.

Why not a registration library's own ICP loop: small_gicp and Open3D solve 6-DoF only, with
no normal-compatibility test; semloc needs the exact gravity-aligned 4-DoF mode and
partner-restricted correspondences.  Their KD-trees cannot be searched from compiled code, so
semloc keeps its own (`semloc.neighbours`; a query costs about what small_gicp's does) and
runs the whole ICP loop compiled, with no Python per iteration.
`benchmarks/bench_pose.py` compares it with small_gicp's and Open3D's ICP on the same problems.

Per-object preparation (voxel downsampling, a cap of `icp_max_points`, normals, flatness,
KD-tree) is `prepare_cloud`; `cached_cloud` keeps it per object while the object lives, so a
map's objects are prepared once however many localizations use them.  `estimate_pose` takes
prepared `ObjectCloud`s or plain arrays (prepared on the fly) and an optional warm start.
Everything is pure computation on numpy arrays (no I/O, no plotting).
Convention: `T_global_local`, i.e. `p_global = R @ p_local + t`.
"""

from __future__ import annotations

import copy
import functools
import math
import weakref
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

import semloc.closed_form as closed_form
import semloc.registration as registration
from semloc.closed_form import DEGENERATE
from semloc.neighbours import Forest, KdTree, neighbourhood_shapes
from semloc.pointsets import voxel_downsample

__all__ = [
    "ObjectCloud",
    "PoseConfig",
    "PoseEstimate",
    "align_positions",
    "align_positions_batch",
    "cached_cloud",
    "PoseRecovery",
    "estimate_pose",
    "prepare_cloud",
    "recover_pose",
]

_CENTRE_INLIER = 0.5  # m: centre-based fitness threshold (no points)
_SEARCH_POINTS = 256  # local points used to score search candidates
_SEARCH_CANDIDATES = 3  # best local maxima refined after the coarse search
_CANDIDATE_SHARE = 0.5  # ... if their score is at least this share of the best score
_SO3_DIRECTIONS = 48  # Fibonacci directions of the 1-pair 6-DoF search (x yaw steps)
_NORMAL_NEIGHBOURS = 8  # neighbours for normal estimation
_MATCH_NEIGHBOURS = (16, 4)  # neighbours searched for a compatible normal: coarse, final
_COARSE_POINTS = 200  # local points used by ICP while the kernel is above icp_kernel
_FLAT_VARIATION = 0.05  # surface variation at which a neighbourhood stops counting as flat
_CONVERGED = 0.01  # an ICP step moving the points less than this x kernel has converged
_POINT_TO_POINT = 0.1  # weight of the point-to-point error next to the point-to-plane error


class PoseConfig(BaseModel):
    """Settings of pose recovery (closed form, global search, robust ICP)."""

    model_config = ConfigDict(extra="forbid")

    refine: bool = Field(True, description="Run robust ICP when both sides have object points.")
    icp_iterations: int = Field(30, ge=0, description="Maximum number of ICP iterations.")
    icp_voxel: float = Field(
        0.05, ge=0, description="Voxel size (m) for downsampling before ICP / fitness; 0 = off."
    )
    icp_max_points: int = Field(
        2000, ge=3, description="Points kept per object after downsampling (seeded subsample)."
    )
    local_points: int = Field(
        500,
        ge=3,
        description="Local points one pose recovery moves, matches and counts (ICP, fitness, "
        "search): the matched local objects' points thinned evenly to at most this many.",
    )
    icp_kernel: float = Field(
        0.1, gt=0, description="Final Tukey kernel scale (m): residuals beyond it get no weight."
    )
    icp_kernel_start: float = Field(
        0.6,
        gt=0,
        description="Initial Tukey kernel scale (m), halved on convergence down to icp_kernel; "
        "about twice the largest centre bias (partial views) that ICP should still correct.",
    )
    icp_normal_angle: float = Field(
        45.0,
        gt=0,
        le=90,
        description="Max angle (deg) between unoriented normals of ICP correspondences; 90 = off.",
    )
    fitness_radius: float = Field(
        0.1, gt=0, description="A local point is an inlier if a global point is within this (m)."
    )
    search_steps: int = Field(
        72, ge=4, description="Angular samples of the 1-D rotation search (72 = 5 deg), refined."
    )
    min_spread: float = Field(
        0.1,
        ge=0,
        description="Centres spread less than this (m; horizontally in 4-DoF, off their best line "
        "in 6-DoF) are treated as degenerate and resolved by the search when points exist.",
    )
    seed: int = Field(
        0, ge=0, le=2**32 - 1, description="Seed of the per-object point subsampling."
    )


@dataclass(frozen=True)
class PoseEstimate:
    """A recovered pose with its quality.

    `fitness` is the share of (downsampled) local points with a global point within
    `fitness_radius`, or without points the share of matched objects whose aligned centre is
    within 0.5 m of its partner; `rmse` is the RMS distance of those inliers (0 if none).
    """

    T: np.ndarray
    fitness: float
    rmse: float
    method: str


# --------------------------------------------------------------------------- validation


def _xyz(array: object, name: str) -> np.ndarray:
    a = np.asarray(array, dtype=float)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"{name} must have shape (N, 3), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} has non-finite values")
    return a


def _unit(vector: object, name: str) -> np.ndarray:
    v = np.asarray(vector, dtype=float)
    if v.shape != (3,) or not np.isfinite(v).all():
        raise ValueError(f"{name} must be 3 finite numbers, got {v!r}")
    norm = math.sqrt(v.dot(v))  # what np.linalg.norm computes, without its dispatch
    if norm < 1e-12:
        raise ValueError(f"{name} must be non-zero")
    return v / norm


def _weights(weights: object, n: int) -> np.ndarray:
    if weights is None:
        return np.ones(n)
    w = np.asarray(weights, dtype=float)
    if w.shape != (n,) or not np.all(np.isfinite(w)) or np.any(w < 0):
        raise ValueError(f"weights must be {n} finite non-negative numbers")
    if w.sum() <= 0:
        raise ValueError("weights must not all be zero")
    return w


def _pairs(local_xyz: object, global_xyz: object) -> tuple[np.ndarray, np.ndarray]:
    src, dst = _xyz(local_xyz, "local positions"), _xyz(global_xyz, "global positions")
    if len(src) != len(dst):
        raise ValueError(f"{len(src)} local vs {len(dst)} global positions: rows must pair up")
    if len(src) == 0:
        raise ValueError("no matched positions")
    return src, dst


# --------------------------------------------------------------------------- geometry


def _transform(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    return T


def _rot_to_z(up: np.ndarray) -> np.ndarray:
    """Smallest rotation taking the unit vector `up` onto +z (Rodrigues, axis up x z); read-only
    (a map's few `up` vectors recur in every pose recovery, so their rotations are kept)."""
    return _rot_to_z_of(np.asarray(up, dtype=float)[:3].tobytes())  # bytes: -0.0 is not 0.0


@functools.lru_cache(maxsize=64)
def _rot_to_z_of(up: bytes) -> np.ndarray:
    x, y, c = np.frombuffer(up).tolist()
    if c < -1 + 1e-12:
        R = np.diag([1.0, -1.0, -1.0])
    else:
        k = 1.0 / (1.0 + c)
        R = np.array(
            [
                [1 - k * x * x, -k * x * y, -x],
                [-k * x * y, 1 - k * y * y, -y],
                [x, y, 1 - k * (x * x + y * y)],
            ]
        )
    R.flags.writeable = False
    return R


def z_up_rotations(up_local: object, up_global: object) -> tuple[np.ndarray, np.ndarray]:
    """The rotations taking each frame's `up` onto +z (local, global): in these z-up frames
    a gravity-aligned (4-DoF) pose is a yaw about +z and a translation."""
    return _rot_to_z(_unit(up_local, "up_local")), _rot_to_z(_unit(up_global, "up_global"))


def _rot_z(theta: np.ndarray | float) -> np.ndarray:
    """Rotation(s) about +z; shape (3,3) for a scalar angle or (K,3,3)."""
    if np.ndim(theta) == 0:
        c, s = np.cos(theta), np.sin(theta)
        return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    c, s = np.cos(theta), np.sin(theta)
    R = np.zeros((len(c), 3, 3))
    R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1], R[:, 2, 2] = c, -s, s, c, 1.0
    return R


# --------------------------------------------------------------------------- closed form


def align_positions(
    local_xyz: np.ndarray,
    global_xyz: np.ndarray,
    up_local: np.ndarray | None = None,
    up_global: np.ndarray | None = None,
    weights: np.ndarray | None = None,
) -> np.ndarray:
    """Closed-form least-squares rigid T (4x4) with global ≈ R @ local + t (no scale).

    4-DoF when both `up_local` and `up_global` are given: R maps up_local onto up_global and is
    otherwise only a rotation about up (yaw); needs ≥ 2 points with horizontal separation.  Else
    6-DoF Kabsch/Umeyama; needs ≥ 3 non-collinear points.  Raise ValueError when under-determined.
    """
    src, dst = _pairs(local_xyz, global_xyz)
    w = _weights(weights, len(src))
    T, determined = _align(src[None], dst[None], w[None], up_local, up_global)
    if not determined[0]:
        if up_local is not None and up_global is not None:
            raise ValueError("4-DoF alignment needs >= 2 positions separated horizontally")
        raise ValueError("6-DoF alignment needs >= 3 non-collinear positions")
    return T[0]


def align_positions_batch(
    local_xyz: np.ndarray,
    global_xyz: np.ndarray,
    up_local: np.ndarray | None = None,
    up_global: np.ndarray | None = None,
    weights: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """`align_positions` of S sets of m pairs at once: (S, m, 3) arrays in, (S, 4, 4) poses out,
    with a boolean (S,) saying which are determined (the others are not meaningful).

    `weights` (S, m), non-negative, each row with a positive sum: sets of different sizes are
    aligned together by padding them and giving the padding weight 0."""
    src, dst = np.asarray(local_xyz, dtype=float), np.asarray(global_xyz, dtype=float)
    if src.ndim != 3 or src.shape[2] != 3 or src.shape != dst.shape:
        raise ValueError(f"expected two (S, m, 3) arrays, got {src.shape} and {dst.shape}")
    if not (np.all(np.isfinite(src)) and np.all(np.isfinite(dst))):
        raise ValueError("positions have non-finite values")
    if weights is None:
        w = np.ones(src.shape[:2])
    else:
        w = np.asarray(weights, dtype=float)
        if w.shape != src.shape[:2] or not np.all(np.isfinite(w)) or np.any(w < 0):
            raise ValueError(f"weights must be {src.shape[:2]} finite non-negative numbers")
        if np.any(w.sum(axis=1) <= 0):
            raise ValueError("every set needs a positive weight")
    return _align(src, dst, w, up_local, up_global)


def _align(src, dst, w, up_local, up_global) -> tuple[np.ndarray, np.ndarray]:
    """Batched closed form over (S, m, 3) pairs: poses (S, 4, 4) and which are determined."""
    T, spread = _fit(src, dst, w, up_local, up_global)
    return T, spread > DEGENERATE


def _fit(src, dst, w, up_local, up_global) -> tuple[np.ndarray, np.ndarray]:
    """`closed_form.fit_many` in the given frames (4-DoF through the z-up frames when both
    `up`s are given): poses (S, 4, 4) and the spread of each set's positions."""
    yaw_only = up_local is not None and up_global is not None
    if yaw_only:
        A_l, A_g = z_up_rotations(up_local, up_global)
        src, dst = src @ A_l.T, dst @ A_g.T
    T, spread = closed_form.fit_many(
        np.ascontiguousarray(src, float), np.ascontiguousarray(dst, float),
        np.ascontiguousarray(w, float), yaw_only,
    )  # fmt: skip
    return (from_z_up(T, A_l, A_g) if yaw_only else T), spread


def from_z_up(T: np.ndarray, A_l: np.ndarray, A_g: np.ndarray) -> np.ndarray:
    """Poses (S, 4, 4) between the z-up frames of `z_up_rotations` as poses between the
    original frames (in place)."""
    T[:, :3, :3] = A_g.T @ T[:, :3, :3] @ A_l
    T[:, :3, 3] = T[:, :3, 3] @ A_g
    return T


# --------------------------------------------------------------------------- object clouds


@dataclass(frozen=True, eq=False)
class ObjectCloud:
    """One object's points prepared for pose recovery: downsampled to at most `icp_max_points`
    voxel means, with unoriented unit normals, how flat each neighbourhood is (the weight of
    the point-to-plane error there) and a KD-tree.  The arrays are in the
    tree's order (`tree.points` is `points`, not a copy); `input_rows[i]` is the row of the
    i-th downsampled point, so that a thinned view keeps the points' spatial spread."""

    points: np.ndarray
    normals: np.ndarray
    flatness: np.ndarray  # (n,) in [0, 1]: 1 where the neighbourhood is a plane, 0 if not flat
    tree: KdTree
    input_rows: np.ndarray  # (n,) int32

    def nearest(self, query: np.ndarray, k: int, bound: float) -> tuple[np.ndarray, np.ndarray]:
        """Rows of `points` (n, k) and distances (n, k), ascending, of the k nearest cloud points
        of each query closer than `bound`; row -1 and distance inf where there are fewer."""
        query = np.asarray(query, dtype=float).reshape(-1, 3)
        return Forest.of([self.tree]).nearest(query, np.zeros(len(query), np.int64), k, bound)


def prepare_cloud(points: object, config: PoseConfig | None = None) -> ObjectCloud | None:
    """`points` (N, 3) as pose recovery uses them: voxel means (`icp_voxel`), a seeded
    subsample of at most `icp_max_points`, normals and a KD-tree; None when there are none."""
    cfg = config or PoseConfig()
    points = np.asarray(points, dtype=float)
    if points.size == 0:
        return None
    points = voxel_downsample(_xyz(points, "points"), cfg.icp_voxel)
    if len(points) > cfg.icp_max_points:
        keep = np.random.default_rng(cfg.seed).choice(len(points), cfg.icp_max_points, False)
        points = points[np.sort(keep)]
    tree = KdTree.build(points)
    normals, variation = neighbourhood_shapes(tree, _NORMAL_NEIGHBOURS)
    flatness = np.clip(1.0 - variation / _FLAT_VARIATION, 0.0, 1.0)
    input_rows = np.empty(len(tree), dtype=np.int32)
    input_rows[tree.order] = np.arange(len(tree), dtype=np.int32)
    return ObjectCloud(tree.points, normals, flatness, tree, input_rows)


_CLOUDS: weakref.WeakKeyDictionary[Any, dict[tuple, ObjectCloud | None]] = (
    weakref.WeakKeyDictionary()
)


def cached_cloud(owner: Any, config: PoseConfig | None = None) -> ObjectCloud | None:
    """`prepare_cloud(owner.points, config)`, computed once per owner and preparation settings
    while the owner lives.  The owner is an immutable object with `.points` (a
    `SemanticObject`: a re-detection is a new object), so a map's objects are prepared once
    per map, whichever Localizer asks, and a local object once per version."""
    cfg = config or PoseConfig()
    key = (cfg.icp_voxel, cfg.icp_max_points, cfg.seed)
    clouds = _CLOUDS.setdefault(owner, {})
    if key not in clouds:
        points = owner.points
        clouds[key] = None if points is None else prepare_cloud(points, cfg)
    return clouds[key]


def _cloud_pairs(
    local_points: Sequence[object] | None,
    global_points: Sequence[object] | None,
    n: int,
    cfg: PoseConfig,
) -> list[tuple[ObjectCloud, ObjectCloud]]:
    """The prepared (local, global) clouds of the pairs that have points on both sides."""
    if local_points is None or global_points is None:
        return []
    if len(local_points) != n or len(global_points) != n:
        raise ValueError(f"point sequences must have one entry per matched pair ({n})")
    pairs = []
    for i, (p, q) in enumerate(zip(local_points, global_points, strict=True)):
        p = _prepared(p, f"local points of pair {i}", cfg)
        q = _prepared(q, f"global points of pair {i}", cfg)
        if p is not None and q is not None:
            pairs.append((p, q))
    return pairs


def _prepared(points: object, name: str, cfg: PoseConfig) -> ObjectCloud | None:
    if points is None or isinstance(points, ObjectCloud):
        return points
    points = np.asarray(points, dtype=float)
    return None if points.size == 0 else prepare_cloud(_xyz(points, name), cfg)


class _Pairs:
    """The matched clouds of one problem: the local points concatenated (with normals and the
    partner tree of each row) and the partners (`targets`: their KD-trees as one forest, whose
    points are theirs, and their normals and flatness concatenated); `limit` thins the local
    points evenly."""

    def __init__(self, pairs: list[tuple[ObjectCloud, ObjectCloud]], limit: int | None = None):
        self.pairs = pairs
        globals_ = [g for _, g in pairs]
        self.targets = registration.Targets(  # shared by thinned views
            Forest.of([g.tree for g in globals_]),
            np.concatenate([g.normals for g in globals_]),
            np.concatenate([g.flatness for g in globals_]),
        )
        # the local clouds concatenated, in their trees' order (shared by thinned views)
        self._sizes = np.array([len(p.points) for p, _ in pairs], dtype=np.int64)
        self._points = np.concatenate([p.points for p, _ in pairs])
        self._normals = np.concatenate([p.normals for p, _ in pairs])
        self._input_rows = np.concatenate([p.input_rows for p, _ in pairs])
        self._select(limit)

    def thinned(self, limit: int) -> _Pairs:
        """The same pairs with the local points thinned to at most `limit` (targets shared)."""
        view = copy.copy(self)
        view._select(limit)
        return view

    def _select(self, limit: int | None) -> None:
        rows, owner = registration.thinned_rows(self._sizes, self._input_rows, limit or 0)
        self.src = self._points[rows]
        self.src_normals = self._normals[rows]
        self.tree_of_row = owner

    @property
    def view(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(points, normals, tree_of_row) of the local points, as `registration.icp` takes."""
        return self.src, self.src_normals, self.tree_of_row


def _point_fitness(T: np.ndarray, pairs: _Pairs, radius: float) -> tuple[float, float, float]:
    """Inlier share, inlier RMS distance and the smooth score (mean of 1 - (d/r)^2, truncated)
    of the local points moved by T against their partners' points."""
    return registration.fitness(T, pairs.src, pairs.tree_of_row, pairs.targets.forest, radius)


def _centre_fitness(T, src, dst) -> tuple[float, float]:
    d = np.linalg.norm(_apply(T, src) - dst, axis=1)
    inliers = d[d < _CENTRE_INLIER]
    rmse = float(np.sqrt(np.mean(inliers**2))) if len(inliers) else 0.0
    return len(inliers) / len(src), rmse


def _apply(T: np.ndarray, points: np.ndarray) -> np.ndarray:
    return points @ T[:3, :3].T + T[:3, 3]


# --------------------------------------------------------------------------- robust ICP


def _icp(T: np.ndarray, full: _Pairs, coarse: _Pairs, axis, cfg: PoseConfig) -> np.ndarray:
    """Robust ICP from T (`registration.icp`): Tukey-weighted Gauss-Newton on
    normal-compatible correspondences, the kernel annealed from `icp_kernel_start` to
    `icp_kernel`; coarse levels move the lighter `coarse` view of the local points."""
    cos_max = np.cos(np.radians(cfg.icp_normal_angle)) if cfg.icp_normal_angle < 90 else 0.0
    settings = registration.IcpSettings(
        cfg.icp_iterations, cfg.icp_kernel_start, cfg.icp_kernel, float(cos_max),
        *_MATCH_NEIGHBOURS, _CONVERGED, _POINT_TO_POINT,
    )  # fmt: skip
    return registration.icp(T, full.view, coarse.view, full.targets, axis, settings)


# --------------------------------------------------------------------------- global search


def _score(rotations: np.ndarray, pivots, sample: _Pairs, radius: float) -> np.ndarray:
    """Smooth fitness (mean of 1 - (d/r)^2, truncated) of rotations about the matched pivots."""
    return registration.rotation_scores(
        rotations, pivots, sample.src, sample.tree_of_row, sample.targets.forest, radius
    )


def _sweep(axis_rot: Callable[[np.ndarray], np.ndarray], pivots, sample, cfg) -> list:
    """1-D search over the angle about an axis: coarse grid, best local maxima, fine grid."""
    step = 2 * np.pi / cfg.search_steps
    angles = np.arange(cfg.search_steps) * step
    s = _score(axis_rot(angles), pivots, sample, cfg.fitness_radius)
    peaks = np.flatnonzero((s >= np.roll(s, 1)) & (s >= np.roll(s, -1)) & (s > 0))
    if len(peaks) == 0:
        peaks = np.array([int(np.argmax(s))])
    peaks = peaks[s[peaks] >= _CANDIDATE_SHARE * s.max()]
    peaks = peaks[np.argsort(-s[peaks])][:_SEARCH_CANDIDATES]
    fine = np.linspace(-step, step, 21)
    best = []
    for a in angles[peaks]:
        sf = _score(axis_rot(a + fine), pivots, sample, cfg.fitness_radius)
        best.append(axis_rot(np.array([a + fine[np.argmax(sf)]]))[0])
    return best


def _fibonacci_rotations(n_dirs: int, n_yaw: int) -> np.ndarray:
    i = np.arange(n_dirs) + 0.5
    z = 1 - 2 * i / n_dirs
    phi = i * np.pi * (3 - np.sqrt(5))
    r = np.sqrt(1 - z**2)
    dirs = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
    yaws = _rot_z(np.arange(n_yaw) * 2 * np.pi / n_yaw)
    tilts = np.stack([_rot_to_z(u).T for u in dirs])
    return np.einsum("aij,bjk->abik", tilts, yaws).reshape(-1, 3, 3)


def _so3_search(pivots, sample, cfg) -> list:
    """Coarse SO(3) grid; the best rotations at least 30 deg apart."""
    rotations = _fibonacci_rotations(_SO3_DIRECTIONS, max(12, cfg.search_steps // 4))
    s = _score(rotations, pivots, sample, cfg.fitness_radius)
    chosen: list[np.ndarray] = []
    for k in np.argsort(-s):
        if s[k] < _CANDIDATE_SHARE * s.max():
            break
        far = all(np.trace(R.T @ rotations[k]) < 1 + 2 * np.cos(np.radians(30)) for R in chosen)
        if far:
            chosen.append(rotations[k])
        if len(chosen) == _SEARCH_CANDIDATES:
            break
    return chosen


def _axis_rotations(axis_l: np.ndarray, axis_g: np.ndarray) -> Callable:
    """Rotations R(theta) with R @ axis_l == axis_g, parametrised by the angle about axis_g."""
    B_l, B_g = _rot_to_z(axis_l), _rot_to_z(axis_g)
    return lambda angles: B_g.T @ _rot_z(angles) @ B_l


def _search(src_c, dst_c, pairs: list, ups, cfg: PoseConfig) -> list[np.ndarray]:
    """Candidate transforms when the centres leave rotational freedom."""
    pivots = (src_c.mean(axis=0), dst_c.mean(axis=0))
    sample = _Pairs(pairs, min(_SEARCH_POINTS, cfg.local_points))
    if ups is not None:
        rotations = _sweep(_axis_rotations(*ups), pivots, sample, cfg)
    else:
        _, s, Vt = np.linalg.svd(src_c - pivots[0])
        axis_g = ((src_c - pivots[0]) @ Vt[0]) @ (dst_c - pivots[1])  # matching global direction
        if s[0] <= cfg.min_spread or np.linalg.norm(axis_g) <= cfg.min_spread * s[0]:
            rotations = _so3_search(
                pivots, _Pairs(pairs, min(_SEARCH_POINTS, cfg.local_points) // 2), cfg
            )
        else:
            axis_g /= np.linalg.norm(axis_g)
            rotations = _sweep(_axis_rotations(Vt[0], axis_g), pivots, sample, cfg)
    return [_transform(R, pivots[1] - R @ pivots[0]) for R in rotations]


# --------------------------------------------------------------------------- estimate_pose


def estimate_pose(
    local_positions: np.ndarray,
    global_positions: np.ndarray,
    local_points: Sequence[np.ndarray | ObjectCloud | None] | None,
    global_points: Sequence[np.ndarray | ObjectCloud | None] | None,
    up_local: np.ndarray | None = None,
    up_global: np.ndarray | None = None,
    config: PoseConfig | None = None,
    init: np.ndarray | None = None,
) -> PoseEstimate | None:
    """Pose of the local frame in the global frame from matched objects.

    local_positions/global_positions: (N,3) matched object centres (row i of each is a pair).
    local_points/global_points: sequences of length N of (M_i,3) arrays, `ObjectCloud`s
    (from `prepare_cloud` with the same config) or None (empty arrays count as None).  Point
    sets are used only for pairs with points on both sides.  4-DoF (gravity-aligned) when both
    `up_local` and `up_global` are given, else 6-DoF.  `init`: a pose to warm-start from (e.g.
    the pose of a subset of these pairs); it replaces the closed form or search when it has
    the higher fitness (4-DoF: it must map up_local onto up_global).

    1) closed form when determined (see `align_positions`); 2) when the centres are too few or
    spread less than `min_spread` (horizontally in 4-DoF, off a line in 6-DoF) and points exist,
    a global search over the free rotation about the matched centres scored by point-set fitness;
    3) robust ICP (4-DoF-constrained in 4-DoF mode) when `refine` and points exist, kept only if
    it does not lower fitness.  Returns None when under-determined and no points exist.
    """
    recovery = recover_pose(
        local_positions, global_positions, local_points, global_points, up_local, up_global,
        config, init,
    )  # fmt: skip
    return None if recovery is None else recovery.estimate(refine=(config or PoseConfig()).refine)


class PoseRecovery:
    """A pose recovery stopped before robust ICP: the scored candidates (closed form, search
    or warm start) of one problem.  `estimate(refine=False)` is the best of them as they are,
    `estimate(refine=True)` the best after ICP from each (computed once), as `estimate_pose`
    returns them: a caller that may not need the refinement asks for it later, without
    repeating the closed form, the rotation search or the scoring."""

    def __init__(self, scored: list[_Scored], full: _Pairs | None, ups, cfg: PoseConfig) -> None:
        self._scored, self._full, self._ups, self._cfg = scored, full, ups, cfg
        self._refined: PoseEstimate | None = None

    @property
    def refinable(self) -> bool:
        """Whether ICP would run (points on both sides and iterations allowed)."""
        return self._full is not None and self._cfg.icp_iterations > 0

    def estimate(self, refine: bool = False) -> PoseEstimate:
        if not (refine and self.refinable):
            return self._best(self._scored)
        if self._refined is None:
            assert self._full is not None
            coarse = self._full.thinned(min(_COARSE_POINTS, self._cfg.local_points))
            axis = None if self._ups is None else self._ups[1]
            self._refined = self._best(
                [_refined(s, self._full, coarse, axis, self._cfg) for s in self._scored]
            )
        return self._refined

    def _best(self, scored: list[_Scored]) -> PoseEstimate:
        best = max(scored, key=lambda s: (s.fitness, -s.rmse))
        T = best.T if self._ups is None or self._full is None else _upright(best.T, *self._ups)
        return PoseEstimate(T, best.fitness, best.rmse, best.method)


def recover_pose(
    local_positions: np.ndarray,
    global_positions: np.ndarray,
    local_points: Sequence[np.ndarray | ObjectCloud | None] | None,
    global_points: Sequence[np.ndarray | ObjectCloud | None] | None,
    up_local: np.ndarray | None = None,
    up_global: np.ndarray | None = None,
    config: PoseConfig | None = None,
    init: np.ndarray | None = None,
) -> PoseRecovery | None:
    """`estimate_pose` up to robust ICP (same arguments): the scored candidates, refined when
    asked (`PoseRecovery.estimate`); None when under-determined and no points exist."""
    cfg = config or PoseConfig()
    src_c, dst_c = _pairs(local_positions, global_positions)
    pairs = _cloud_pairs(local_points, global_points, len(src_c), cfg)
    ups = None
    if up_local is not None and up_global is not None:
        ups = (_unit(up_local, "up_local"), _unit(up_global, "up_global"))
    tag = "4dof" if ups else "6dof"
    closed = _closed_form(src_c, dst_c, ups, cfg.min_spread if pairs else DEGENERATE)
    if closed is not None:
        candidates, method = [closed], f"closed-form-{tag}"
    elif not pairs:
        if init is None:
            return None
        return PoseRecovery([_centre_scored(init, src_c, dst_c, f"warm-{tag}")], None, ups, cfg)
    else:
        candidates, method = _search(src_c, dst_c, pairs, ups, cfg), f"search-{tag}"
    if not pairs:
        return PoseRecovery([_centre_scored(candidates[0], src_c, dst_c, method)], None, ups, cfg)
    full = _Pairs(pairs, cfg.local_points)
    scored = [_scored(T, method, full, cfg) for T in candidates]
    if init is not None:
        warm = _scored(init, f"warm-{tag}", full, cfg)
        if warm.score > max(s.score for s in scored):
            scored = [warm]
    return PoseRecovery(scored, full, ups, cfg)


def _closed_form(src, dst, ups, tol: float) -> np.ndarray | None:
    """The centres' closed-form pose, if they fix it: enough of them, spread more than `tol`."""
    if len(src) < (2 if ups is not None else 3):
        return None
    T, spread = _fit(src[None], dst[None], np.ones((1, len(src))), *(ups or (None, None)))
    return T[0] if spread[0] > tol else None


def _centre_scored(T, src_c, dst_c, method: str) -> _Scored:
    """A pose scored by its centres alone (no points: nothing to refine)."""
    return _Scored(*_centre_fitness(T, src_c, dst_c), 0.0, T, method)


class _Scored(NamedTuple):
    """A candidate pose with its fit: inlier share, inlier RMS and the smooth score."""

    fitness: float
    rmse: float
    score: float
    T: np.ndarray
    method: str


def _scored(T: np.ndarray, method: str, pairs: _Pairs, cfg: PoseConfig) -> _Scored:
    return _Scored(*_point_fitness(T, pairs, cfg.fitness_radius), T, method)


def _refined(start: _Scored, full: _Pairs, coarse: _Pairs, axis, cfg: PoseConfig) -> _Scored:
    """ICP from a candidate, kept when it does not lower the fitness."""
    refined = _scored(_icp(start.T, full, coarse, axis, cfg), start.method + "+icp", full, cfg)
    return refined if refined.fitness >= start.fitness else start


def _upright(T: np.ndarray, up_l: np.ndarray, up_g: np.ndarray) -> np.ndarray:
    """T with its rotation snapped to the nearest one mapping up_l exactly onto up_g (a yaw
    in the z-up canonical frames); removes the rounding drift of repeated updates."""
    A_l, A_g = _rot_to_z(up_l), _rot_to_z(up_g)
    Rc = A_g @ T[:3, :3] @ A_l.T
    yaw = np.arctan2(Rc[1, 0] - Rc[0, 1], Rc[0, 0] + Rc[1, 1])
    return _transform(A_g.T @ _rot_z(yaw) @ A_l, T[:3, 3])
