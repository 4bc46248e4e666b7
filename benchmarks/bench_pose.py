"""Speed of pose recovery: registration libraries compared, and localization by stage.

Two parts (both on one core: run under `taskset -c 0`; times are CPU time of the process
per call, `time.process_time`, which on an idle machine equals wall time and on a shared one
leaves out the other processes' time slices):

`registration`: the same partial-view problems (4 boxes of 0.5-1.2 m, full surfaces in the
global map, the -y half seen locally, so the centres are biased by ~0.2 m; a random yaw +
translation) refined from the closed form of the biased centres by
  - semloc.pose.estimate_pose (own KD-trees, compiled Gauss-Newton point-to-plane, exact 4-DoF),
    with the clouds prepared beforehand as the Localizer keeps them (`prepare_cloud`),
  - small_gicp.align (GICP, 6-DoF; correspondence distance annealed 0.6 -> 0.1 m as semloc's
    kernel is), on the same downsampled clouds (as many local points as semloc moves) and a
    prebuilt KD-tree, when small_gicp is installed (the `test` extra has it),
  - Open3D registration_icp (point-to-plane with a Tukey loss, 6-DoF, same annealing) when
    Open3D is installed (it is not a semloc dependency).
  Prints median / p90 ms and rotation / translation error against the truth.

`localize`: real layouts (ScanNet scene0000_00 and Replica office4 under $SEMLOC_DATA) tiled
side by side into maps of ~300 objects with points (each copy keeps a random 80 % of the
objects, so that a view is not the same in every copy); crops of the 8 objects nearest a random
viewpoint (visible sides only, random heading).  Full `semloc.localize` per crop (the map is
loaded once): a first pass over the crops (each map object's cloud is prepared when a
localization first uses it), then the same crops again, with the time split by stage
(`Result.timing_ms`); and streaming: one new object per `Localizer.update`.

    SEMLOC_DATA=/path/to/shared/data/real PYTHONPATH=src taskset -c 0 \
        python benchmarks/bench_pose.py [--part registration localize] [--crops 40]

The `localize` part uses only the public API, so it also times older versions of semloc.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # one core, as the targets are stated

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

import semloc  # noqa: E402
from semloc.maps import ObjectMap  # noqa: E402

ZUP = np.array([0.0, 0.0, 1.0])
KERNELS = (0.6, 0.3, 0.15, 0.1)  # the annealing of semloc's ICP, given to the libraries too


# --------------------------------------------------------------------------- registration


def box_surface(rng: np.random.Generator, size, n: int) -> np.ndarray:
    size = np.asarray(size, dtype=float)
    p = rng.uniform(-0.5, 0.5, (n, 3)) * size
    axis = rng.integers(0, 3, n)
    p[np.arange(n), axis] = np.sign(rng.uniform(-1, 1, n)) * size[axis] / 2
    return p


def partial_view_problem(rng: np.random.Generator, n_objects: int = 4, n: int = 6000):
    """Boxes seen from -y locally, full in the global map; a random yaw + translation."""
    yaw = rng.uniform(-np.pi, np.pi)
    T = np.eye(4)
    T[:3, :3] = [[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]]
    T[:3, 3] = rng.uniform(-3, 3, 3)
    local_pts, glob_pts = [], []
    for _ in range(n_objects):
        size, offset = rng.uniform(0.5, 1.2, 3), rng.uniform(-4, 4, 3)
        seen = box_surface(rng, size, n)
        local_pts.append(seen[seen[:, 1] < 0] + offset)
        glob_pts.append((box_surface(rng, size, n) + offset) @ T[:3, :3].T + T[:3, 3])
    return T, local_pts, glob_pts


def errors(T: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    from semloc.transforms import pose_error

    return pose_error(T, truth)


def clock() -> float:
    """Seconds of CPU time of this process: on a shared machine, wall time also counts the
    other processes' time slices; one core is used (the BLAS threads are limited above)."""
    return time.process_time()


def timed(fn, repeat: int = 5) -> tuple[float, object]:
    """Milliseconds per call (the fastest of `repeat`) and a result."""
    out = fn()
    best = np.inf
    for _ in range(repeat):
        start = clock()
        fn()
        best = min(best, clock() - start)
    return best * 1e3, out


