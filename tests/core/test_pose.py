"""Pose recovery: closed form, global search, robust ICP, fitness and input validation."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from semloc.maps import SemanticObject
from semloc.pose import (
    ObjectCloud,
    PoseConfig,
    PoseEstimate,
    align_positions,
    align_positions_batch,
    cached_cloud,
    estimate_pose,
    prepare_cloud,
)
from semloc.transforms import rigid as make_T
from semloc.transforms import yaw_rotation as rot_z

Z = np.array([0.0, 0.0, 1.0])
seeds = st.integers(0, 2**32 - 1)


# --------------------------------------------------------------------------- helpers


def apply(T: np.ndarray, p: np.ndarray) -> np.ndarray:
    return p @ T[:3, :3].T + T[:3, 3]


def rot_err_deg(T: np.ndarray, T_true: np.ndarray) -> float:
    return float(np.degrees(Rotation.from_matrix(T[:3, :3].T @ T_true[:3, :3]).magnitude()))


def trans_err(T: np.ndarray, T_true: np.ndarray) -> float:
    return float(np.linalg.norm(T[:3, 3] - T_true[:3, 3]))


def random_T(rng: np.random.Generator, yaw_only: bool = False) -> np.ndarray:
    R = (
        rot_z(rng.uniform(-np.pi, np.pi))
        if yaw_only
        else Rotation.random(random_state=rng).as_matrix()
    )
    return make_T(R, rng.uniform(-5, 5, 3))


def l_shape(rng: np.random.Generator, n: int = 3000) -> np.ndarray:
    """Points on the surfaces of an asymmetric L-shaped object (1.0 x 0.6 x 0.8 m: two boxes),
    origin at a corner; surfaces, as scans, meshes and the simulator give them."""
    a = box_surface(rng, [1.0, 0.2, 0.8], n // 2) + [0.5, 0.1, 0.4]
    b = box_surface(rng, [0.2, 0.6, 0.5], n - n // 2) + [0.1, 0.3, 0.25]
    return np.vstack([a, b])


def box_surface(rng: np.random.Generator, size, n: int = 3000) -> np.ndarray:
    """Points on the surface of an axis-aligned box centred at the origin."""
    size = np.asarray(size, dtype=float)
    p = rng.uniform(-0.5, 0.5, (n, 3)) * size
    axis = rng.integers(0, 3, n)
    p[np.arange(n), axis] = np.sign(rng.uniform(-1, 1, n)) * size[axis] / 2
    return p


# --------------------------------------------------------------------------- closed form


@settings(max_examples=50)
@given(seed=seeds, n=st.integers(3, 12))
def test_align_6dof_recovers_known_transform(seed: int, n: int) -> None:
    rng = np.random.default_rng(seed)
    local = rng.uniform(-3, 3, (n, 3))
    s = np.linalg.svd(local - local.mean(0), compute_uv=False)
    assume(s[1] > 0.3)  # not near-collinear
    T_true = random_T(rng)
    T = align_positions(local, apply(T_true, local))
    assert np.allclose(T[:3, :3], T_true[:3, :3], atol=1e-6)
    assert np.allclose(T[:3, 3], T_true[:3, 3], atol=1e-6)
    assert np.allclose(T[3], [0, 0, 0, 1])


@settings(max_examples=50)
@given(seed=seeds, n=st.integers(2, 10))
def test_align_4dof_recovers_yaw_and_translation(seed: int, n: int) -> None:
    rng = np.random.default_rng(seed)
    local = rng.uniform(-3, 3, (n, 3))
    assume(np.ptp(local[:, 0]) + np.ptp(local[:, 1]) > 0.3)  # horizontal separation
    T_true = random_T(rng, yaw_only=True)
    T = align_positions(local, apply(T_true, local), up_local=Z, up_global=Z)
    assert np.allclose(T, T_true, atol=1e-6)


@settings(max_examples=50)
@given(seed=seeds, n=st.integers(2, 6), sets=st.integers(1, 6), yaw_only=st.booleans())
def test_align_batch_equals_one_by_one(seed: int, n: int, sets: int, yaw_only: bool) -> None:
    """The batched closed form gives each set's `align_positions` pose, and flags exactly the
    sets that `align_positions` rejects as under-determined."""
    rng = np.random.default_rng(seed)
    local = rng.uniform(-3, 3, (sets, n, 3))
    global_ = local + rng.normal(0, 0.2, local.shape)
    local[0, :, :2] = local[0, :1, :2]  # stacked vertically: degenerate in both modes
    up = (Z, Z) if yaw_only else (None, None)
    T, determined = align_positions_batch(local, global_, *up)
    for i in range(sets):
        try:
            expected = align_positions(local[i], global_[i], *up)
        except ValueError:
            assert not determined[i]
            continue
        assert determined[i]
        assert np.allclose(T[i], expected, atol=1e-9)


def test_align_batch_rejects_bad_shapes() -> None:
    with pytest.raises(ValueError, match=r"\(S, m, 3\)"):
        align_positions_batch(np.zeros((2, 3)), np.zeros((2, 3)))
    with pytest.raises(ValueError, match="non-finite"):
        align_positions_batch(np.full((1, 2, 3), np.nan), np.zeros((1, 2, 3)))


@settings(max_examples=50)
@given(seed=seeds, n=st.integers(2, 10))
def test_align_4dof_with_tilted_up(seed: int, n: int) -> None:
    """up_local = R0 @ z, up_global = z: the true R is yaw @ R0^T and must be recovered."""
    rng = np.random.default_rng(seed)
    R0 = Rotation.random(random_state=rng).as_matrix()
    T_true = make_T(rot_z(rng.uniform(-np.pi, np.pi)) @ R0.T, rng.uniform(-5, 5, 3))
    local = rng.uniform(-3, 3, (n, 3))
    horizontal = (local - local.mean(0)) @ R0[:, :2]  # coordinates orthogonal to up_local
    assume(np.linalg.norm(horizontal) > 0.3)
    T = align_positions(local, apply(T_true, local), up_local=R0 @ Z, up_global=Z)
    assert np.allclose(T, T_true, atol=1e-6)


def test_align_4dof_keeps_up_exactly_under_noise() -> None:
    rng = np.random.default_rng(3)
    up_l, up_g = Rotation.random(random_state=rng).as_matrix() @ Z, np.array([0.1, -0.2, 1.0])
    local, glob = rng.uniform(-3, 3, (6, 3)), rng.uniform(-3, 3, (6, 3))  # unrelated sets
    T = align_positions(local, glob, up_local=up_l, up_global=up_g)
    assert np.allclose(T[:3, :3] @ up_l, up_g / np.linalg.norm(up_g), atol=1e-12)
    assert np.allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-12)
    assert np.linalg.det(T[:3, :3]) == pytest.approx(1.0)


@pytest.mark.parametrize("yaw_only", [False, True])
def test_align_with_5cm_noise_is_accurate(yaw_only: bool) -> None:
    rng = np.random.default_rng(4)
    local = rng.uniform([-4, -4, 0], [4, 4, 2], (10, 3))
    T_true = random_T(rng, yaw_only)
    glob = apply(T_true, local) + rng.normal(0, 0.05, local.shape)
    up = Z if yaw_only else None
    T = align_positions(local, glob, up_local=up, up_global=up)
    assert rot_err_deg(T, T_true) < 1.5
    assert trans_err(T, T_true) < 0.1


def test_align_weights_are_respected() -> None:
    rng = np.random.default_rng(5)
    local = rng.uniform(-3, 3, (6, 3))
    T_true = random_T(rng)
    glob = apply(T_true, local)
    glob[0] += [3.0, -2.0, 1.0]  # an outlier pair
    for up in (None, Z):
        T_true_mode = T_true if up is None else None
        w = np.array([0.0, 1, 1, 1, 1, 1])
        T = align_positions(local, glob, up, up, weights=w)
        if T_true_mode is not None:
            assert np.allclose(T, T_true, atol=1e-6)
        # weight 2 on a row == that row duplicated; scaling all weights changes nothing
        w2 = np.array([2.0, 1, 1, 1, 1, 1])
        dup = align_positions(np.vstack([local, local[:1]]), np.vstack([glob, glob[:1]]), up, up)
        assert np.allclose(align_positions(local, glob, up, up, weights=w2), dup, atol=1e-9)
        assert np.allclose(align_positions(local, glob, up, up, weights=5 * w2), dup, atol=1e-9)


@pytest.mark.parametrize(
    ("local", "up"),
    [
        ([[0, 0, 0], [1, 0, 0]], None),  # 6-DoF: 2 points
        ([[0, 0, 0], [1, 1, 1], [2, 2, 2]], None),  # 6-DoF: collinear
        ([[0, 0, 0], [70, 110, 30], [140, 220, 60]], None),  # collinear, building scale
        ([[1, 2, 3]], Z),  # 4-DoF: 1 point
        ([[1, 2, 0], [1, 2, 3]], Z),  # 4-DoF: stacked vertically
    ],
)
def test_align_under_determined_raises(local, up) -> None:
    local = np.asarray(local, dtype=float)
    with pytest.raises(ValueError, match="needs"):
        align_positions(local, local + 1.0, up_local=up, up_global=up)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"local_xyz": [[0, 0, np.nan], [1, 0, 0], [0, 1, 0]]},
        {"global_xyz": [[0, 0, 0], [1, 0, 0]]},  # length mismatch
        {"local_xyz": [[0, 0], [1, 0], [0, 1]]},  # wrong shape
        {"local_xyz": np.zeros((0, 3)), "global_xyz": np.zeros((0, 3))},
        {"up_local": [0, 0, 0], "up_global": Z},
        {"up_local": [0, np.inf, 1], "up_global": Z},
        {"weights": [1, -1, 1]},
        {"weights": [0, 0, 0]},
        {"weights": [1, 1]},
    ],
)
def test_align_bad_input_raises(kwargs) -> None:
    args = {"local_xyz": np.eye(3), "global_xyz": np.eye(3) + 1} | kwargs
    with pytest.raises(ValueError):
        align_positions(**args)


# --------------------------------------------------------------------------- estimate_pose


@settings(max_examples=50)
@given(seed=seeds, n=st.integers(3, 8), yaw_only=st.booleans())
def test_estimate_without_points_matches_closed_form(seed: int, n: int, yaw_only: bool) -> None:
    rng = np.random.default_rng(seed)
    local = rng.uniform(-3, 3, (n, 3))
    assume(np.linalg.svd(local - local.mean(0), compute_uv=False)[1] > 0.3)
    T_true = random_T(rng, yaw_only)
    up = Z if yaw_only else None
    est = estimate_pose(local, apply(T_true, local), None, [None] * n, up, up)
    assert isinstance(est, PoseEstimate)
    assert np.allclose(est.T, T_true, atol=1e-6)
    assert est.method == ("closed-form-4dof" if yaw_only else "closed-form-6dof")
    assert est.fitness == 1.0 and est.rmse < 1e-6


def test_fitness_and_rmse_exact_with_points() -> None:
    centres = np.array([[0.0, 0, 0], [4, 0, 0], [0, 4, 0]])
    glob_pts = np.array([[0.0, 0, 0], [1, 0, 0]])
    loc_pts = np.array([[0.0, 0, 0.03], [1, 0, 0.04], [3, 0, 0], [0, 0, 0.5]])
    cfg = PoseConfig(refine=False, icp_voxel=0.0, fitness_radius=0.1)
    est = estimate_pose(centres, centres, [loc_pts, None, None], [glob_pts, None, None], config=cfg)
    assert np.allclose(est.T, np.eye(4), atol=1e-12)
    assert est.fitness == pytest.approx(0.5)
    assert est.rmse == pytest.approx(np.sqrt((0.03**2 + 0.04**2) / 2))
    assert est.method == "closed-form-6dof"


def test_fitness_and_rmse_exact_from_centres() -> None:
    """x: local (0, 1, 2) vs global (0, 1, 3.2): yaw 0, t = 0.4, residuals 0.4, 0.4, 0.8."""
    local = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]])
    glob = np.array([[0.0, 0, 0], [1, 0, 0], [3.2, 0, 0]])
    est = estimate_pose(local, glob, None, None, Z, Z)
    assert np.allclose(est.T, make_T(np.eye(3), [0.4, 0, 0]), atol=1e-12)
    assert est.fitness == pytest.approx(2 / 3)
    assert est.rmse == pytest.approx(0.4)


@pytest.mark.parametrize("yaw", [0.3, 2.0, -2.6])
def test_search_4dof_one_pair_with_points(yaw: float) -> None:
    rng = np.random.default_rng(int(yaw * 100) % 997)
    T_true = make_T(rot_z(yaw), [2.0, -1.0, 0.3])
    local_pts = l_shape(rng) + [1.0, 2.0, 0.0]
    glob_pts = apply(T_true, l_shape(rng) + [1.0, 2.0, 0.0])  # an independent sample
    est = estimate_pose(
        local_pts.mean(0)[None], glob_pts.mean(0)[None], [local_pts], [glob_pts], Z, Z
    )
    assert est.method.startswith("search-4dof")
    assert rot_err_deg(est.T, T_true) < 3.0
    assert trans_err(est.T, T_true) < 0.03
    assert est.fitness > 0.9


def test_search_4dof_two_pairs_stacked_vertically_with_tilted_up() -> None:
    rng = np.random.default_rng(7)
    R0 = Rotation.from_euler("xy", [0.2, -0.1]).as_matrix()
    T_true = make_T(rot_z(1.1) @ R0.T, [0.5, 3.0, -0.2])
    objs = [l_shape(rng, 1500), l_shape(rng, 1500) + [0, 0, 1.2]]  # in a z-up "room" frame
    local_pts = [p @ R0.T for p in objs]  # local frame has up = R0 @ z
    glob_pts = [apply(T_true, p @ R0.T + rng.normal(0, 0.005, p.shape)) for p in objs]
    centres_l = np.array([p.mean(0) for p in local_pts])
    centres_g = np.array([p.mean(0) for p in glob_pts])
    est = estimate_pose(centres_l, centres_g, local_pts, glob_pts, R0 @ Z, Z)
    assert est.method.startswith("search-4dof")
    assert np.allclose(est.T[:3, :3] @ (R0 @ Z), Z, atol=1e-9)
    assert rot_err_deg(est.T, T_true) < 3.0
    assert trans_err(est.T, T_true) < 0.03


def test_search_6dof_two_pairs() -> None:
    rng = np.random.default_rng(8)
    T_true = make_T(Rotation.from_rotvec([0.4, -1.2, 2.0]).as_matrix(), [1.0, -2.0, 0.5])
    local_pts = [l_shape(rng, 1500), box_surface(rng, [0.4, 0.9, 0.5], 1500) + [2.0, 0.5, 0.3]]
    glob_pts = [apply(T_true, p + rng.normal(0, 0.005, p.shape)) for p in local_pts]
    centres_l = np.array([p.mean(0) for p in local_pts])
    centres_g = np.array([p.mean(0) for p in glob_pts])
    est = estimate_pose(centres_l, centres_g, local_pts, glob_pts)
    assert est.method.startswith("search-6dof")
    assert rot_err_deg(est.T, T_true) < 3.0
    assert trans_err(est.T, T_true) < 0.03


def test_search_6dof_one_pair_coarse_so3() -> None:
    rng = np.random.default_rng(9)
    T_true = make_T(Rotation.from_rotvec([1.0, 0.5, -0.7]).as_matrix(), [0.3, 0.2, 1.0])
    local_pts = l_shape(rng, 3000)
    glob_pts = apply(T_true, local_pts + rng.normal(0, 0.005, local_pts.shape))
    est = estimate_pose(local_pts.mean(0)[None], glob_pts.mean(0)[None], [local_pts], [glob_pts])
    assert est.method == "search-6dof+icp"
    assert rot_err_deg(est.T, T_true) < 5.0
    assert trans_err(est.T, T_true) < 0.05


def test_search_without_refinement_is_within_the_fine_grid() -> None:
    rng = np.random.default_rng(11)
    T_true = make_T(rot_z(-1.234), [0.4, 0.1, -0.2])
    local_pts = l_shape(rng, 2000)
    glob_pts = apply(T_true, local_pts)
    cfg = PoseConfig(refine=False)
    est = estimate_pose(
        local_pts.mean(0)[None],
        apply(T_true, local_pts.mean(0)[None]),
        [local_pts],
        [glob_pts],
        Z,
        Z,
        cfg,
    )
    assert est.method == "search-4dof"
    assert rot_err_deg(est.T, T_true) < 1.0  # coarse 5 deg grid refined to 0.5 deg
    assert trans_err(est.T, T_true) < 0.02
    assert np.allclose(est.T[:3, :3] @ Z, Z)


def test_close_centres_use_the_search_when_points_exist() -> None:
    """Two pairs 4 cm apart horizontally: the closed-form yaw would be noise; search instead."""
    rng = np.random.default_rng(12)
    T_true = make_T(rot_z(2.2), [1.0, 1.0, 0.0])
    objs = [l_shape(rng, 1500), l_shape(rng, 1500)[:, [1, 0, 2]] + [0.04, 0.0, 1.0]]
    centres_l = np.array([p.mean(0) for p in objs])
    centres_g = apply(T_true, centres_l) + rng.normal(0, 0.02, (2, 3))
    glob = [apply(T_true, p) for p in objs]
    est = estimate_pose(centres_l, centres_g, objs, glob, Z, Z)
    assert est.method.startswith("search-4dof")
    assert rot_err_deg(est.T, T_true) < 3.0
    assert estimate_pose(centres_l, centres_g, None, None, Z, Z).method == "closed-form-4dof"


def test_6dof_pairs_with_coincident_global_centres_stay_finite() -> None:
    rng = np.random.default_rng(13)
    local_pts = [box_surface(rng, [0.5, 0.3, 0.2], 300), box_surface(rng, [0.3, 0.3, 0.3], 300) + 1]
    centres_l = np.array([p.mean(0) for p in local_pts])
    centres_g = np.zeros((2, 3))  # inconsistent data: both global centres coincide
    glob_pts = [box_surface(rng, [0.5, 0.3, 0.2], 300)] * 2
    est = estimate_pose(centres_l, centres_g, local_pts, glob_pts, config=PoseConfig(refine=False))
    assert est.method == "search-6dof"
    assert np.all(np.isfinite(est.T)) and 0.0 <= est.fitness <= 1.0


def test_prepared_cloud_voxel_means_cap_and_huge_ranges() -> None:
    pts = np.array([[0.01, 0.01, 0.01], [0.03, 0.03, 0.03], [1.0, 1.0, 1.0]])
    cloud = prepare_cloud(pts, PoseConfig(icp_voxel=0.05))
    assert np.allclose(cloud.points, [[0.02, 0.02, 0.02], [1.0, 1.0, 1.0]])
    assert np.allclose(np.linalg.norm(cloud.normals, axis=1), 1.0)
    far = np.vstack([pts, [[1e9, -1e9, 1e9]]])  # voxel keys no longer fit one int64
    cloud = prepare_cloud(far, PoseConfig(icp_voxel=1e-6))
    assert len(cloud.points) == 4 and np.allclose(np.sort(cloud.points[:, 0]), np.sort(far[:, 0]))
    capped = prepare_cloud(
        np.random.default_rng(0).uniform(size=(50, 3)), PoseConfig(icp_voxel=0.0, icp_max_points=7)
    )
    assert len(capped.points) == 7
    assert prepare_cloud(np.zeros((0, 3))) is None


@pytest.mark.parametrize(
    ("local", "up"),
    [([[1.0, 2, 3]], Z), ([[1.0, 2, 3]], None), ([[0.0, 0, 0], [1, 0, 0]], None)],
)
def test_under_determined_without_points_returns_none(local, up) -> None:
    local = np.asarray(local)
    n = len(local)
    assert estimate_pose(local, local + 1, None, None, up, up) is None
    assert estimate_pose(local, local + 1, [None] * n, [np.zeros((0, 3))] * n, up, up) is None


def _partial_view_scene(rng: np.random.Generator, T_lw: np.ndarray, T_gw: np.ndarray):
    """Three boxes in a z-up room frame W: full surfaces in the global map, only the -y half
    seen locally, so the local centres are biased by ~0.2 m along +y."""
    sizes = [[0.8, 0.9, 0.8], [1.2, 0.8, 0.5], [0.5, 0.9, 1.0]]
    offsets = [[0.0, 0.0, 0.4], [3.0, 1.0, 0.25], [1.0, 4.0, 0.5]]
    local_pts, glob_pts = [], []
    for size, offset in zip(sizes, offsets, strict=True):
        seen = box_surface(rng, size, 4000)
        local_pts.append(apply(T_lw, seen[seen[:, 1] < 0] + offset))
        glob_pts.append(apply(T_gw, box_surface(rng, size, 4000) + offset))
    centres_l = np.array([p.mean(0) for p in local_pts])
    centres_g = np.array([p.mean(0) for p in glob_pts])
    return centres_l, centres_g, local_pts, glob_pts


@pytest.mark.parametrize("yaw_only", [True, False])
def test_icp_corrects_centres_biased_by_partial_views(yaw_only: bool) -> None:
    rng = np.random.default_rng(10)
    R0 = Rotation.from_euler("xy", [0.15, 0.1]).as_matrix()
    if yaw_only:  # local up = R0 @ z, global up = z
        T_lw, T_gw = make_T(R0, [0.2, 0.1, -0.3]), make_T(rot_z(0.8), [1.0, -2.0, 0.5])
        up_l, up_g = R0 @ Z, Z
    else:
        T_lw = np.eye(4)
        T_gw = make_T(Rotation.from_rotvec([0.3, 0.2, 0.8]).as_matrix(), [1.0, -2.0, 0.5])
        up_l = up_g = None
    T_true = T_gw @ np.linalg.inv(T_lw)
    args = (*_partial_view_scene(rng, T_lw, T_gw), up_l, up_g)
    coarse = estimate_pose(*args, config=PoseConfig(refine=False))
    fine = estimate_pose(*args)
    assert coarse.method.startswith("closed-form")
    assert trans_err(coarse.T, T_true) > 0.15  # the biased centres mislead the closed form
    assert fine.method == coarse.method + "+icp"
    assert trans_err(fine.T, T_true) < 0.05
    assert rot_err_deg(fine.T, T_true) < 1.0
    assert fine.fitness >= coarse.fitness
    if yaw_only:
        assert np.allclose(fine.T[:3, :3] @ up_l, up_g, atol=1e-9)


def test_bad_point_input_raises() -> None:
    c = np.eye(3)
    ok = [np.zeros((5, 3))] * 3
    with pytest.raises(ValueError, match="one entry per"):
        estimate_pose(c, c, ok[:2], ok)
    with pytest.raises(ValueError, match="non-finite"):
        estimate_pose(c, c, [np.full((5, 3), np.nan)] + ok[:2], ok)
    with pytest.raises(ValueError, match="shape"):
        estimate_pose(c, c, [np.zeros((5, 2))] + ok[:2], ok)
    with pytest.raises(ValueError, match="no matched"):
        estimate_pose(np.zeros((0, 3)), np.zeros((0, 3)), [], [])
    with pytest.raises(ValueError, match="rows must pair up"):
        estimate_pose(c, c[:2], None, None)


def test_config_forbids_unknown_fields() -> None:
    with pytest.raises(ValueError):
        PoseConfig(icp_itrations=3)


# --------------------------------------------------------------------------- library path


def _boxes_scene(rng: np.random.Generator, T_true: np.ndarray, up_tilt: np.ndarray):
    """Three boxes with independent surface samples: local (in a frame tilted by `up_tilt`)
    and global (moved by T_true after the tilt), as prepared clouds."""
    sizes = [[0.8, 0.5, 0.9], [1.2, 0.7, 0.5], [0.4, 0.9, 1.1]]
    offsets = [[0.0, 0.0, 0.45], [2.5, 1.0, 0.25], [0.5, 3.0, 0.55]]
    local, glob = [], []
    for size, offset in zip(sizes, offsets, strict=True):
        local.append(box_surface(rng, size, 3000) @ up_tilt.T + np.asarray(offset) @ up_tilt.T)
        glob.append(
            apply(T_true, box_surface(rng, size, 3000) @ up_tilt.T + np.asarray(offset) @ up_tilt.T)
        )
    return local, glob


@settings(max_examples=15)
@given(
    seed=seeds,
    yaw=st.floats(-np.pi, np.pi),
    tilt=st.tuples(st.floats(-0.3, 0.3), st.floats(-0.3, 0.3)),
    bias=st.floats(0.0, 0.25),
)
def test_4dof_icp_on_prepared_clouds_keeps_up_exactly(seed, yaw, tilt, bias) -> None:
    """Random yaw + translation, a tilted local up, centres biased by `bias` m: the ICP on the
    prepared clouds (compiled KD-trees and ICP) recovers the pose and maps up_local exactly onto up_global."""
    rng = np.random.default_rng(seed)
    R0 = Rotation.from_euler("xy", tilt).as_matrix()  # the local frame's up is R0 @ z
    T_true = make_T(rot_z(yaw) @ R0.T, rng.uniform(-4, 4, 3))
    local, glob = _boxes_scene(rng, T_true, R0)
    centres_l = np.array([p.mean(0) for p in local]) + bias * rng.normal(size=(3, 3)) / np.sqrt(3)
    centres_g = np.array([p.mean(0) for p in glob])
    cfg = PoseConfig()
    clouds_l, clouds_g = (
        [prepare_cloud(p, cfg) for p in local],
        [prepare_cloud(p, cfg) for p in glob],
    )
    assert all(isinstance(c, ObjectCloud) for c in clouds_l + clouds_g)
    est = estimate_pose(centres_l, centres_g, clouds_l, clouds_g, R0 @ Z, Z, cfg)
    assert est.method == "closed-form-4dof+icp"
    np.testing.assert_allclose(est.T[:3, :3] @ (R0 @ Z), Z, atol=1e-12)
    assert rot_err_deg(est.T, T_true) < 0.5
    assert trans_err(est.T, T_true) < 0.02
    assert est.fitness > 0.95


@settings(max_examples=15)
@given(seed=seeds, bias=st.floats(0.0, 0.2))
def test_6dof_icp_recovers_random_rigid_transforms(seed, bias) -> None:
    rng = np.random.default_rng(seed)
    T_true = random_T(rng)
    local, glob = _boxes_scene(rng, T_true, np.eye(3))
    centres_l = np.array([p.mean(0) for p in local]) + bias * rng.normal(size=(3, 3)) / np.sqrt(3)
    centres_g = np.array([p.mean(0) for p in glob])
    est = estimate_pose(centres_l, centres_g, local, glob)
    assert est.method == "closed-form-6dof+icp"
    assert rot_err_deg(est.T, T_true) < 0.5
    assert trans_err(est.T, T_true) < 0.02
    np.testing.assert_allclose(est.T[:3, :3] @ est.T[:3, :3].T, np.eye(3), atol=1e-9)


def test_prepared_clouds_and_arrays_give_the_same_pose() -> None:
    rng = np.random.default_rng(21)
    T_true = make_T(rot_z(0.7), [1.0, 2.0, 0.0])
    local, glob = _boxes_scene(rng, T_true, np.eye(3))
    centres_l = np.array([p.mean(0) for p in local])
    centres_g = apply(T_true, centres_l)
    cfg = PoseConfig()
    from_arrays = estimate_pose(centres_l, centres_g, local, glob, Z, Z, cfg)
    prepared = [prepare_cloud(p, cfg) for p in local], [prepare_cloud(p, cfg) for p in glob]
    from_clouds = estimate_pose(centres_l, centres_g, *prepared, Z, Z, cfg)
    np.testing.assert_array_equal(from_arrays.T, from_clouds.T)
    assert from_arrays.fitness == from_clouds.fitness


def test_warm_start_replaces_a_worse_start_and_is_refined() -> None:
    """Two pairs stacked on the up axis (the closed form cannot fix the yaw): a warm start
    near the truth wins over the search candidates when it fits better, and is refined."""
    rng = np.random.default_rng(22)
    T_true = make_T(rot_z(-1.3), [0.5, 1.0, 0.0])
    objs = [l_shape(rng, 1500), l_shape(rng, 1500) + [0, 0, 1.2]]
    glob = [apply(T_true, p) for p in objs]
    centres_l = np.array([p.mean(0) for p in objs])
    centres_g = apply(T_true, centres_l)
    near = make_T(rot_z(-1.3 + 0.03), [0.52, 0.98, 0.0])
    est = estimate_pose(centres_l, centres_g, objs, glob, Z, Z, init=near)
    assert est.method in ("warm-4dof+icp", "search-4dof+icp")
    assert rot_err_deg(est.T, T_true) < 0.5 and trans_err(est.T, T_true) < 0.02
    only = estimate_pose(centres_l[:1], centres_g[:1], None, None, Z, Z, init=near)
    assert only.method == "warm-4dof" and np.array_equal(only.T, near)


def test_cached_cloud_is_prepared_once_per_object_and_setting() -> None:
    rng = np.random.default_rng(23)
    obj = SemanticObject("a", "chair", [0.0, 0, 0], points=box_surface(rng, [0.5, 0.5, 0.9], 2000))
    first = cached_cloud(obj, PoseConfig())
    assert cached_cloud(obj, PoseConfig()) is first
    assert cached_cloud(obj, PoseConfig(refine=False)) is first  # ICP settings do not matter
    coarser = cached_cloud(obj, PoseConfig(icp_voxel=0.1))
    assert coarser is not first and len(coarser.points) < len(first.points)
    assert cached_cloud(obj.replace(points=None), PoseConfig()) is None
    moved = obj.replace(points=obj.points + 1.0)  # a new version: prepared anew
    again = cached_cloud(moved, PoseConfig())
    assert again is not first
    np.testing.assert_allclose(again.points.mean(0), first.points.mean(0) + 1.0, atol=0.01)


def test_far_queries_are_answered_without_neighbours() -> None:
    rng = np.random.default_rng(24)
    cloud = prepare_cloud(box_surface(rng, [1.0, 1.0, 1.0], 3000))
    query = np.array([[0.5, 0.0, 0.0], [0.55, 0.0, 0.0], [0.0, 0.0, 0.0], [30.0, 0.0, 0.0]])
    idx, dist = cloud.nearest(query, 1, 0.1)
    assert np.isfinite(dist[:2, 0]).all() and np.all(dist[:2, 0] < 0.1)
    assert np.isinf(dist[2:, 0]).all()  # the box centre is 0.5 m from its surface
    exact = np.min(np.linalg.norm(cloud.points[None] - query[:2, None], axis=2), axis=1)
    np.testing.assert_allclose(dist[:2, 0], exact)
    _, wide = cloud.nearest(query, 1, 1.0)
    assert np.isfinite(wide[2, 0]) and np.isinf(wide[3, 0])


@given(sizes=st.lists(st.integers(1, 40), min_size=1, max_size=8), limit=st.integers(0, 200))
def test_thinned_rows_keep_every_cloud_evenly_in_input_order(sizes: list[int], limit: int) -> None:
    from semloc.registration import thinned_rows

    rng = np.random.default_rng(sum(sizes) + limit)
    orders = [rng.permutation(n).astype(np.int32) for n in sizes]  # input row -> tree row
    rows, owner = thinned_rows(np.array(sizes), np.concatenate(orders), limit)
    total = sum(sizes)
    first = np.cumsum([0, *sizes])
    for cloud, (n, order) in enumerate(zip(sizes, orders)):
        mine = rows[owner == cloud] - first[cloud]
        if 0 < limit < total:  # every (total / limit)-th point, in input order
            kept = [int(k * total / limit) for k in range(int(np.ceil(n * limit / total)))]
        else:
            kept = list(range(n))
        assert mine.tolist() == order[kept].tolist()
    assert np.all(np.diff(owner) >= 0)
