"""Pose recovery: the rigid transform of the local frame in the global frame from matched objects.

This module owns the last stage of the pipeline (paper, "Camera pose recovery"):

1. **Closed form** (`align_positions`): weighted least-squares alignment of matched object
   centres, 6-DoF (Kabsch/Umeyama without scale) or 4-DoF (yaw about gravity-up + translation)
   when both frames know their `up` direction.
2. **Global search** when the centres alone do not determine the pose (1 pair, 2 pairs on the
   up axis in 4-DoF, 1-2 pairs or collinear centres in 6-DoF; with points, also centres spread
   less than `min_spread`, whose closed-form rotation would be noise): the free rotation is sampled
   (a 1-D sweep about the axis through the matched centres, or a coarse grid over SO(3) for a
   single 6-DoF pair) and scored by point-set fitness; the best few candidates are refined.
   This is the low-dimensional stand-in for the paper's Go-ICP.
3. **Robust ICP** on the concatenated per-object point sets (local object points vs. the points
   of their matched global objects): one numpy IRLS implementation for both modes
   (scipy cKDTree nearest neighbours, Tukey biweight with a kernel annealed from
   `icp_kernel_start` to `icp_kernel`, correspondences restricted to compatible normals,
   weighted Kabsch in 6-DoF, weighted yaw + translation in 4-DoF; Open3D is not used).  A
   refinement is kept only if it does not lower fitness.

4-DoF problems are solved in "canonical" frames: each side is rotated so that its `up` is +z,
yaw + translation are solved there, and the result is rotated back, so `R @ up_local ==
up_global` holds exactly.  Everything is pure computation on numpy arrays (no I/O, no plotting).
Convention: `T_global_local`, i.e. `p_global = R @ p_local + t`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from pydantic import BaseModel, ConfigDict, Field
from scipy.spatial import cKDTree

from semloc.pointsets import voxel_downsample

__all__ = [
    "PoseConfig",
    "PoseEstimate",
    "align_positions",
    "align_positions_batch",
    "estimate_pose",
]

_TOL = 1e-9  # spread (m) below which positions are mathematically degenerate
_CENTRE_INLIER = 0.5  # m: centre-based fitness threshold (no points)
_SEARCH_POINTS = 512  # local points used to score search candidates
_SEARCH_CANDIDATES = 3  # best local maxima refined after the coarse search
_CANDIDATE_SHARE = 0.5  # ... if their score is at least this share of the best score
_SO3_DIRECTIONS = 48  # Fibonacci directions of the 1-pair 6-DoF search (x yaw steps)
_NORMAL_NEIGHBOURS = 8  # neighbours for normal estimation
_COARSE_POINTS = 1000  # local points used by ICP while the kernel is above icp_kernel
_SIGN_DIRECTION = np.array([1.0, 2.0, 3.0]) / np.sqrt(14.0)  # half-space for signed normals

Solver = Callable[[np.ndarray, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]


class PoseConfig(BaseModel):
    """Settings of pose recovery (closed form, global search, robust ICP)."""

    model_config = ConfigDict(extra="forbid")

    refine: bool = Field(True, description="Run robust ICP when both sides have object points.")
    icp_iterations: int = Field(30, ge=0, description="Maximum number of ICP (IRLS) iterations.")
    icp_voxel: float = Field(
        0.05, ge=0, description="Voxel size (m) for downsampling before ICP / fitness; 0 = off."
    )
    icp_max_points: int = Field(
        4000, ge=3, description="Points per side after downsampling (seeded random subsample)."
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
    seed: int = Field(0, description="Seed of the random point subsampling.")


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
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ValueError(f"{name} must be 3 finite numbers, got {v!r}")
    norm = np.linalg.norm(v)
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
    """Smallest rotation taking the unit vector `up` onto +z (Rodrigues, axis up x z)."""
    x, y, c = float(up[0]), float(up[1]), float(up[2])
    if c < -1 + 1e-12:
        return np.diag([1.0, -1.0, -1.0])
    k = 1.0 / (1.0 + c)
    return np.array(
        [
            [1 - k * x * x, -k * x * y, -x],
            [-k * x * y, 1 - k * y * y, -y],
            [x, y, 1 - k * (x * x + y * y)],
        ]
    )


def _rot_z(theta: np.ndarray | float) -> np.ndarray:
    """Rotation(s) about +z; shape (3,3) for a scalar angle or (K,3,3)."""
    if np.ndim(theta) == 0:
        c, s = np.cos(theta), np.sin(theta)
        return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    c, s = np.cos(theta), np.sin(theta)
    R = np.zeros((len(c), 3, 3))
    R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1], R[:, 2, 2] = c, -s, s, c, 1.0
    return R


# The closed-form solvers broadcast over leading axes: (..., m, 3) points with (..., m) weights,
# so that many small association sets are aligned in one call (see `align_positions_batch`).


def _mean(w: np.ndarray, xyz: np.ndarray) -> np.ndarray:
    return (w[..., None, :] @ xyz)[..., 0, :]


def _centroids(src, dst, w):
    w = w / w.sum(axis=-1, keepdims=True)
    return _mean(w, src), _mean(w, dst), w


def _kabsch(src: np.ndarray, dst: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    cs, cd, w = _centroids(src, dst, w)
    H = np.swapaxes(src - cs[..., None, :], -1, -2) @ ((dst - cd[..., None, :]) * w[..., None])
    U, _, Vt = np.linalg.svd(H)
    V, Ut = np.swapaxes(Vt, -1, -2), np.swapaxes(U, -1, -2)
    sign = np.sign(np.linalg.det(V @ Ut))
    V = V.copy()
    V[..., :, 2] *= np.where(sign == 0, 1.0, sign)[..., None]  # V @ diag(1, 1, sign)
    R = V @ Ut
    return R, cd - (R @ cs[..., None])[..., 0]


def _yaw(src: np.ndarray, dst: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weighted yaw about +z and translation (frames already z-up)."""
    cs, cd, w = _centroids(src, dst, w)
    a, b = src[..., :2] - cs[..., None, :2], dst[..., :2] - cd[..., None, :2]
    sin = np.sum(w * (a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]), axis=-1)
    cos = np.sum(w * (a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1]), axis=-1)
    R = _rot_z(np.arctan2(sin, cos))
    return R, cd - (R @ cs[..., None])[..., 0]


