"""Timing of pose recovery: closed form, global search and ICP on ~2 x 4000 points.

Run: PYTHONPATH=src python benchmarks/bench_pose.py  (process CPU time per call)
"""

from __future__ import annotations

import time

import numpy as np
from scipy.spatial.transform import Rotation

from semloc.pose import PoseConfig, align_positions, estimate_pose

Z = np.array([0.0, 0.0, 1.0])


def box_surface(rng: np.random.Generator, size, n: int) -> np.ndarray:
    size = np.asarray(size, dtype=float)
    p = rng.uniform(-0.5, 0.5, (n, 3)) * size
    axis = rng.integers(0, 3, n)
    p[np.arange(n), axis] = np.sign(rng.uniform(-1, 1, n)) * size[axis] / 2
    return p


def scene(rng: np.random.Generator, T: np.ndarray, n_objects: int = 4, n: int = 20000):
    """Boxes of 0.5-1.2 m: full surfaces in the global map, the -y half seen locally."""
    local_pts, glob_pts = [], []
    for _ in range(n_objects):
        size, offset = rng.uniform(0.5, 1.2, 3), rng.uniform(-4, 4, 3)
        seen = box_surface(rng, size, n)
        local_pts.append(seen[seen[:, 1] < 0] + offset)
        full = box_surface(rng, size, n) + offset
        glob_pts.append(full @ T[:3, :3].T + T[:3, 3])
    centres = [np.array([p.mean(0) for p in pts]) for pts in (local_pts, glob_pts)]
    return centres[0], centres[1], local_pts, glob_pts


def timed(fn, repeat: int) -> float:
    fn()
    start = time.process_time()
    for _ in range(repeat):
        fn()
    return (time.process_time() - start) / repeat * 1e3


def main() -> None:
    rng = np.random.default_rng(0)
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = Rotation.from_euler("z", 0.7).as_matrix(), [1.0, -2.0, 0.3]
    cl, cg, lp, gp = scene(rng, T)
    us = timed(lambda: align_positions(cl, cg), 2000) * 1e3
    print(f"closed form 6-DoF:          {us:8.1f} us")
    us = timed(lambda: align_positions(cl, cg, Z, Z), 2000) * 1e3
    print(f"closed form 4-DoF:          {us:8.1f} us")
    no_icp = PoseConfig(refine=False)
    base = timed(lambda: estimate_pose(cl, cg, lp, gp, Z, Z, no_icp), 10)
    print(f"estimate 4-DoF, no ICP:     {base:8.1f} ms  (downsampling + fitness)")
    for up, tag in ((Z, "4-DoF"), (None, "6-DoF")):
        ms = timed(lambda up=up: estimate_pose(cl, cg, lp, gp, up, up), 10)
        est = estimate_pose(cl, cg, lp, gp, up, up)
        err = np.linalg.norm(est.T[:3, 3] - T[:3, 3])
        print(f"estimate {tag} + ICP:      {ms:8.1f} ms  ({est.method}, t err {err:.3f} m)")
    one = (cl[:1], cg[:1], lp[:1], gp[:1])
    for up, tag in ((Z, "4-DoF"), (None, "6-DoF")):
        ms = timed(lambda up=up: estimate_pose(*one, up, up), 3)
        est = estimate_pose(*one, up, up)
        err = np.linalg.norm(est.T[:3, 3] - T[:3, 3])
        print(f"search {tag}, 1 pair + ICP: {ms:8.1f} ms  ({est.method}, t err {err:.3f} m)")


if __name__ == "__main__":
    main()