def _small_gicp(src: np.ndarray, dst: np.ndarray, T0: np.ndarray):
    """small_gicp's GICP (6-DoF), annealed as semloc's kernel; None when it is not installed."""
    try:
        import small_gicp
    except ImportError:
        return None
    target = small_gicp.PointCloud(dst)
    tree = small_gicp.KdTree(target)
    small_gicp.estimate_normals_covariances(target, tree, 10)
    source = small_gicp.PointCloud(src)
    small_gicp.estimate_normals_covariances(source, small_gicp.KdTree(source), 10)

    def gicp():
        T = T0
        for kernel in KERNELS:
            T = small_gicp.align(
                target, source, tree, T, registration_type="GICP",
                max_correspondence_distance=kernel, max_iterations=10,
            ).T_target_source  # fmt: skip
        return T

    return timed(gicp)


def registration(trials: int) -> None:
    from semloc.pose import PoseConfig, align_positions, estimate_pose, prepare_cloud

    cfg = PoseConfig()
    rows: dict[str, list[tuple[float, float, float]]] = {}
    rng = np.random.default_rng(0)
    for _ in range(trials):
        truth, lp, gp = partial_view_problem(rng)
        cl = np.array([p.mean(0) for p in lp])
        cg = np.array([p.mean(0) for p in gp])
        T0 = align_positions(cl, cg, ZUP, ZUP)
        lc = [prepare_cloud(p, cfg) for p in lp]
        gc = [prepare_cloud(p, cfg) for p in gp]
        for name, up in (("semloc 4-DoF", ZUP), ("semloc 6-DoF", None)):
            args = (cl, cg, lc, gc, up, up, cfg)
            ms, est = timed(lambda args=args: estimate_pose(*args))
            rows.setdefault(name, []).append((ms, *errors(est.T, truth)))
        src = np.concatenate([c.points for c in lc])
        src = src[np.linspace(0, len(src) - 1, min(len(src), cfg.local_points)).astype(int)]
        dst = np.concatenate([c.points for c in gc])
        gicp_row = _small_gicp(src, dst, T0)
        if gicp_row is not None:
            ms, T = gicp_row
            rows.setdefault("small_gicp GICP 6-DoF", []).append((ms, *errors(T, truth)))
        o3d_row = _open3d(src, dst, T0)
        if o3d_row is not None:
            ms, T = o3d_row
            rows.setdefault("Open3D p2plane Tukey 6-DoF", []).append((ms, *errors(T, truth)))
    print(f"registration: {trials} partial-view problems of 4 boxes, ms per call, one core")
    print(f"{'method':30s} {'median ms':>10s} {'p90 ms':>8s} {'rot p90 deg':>12s} "
          f"{'t median m':>11s} {'t p90 m':>8s}")  # fmt: skip
    for name, values in rows.items():
        a = np.array(values)
        print(f"{name:30s} {np.median(a[:, 0]):10.2f} {np.percentile(a[:, 0], 90):8.2f} "
              f"{np.percentile(a[:, 1], 90):12.2f} {np.median(a[:, 2]):11.3f} "
              f"{np.percentile(a[:, 2], 90):8.3f}")  # fmt: skip


def _open3d(src, dst, T0):
    try:
        import open3d as o3d
    except ImportError:
        return None
    reg = o3d.pipelines.registration
    source = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(src))
    target = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(dst))
    target.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(10))

    def run():
        T = T0
        for kernel in KERNELS:
            method = reg.TransformationEstimationPointToPlane(reg.TukeyLoss(k=kernel))
            criteria = reg.ICPConvergenceCriteria(max_iteration=10)
            T = reg.registration_icp(source, target, kernel, T, method, criteria).transformation
        return T

    return timed(run)


# --------------------------------------------------------------------------- localize


def tiled(objmap: ObjectMap, copies: int, spacing: float, keep: float = 0.8) -> ObjectMap:
    """`copies` copies of a map side by side along x (ids suffixed), one frame; each copy
    keeps a random `keep` share of the objects, so that the copies are told apart."""
    rng = np.random.default_rng(len(objmap))
    objects = []
    for c in range(copies):
        T = np.eye(4)
        T[0, 3] = c * spacing
        kept = [o for o in objmap if rng.random() < keep]
        objects += [o.transformed(T).replace(id=f"{o.id}#{c}") for o in kept]
    return objmap.with_objects(objects)