def _spread(xyz: np.ndarray, w: np.ndarray, horizontal: bool) -> np.ndarray:
    """Horizontal RMS spread (z-up frame) or RMS distance off the best-fit line (6-DoF)."""
    w = w / w.sum(axis=-1, keepdims=True)
    d = xyz - _mean(w, xyz)[..., None, :]
    cov = np.swapaxes(d, -1, -2) @ (d * w[..., None])
    if horizontal:
        return np.sqrt(np.maximum(cov[..., 0, 0] + cov[..., 1, 1], 0.0))
    return np.sqrt(np.maximum(np.sum(np.linalg.eigvalsh(cov)[..., :2], axis=-1), 0.0))


def _degenerate(src, dst, w, yaw_only: bool, tol: float) -> np.ndarray:
    return np.minimum(_spread(src, w, yaw_only), _spread(dst, w, yaw_only)) <= tol


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
) -> tuple[np.ndarray, np.ndarray]:
    """`align_positions` of S sets of m pairs at once: (S, m, 3) arrays in, (S, 4, 4) poses out,
    with a boolean (S,) saying which are determined (the others are not meaningful)."""
    src, dst = np.asarray(local_xyz, dtype=float), np.asarray(global_xyz, dtype=float)
    if src.ndim != 3 or src.shape[2] != 3 or src.shape != dst.shape:
        raise ValueError(f"expected two (S, m, 3) arrays, got {src.shape} and {dst.shape}")
    if not (np.all(np.isfinite(src)) and np.all(np.isfinite(dst))):
        raise ValueError("positions have non-finite values")
    return _align(src, dst, np.ones(src.shape[:2]), up_local, up_global)


def _align(src, dst, w, up_local, up_global) -> tuple[np.ndarray, np.ndarray]:
    """Batched closed form over (S, m, 3) pairs: poses (S, 4, 4) and which are determined."""
    T = np.tile(np.eye(4), (len(src), 1, 1))
    if up_local is not None and up_global is not None:
        A_l, A_g = _rot_to_z(_unit(up_local, "up_local")), _rot_to_z(_unit(up_global, "up_global"))
        src, dst = src @ A_l.T, dst @ A_g.T
        R, t = _yaw(src, dst, w)
        T[:, :3, :3], T[:, :3, 3] = A_g.T @ R @ A_l, t @ A_g
        return T, ~_degenerate(src, dst, w, True, _TOL)
    T[:, :3, :3], T[:, :3, 3] = _kabsch(src, dst, w)
    return T, ~_degenerate(src, dst, w, False, _TOL)


# --------------------------------------------------------------------------- point sets


def _downsample(points: np.ndarray, voxel: float, max_points: int, rng) -> np.ndarray:
    """Voxel-grid means, then a seeded random subsample of at most `max_points`."""
    points = voxel_downsample(points, voxel)
    if len(points) > max_points:
        points = points[np.sort(rng.choice(len(points), max_points, replace=False))]
    return points


def _clouds(
    local_points: Sequence[np.ndarray | None] | None,
    global_points: Sequence[np.ndarray | None] | None,
    n: int,
    cfg: PoseConfig,
) -> tuple[np.ndarray, np.ndarray] | None:
    """Concatenated, downsampled point sets of the pairs that have points on both sides."""
    if local_points is None or global_points is None:
        return None
    if len(local_points) != n or len(global_points) != n:
        raise ValueError(f"point sequences must have one entry per matched pair ({n})")
    src, dst = [], []
    for i, (p, q) in enumerate(zip(local_points, global_points, strict=True)):
        if p is None or q is None:
            continue
        p, q = np.asarray(p, dtype=float), np.asarray(q, dtype=float)
        if p.size == 0 or q.size == 0:
            continue
        src.append(_xyz(p, f"local points of pair {i}"))
        dst.append(_xyz(q, f"global points of pair {i}"))
    if not src:
        return None
    rng = np.random.default_rng(cfg.seed)
    args = (cfg.icp_voxel, cfg.icp_max_points, rng)
    return _downsample(np.concatenate(src), *args), _downsample(np.concatenate(dst), *args)


def _apply(T: np.ndarray, points: np.ndarray) -> np.ndarray:
    return points @ T[:3, :3].T + T[:3, 3]


def _point_fitness(T, src, tree: cKDTree, radius: float) -> tuple[float, float]:
    d, _ = tree.query(_apply(T, src), distance_upper_bound=radius)
    inliers = d[np.isfinite(d)]
    rmse = float(np.sqrt(np.mean(inliers**2))) if len(inliers) else 0.0
    return len(inliers) / len(src), rmse


def _centre_fitness(T, src, dst) -> tuple[float, float]:
    d = np.linalg.norm(_apply(T, src) - dst, axis=1)
    inliers = d[d < _CENTRE_INLIER]
    rmse = float(np.sqrt(np.mean(inliers**2))) if len(inliers) else 0.0
    return len(inliers) / len(src), rmse


# --------------------------------------------------------------------------- robust ICP


def _normals(points: np.ndarray, tree: cKDTree | None = None) -> np.ndarray:
    """Unoriented unit normals: smallest-eigenvalue direction of the k-neighbour covariance."""
    k = min(_NORMAL_NEIGHBOURS, len(points))
    _, idx = (tree or cKDTree(points)).query(points, k=k)
    nb = points[idx.reshape(len(points), k)]
    nb = nb - nb.mean(axis=1, keepdims=True)
    return _smallest_eigenvectors(np.swapaxes(nb, 1, 2) @ nb)