def real_maps(target: int) -> list[tuple[str, ObjectMap]]:
    from semloc.eval.datasets import real_data_dir
    from semloc.io.importers.replica import load_replica
    from semloc.io.importers.scannet import load_scannet

    data = real_data_dir()
    if data is None:
        print("real data not found: set SEMLOC_DATA (see ../shared/data/real)", file=sys.stderr)
        raise SystemExit(2)
    maps = []
    for name, full in (
        ("ScanNet scene0000_00", load_scannet(data / "scannet" / "scene0000_00")),
        ("Replica office4", load_replica(data / "replica" / "office4")),
    ):
        copies = max(1, round(target / (0.8 * len(full))))
        extent = np.ptp(full.positions[:, 0]) + 5.0
        maps.append((f"{name} x{copies}", tiled(full, copies, extent)))
    return maps


def crop8(full: ObjectMap, rng: np.random.Generator):
    """The 8 objects nearest a random viewpoint (visible sides, random heading), or None."""
    from semloc.sim.crop import crop_with_truth

    anchor = full.positions[rng.integers(len(full))]
    center = anchor + np.append(rng.uniform(-1, 1, 2), 0.0)
    local, truth = crop_with_truth(full, center, 4.0, "random", int(rng.integers(2**31)))
    if len(local) < 8:
        return None
    nearest = [o for o in local if int(o.id[1:]) < 8]  # crop ids l0, l1, ... by distance
    return local.with_objects(nearest), truth.T_global_local


def localize_part(crops: int, target: int) -> None:
    from semloc.localizer import Localizer

    print(f"localize: maps of ~{target} objects with points, 8-object crops, one core, ms")
    print("  first: the first localization that meets each map object (its cloud is prepared);")
    print("  then: the same crops again (prepared once per map); stages: medians of `then`;")
    print("  stream: Localizer.update with one new object and an answer each time")
    header = (f"{'map':26s} {'objects':>7s} {'runs':>4s} {'first med':>9s} {'then med':>8s} "
              f"{'p90':>6s} {'max':>6s} {'assoc':>6s} {'clust':>6s} {'pose':>6s} "
              f"{'right':>6s} {'stream med':>10s} {'p90':>6s}")  # fmt: skip
    print(header)
    for name, full in real_maps(target):
        rng = np.random.default_rng(0)
        samples = []
        while len(samples) < crops:
            sample = crop8(full, rng)
            if sample is not None:
                samples.append(sample)
        first = [_localize_ms(full, local)[0] for local, _ in samples]
        totals, stages, right, stream = [], [], [], []
        for local, truth in samples:
            ms, result = _localize_ms(full, local)
            totals.append(ms)
            stages.append(
                [result.timing_ms.get(k, 0.0) for k in ("association", "clustering", "pose")]
            )
            right.append(result.pose is not None and _right(result.pose, truth))
            localizer = Localizer(full, local_up=local.up)
            for obj in local:  # streaming: one object per update, an answer each time
                start = clock()
                localizer.update([obj])
                stream.append((clock() - start) * 1e3)
        st = np.median(np.array(stages), axis=0)
        print(f"{name:26s} {len(full):7d} {len(totals):4d} {np.median(first):9.1f} "
              f"{np.median(totals):8.1f} {np.percentile(totals, 90):6.1f} {np.max(totals):6.1f} "
              f"{st[0]:6.2f} {st[1]:6.2f} {st[2]:6.2f} {np.mean(right):6.0%} "
              f"{np.median(stream):10.2f} {np.percentile(stream, 90):6.2f}")  # fmt: skip


def _localize_ms(full: ObjectMap, local: ObjectMap):
    start = clock()
    result = semloc.localize(full, local)
    return (clock() - start) * 1e3, result


def _right(pose: np.ndarray, truth: np.ndarray) -> bool:
    R = pose[:3, :3].T @ truth[:3, :3]
    angle = np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1)))
    return bool(angle < 15 and np.linalg.norm(pose[:3, 3] - truth[:3, 3]) < 0.5)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--part", nargs="+", default=["registration", "localize"],
                        choices=["registration", "localize"])  # fmt: skip
    parser.add_argument("--trials", type=int, default=20, help="registration problems")
    parser.add_argument("--crops", type=int, default=40, help="crops per map")
    parser.add_argument("--objects", type=int, default=300, help="objects per tiled map")
    args = parser.parse_args()
    if "registration" in args.part:
        registration(args.trials)
    if "localize" in args.part:
        localize_part(args.crops, args.objects)


if __name__ == "__main__":
    main()