def _smallest_eigenvectors(C: np.ndarray) -> np.ndarray:
    """Unit eigenvectors of the smallest eigenvalues of symmetric (N,3,3) matrices.

    Closed form (trigonometric eigenvalues, then the widest cross product of two rows of
    C - lambda I); several times faster than a batched `eigh`.  Isotropic or line-like
    neighbourhoods get an arbitrary unit vector.
    """
    q = np.trace(C, axis1=1, axis2=2) / 3
    off = C[:, 0, 1] ** 2 + C[:, 0, 2] ** 2 + C[:, 1, 2] ** 2
    diag = (C[:, 0, 0] - q) ** 2 + (C[:, 1, 1] - q) ** 2 + (C[:, 2, 2] - q) ** 2
    p = np.sqrt((diag + 2 * off) / 6)
    B = (C - q[:, None, None] * np.eye(3)) / np.where(p > 0, p, 1.0)[:, None, None]
    phi = np.arccos(np.clip(np.linalg.det(B) / 2, -1, 1)) / 3
    smallest = q + 2 * p * np.cos(phi + 2 * np.pi / 3)
    M = C - smallest[:, None, None] * np.eye(3)
    crosses = np.stack(
        [np.cross(M[:, 0], M[:, 1]), np.cross(M[:, 0], M[:, 2]), np.cross(M[:, 1], M[:, 2])], 1
    )
    norms = np.linalg.norm(crosses, axis=2)
    best = np.argmax(norms, axis=1)
    rows = np.arange(len(C))
    n, size = crosses[rows, best], norms[rows, best]
    ok = size > 1e-12 * np.maximum(q, 1e-300) ** 2
    return np.where(ok[:, None], n / np.where(ok, size, 1.0)[:, None], [0.0, 0.0, 1.0])


def _signed(normals: np.ndarray) -> np.ndarray:
    """Flip unoriented normals into one half-space so that similar normals get similar vectors."""
    return normals * np.where(normals @ _SIGN_DIRECTION < 0, -1.0, 1.0)[:, None]


class _Matcher:
    """Nearest global point within the kernel, with a compatible normal when normals are used.

    With normals, the search runs in 6-D on (point, kernel * signed normal), so that a point on
    another face is not preferred just for being a little closer; the 3-D distance and the
    normal angle are then checked.
    """

    def __init__(self, dst: np.ndarray, tree: cKDTree, src: np.ndarray, cfg: PoseConfig):
        self.dst, self.tree, self.trees6 = dst, tree, {}
        self.use_normals = cfg.icp_normal_angle < 90 and min(len(src), len(dst)) >= 3
        self.cos_max = np.cos(np.radians(cfg.icp_normal_angle))
        if self.use_normals:
            self.src_n, self.dst_n = _normals(src), _signed(_normals(dst, tree))

    def __call__(self, moved: np.ndarray, rows, R: np.ndarray, kernel: float):
        if not self.use_normals:
            d, idx = self.tree.query(moved, distance_upper_bound=kernel)
            ok = np.isfinite(d)
            return d[ok], idx[ok], ok
        if kernel not in self.trees6:  # the 6-D tree depends on the kernel
            self.trees6[kernel] = cKDTree(np.hstack([self.dst, kernel * self.dst_n]))
        normals = _signed(self.src_n[rows] @ R.T)
        bound = kernel * np.sqrt(1 + 2 * (1 - self.cos_max))  # 3-D and normal chord both in range
        query = np.hstack([moved, kernel * normals])
        _, idx = self.trees6[kernel].query(query, distance_upper_bound=bound)
        found = idx < len(self.dst)
        idx = np.where(found, idx, 0)
        d = np.linalg.norm(self.dst[idx] - moved, axis=1)
        cos = np.abs(np.einsum("ni,ni->n", normals, self.dst_n[idx]))
        ok = found & (d < kernel) & (cos >= self.cos_max)
        return d[ok], idx[ok], ok


def _icp(T: np.ndarray, src, dst, match: _Matcher, cfg: PoseConfig, solve: Solver) -> np.ndarray:
    """IRLS point-to-point ICP with Tukey weights (correspondences beyond the kernel ignored).

    Correspondences must have compatible (unoriented) normals, within `icp_normal_angle`: this
    keeps a partial view from settling inside the full object.  Graduated: the kernel starts at
    `icp_kernel_start` and halves whenever an iteration moves the points by less than 1 % of it
    on average, so offsets beyond `icp_kernel` (centres biased by partial views) are still
    pulled in; stops once that happens at `icp_kernel`.  Coarse levels use a subsample of
    about `_COARSE_POINTS` local points.
    """
    kernel = max(cfg.icp_kernel_start, cfg.icp_kernel)
    coarse = np.arange(0, len(src), max(1, len(src) // _COARSE_POINTS))
    for _ in range(cfg.icp_iterations):
        rows = coarse if kernel > cfg.icp_kernel else slice(None)
        moved = _apply(T, src[rows])
        d, idx, ok = match(moved, rows, T[:3, :3], kernel)
        if len(d) < 3:
            break
        w = (1.0 - (d / kernel) ** 2) ** 2
        p, q = moved[ok], dst[idx]
        if _degenerate(p, q, w, solve is _yaw, _TOL):
            break
        R, t = solve(p, q, w)
        T = _transform(R, t) @ T
        if np.mean(np.linalg.norm(p @ (R - np.eye(3)).T + t, axis=1)) < 0.01 * kernel:
            if kernel <= cfg.icp_kernel:
                break
            kernel = max(cfg.icp_kernel, 0.5 * kernel)
    return T


# --------------------------------------------------------------------------- global search


def _scores(rotations: np.ndarray, pivot_l, pivot_g, src, tree: cKDTree, radius: float):
    """Smooth fitness (mean of 1 - (d/r)^2, truncated) of rotations about the matched pivots."""
    moved = np.einsum("kij,pj->kpi", rotations, src - pivot_l) + pivot_g
    d, _ = tree.query(moved.reshape(-1, 3), distance_upper_bound=radius)
    s = np.where(np.isfinite(d), 1.0 - (d / radius) ** 2, 0.0)
    return s.reshape(len(rotations), len(src)).mean(axis=1)


def _sweep(axis_rot: Callable[[np.ndarray], np.ndarray], pivots, src, tree, cfg) -> list:
    """1-D search over the angle about an axis: coarse grid, best local maxima, fine grid."""
    step = 2 * np.pi / cfg.search_steps
    angles = np.arange(cfg.search_steps) * step
    s = _scores(axis_rot(angles), *pivots, src, tree, cfg.fitness_radius)
    peaks = np.flatnonzero((s >= np.roll(s, 1)) & (s >= np.roll(s, -1)) & (s > 0))
    if len(peaks) == 0:
        peaks = np.array([int(np.argmax(s))])
    peaks = peaks[s[peaks] >= _CANDIDATE_SHARE * s.max()]
    peaks = peaks[np.argsort(-s[peaks])][:_SEARCH_CANDIDATES]
    fine = np.linspace(-step, step, 21)
    best = []
    for a in angles[peaks]:
        sf = _scores(axis_rot(a + fine), *pivots, src, tree, cfg.fitness_radius)
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


def _so3_search(pivots, src, tree, cfg) -> list:
    """Coarse SO(3) grid; the best rotations at least 30 deg apart."""
    rotations = _fibonacci_rotations(_SO3_DIRECTIONS, max(12, cfg.search_steps // 4))
    s = _scores(rotations, *pivots, src, tree, cfg.fitness_radius)
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


def _search(src_c, dst_c, clouds, tree, yaw_only: bool, cfg: PoseConfig) -> list[np.ndarray]:
    """Candidate transforms when the centres leave rotational freedom."""
    pivots = (src_c.mean(axis=0), dst_c.mean(axis=0))
    sample = clouds[0]
    if len(sample) > _SEARCH_POINTS:
        sample = sample[np.linspace(0, len(sample) - 1, _SEARCH_POINTS).astype(int)]
    if yaw_only:
        rotations = _sweep(_rot_z, pivots, sample, tree, cfg)
    else:
        _, s, Vt = np.linalg.svd(src_c - pivots[0])
        axis_g = ((src_c - pivots[0]) @ Vt[0]) @ (dst_c - pivots[1])  # matching global direction
        if s[0] <= cfg.min_spread or np.linalg.norm(axis_g) <= cfg.min_spread * s[0]:
            rotations = _so3_search(pivots, sample[::2], tree, cfg)
        else:
            axis_g /= np.linalg.norm(axis_g)
            rotations = _sweep(_axis_rotations(Vt[0], axis_g), pivots, sample, tree, cfg)
    return [_transform(R, pivots[1] - R @ pivots[0]) for R in rotations]


# --------------------------------------------------------------------------- estimate_pose


def estimate_pose(
    local_positions: np.ndarray,
    global_positions: np.ndarray,
    local_points: Sequence[np.ndarray | None] | None,
    global_points: Sequence[np.ndarray | None] | None,
    up_local: np.ndarray | None = None,
    up_global: np.ndarray | None = None,
    config: PoseConfig | None = None,
) -> PoseEstimate | None:
    """Pose of the local frame in the global frame from matched objects.

    local_positions/global_positions: (N,3) matched object centres (row i of each is a pair).
    local_points/global_points: sequences of length N of (M_i,3) arrays or None (per-object point
    sets; empty arrays count as None).  Point sets are used only for pairs with points on both
    sides.  4-DoF (gravity-aligned) when both `up_local` and `up_global` are given, else 6-DoF.

    1) closed form when determined (see `align_positions`); 2) when the centres are too few or
    spread less than `min_spread` (horizontally in 4-DoF, off a line in 6-DoF) and points exist,
    a global search over the free rotation about the matched centres scored by point-set fitness;
    3) robust ICP (4-DoF-constrained in 4-DoF mode) when `refine` and points exist, kept only if
    it does not lower fitness.  Returns None when under-determined and no points exist.
    """
    cfg = config or PoseConfig()
    src_c, dst_c = _pairs(local_positions, global_positions)
    clouds = _clouds(local_points, global_points, len(src_c), cfg)
    yaw_only = up_local is not None and up_global is not None
    A_l = A_g = np.eye(3)
    if yaw_only:
        A_l, A_g = _rot_to_z(_unit(up_local, "up_local")), _rot_to_z(_unit(up_global, "up_global"))
        src_c, dst_c = src_c @ A_l.T, dst_c @ A_g.T
        if clouds is not None:
            clouds = (clouds[0] @ A_l.T, clouds[1] @ A_g.T)
    tag = "4dof" if yaw_only else "6dof"
    solve: Solver = _yaw if yaw_only else _kabsch
    ones = np.ones(len(src_c))
    tol = cfg.min_spread if clouds is not None else _TOL
    tree = cKDTree(clouds[1]) if clouds is not None else None
    if len(src_c) >= (2 if yaw_only else 3) and not _degenerate(src_c, dst_c, ones, yaw_only, tol):
        candidates, method = [_transform(*solve(src_c, dst_c, ones))], f"closed-form-{tag}"
    elif clouds is None:
        return None
    else:
        candidates, method = _search(src_c, dst_c, clouds, tree, yaw_only, cfg), f"search-{tag}"
    if clouds is None:
        T, (fitness, rmse) = candidates[0], _centre_fitness(candidates[0], src_c, dst_c)
    else:
        T, fitness, rmse, method = _best_refined(candidates, method, clouds, tree, cfg, solve)
    T = _transform(A_g.T, np.zeros(3)) @ T @ _transform(A_l, np.zeros(3))
    return PoseEstimate(T, fitness, rmse, method)


def _best_refined(candidates, method, clouds, tree, cfg: PoseConfig, solve: Solver):
    """Best candidate by (fitness, -rmse), each refined by ICP when that does not lower fitness."""
    src, dst = clouds
    match = _Matcher(dst, tree, src, cfg) if cfg.refine else None
    best = None
    for T0 in candidates:
        result = (*_point_fitness(T0, src, tree, cfg.fitness_radius), T0, method)
        if cfg.refine and cfg.icp_iterations > 0:
            T1 = _icp(T0, src, dst, match, cfg, solve)
            refined = (*_point_fitness(T1, src, tree, cfg.fitness_radius), T1, method + "+icp")
            if refined[0] >= result[0]:
                result = refined
        if best is None or (result[0], -result[1]) > (best[0], -best[1]):
            best = result
    fitness, rmse, T, method = best
    return T, fitness, rmse, method
