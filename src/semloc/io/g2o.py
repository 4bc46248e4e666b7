"""The relative pose of two maps as one g2o `EDGE_SE3:QUAT` line, what pose-graph back-ends read.

    EDGE_SE3:QUAT id_a id_b  x y z  qx qy qz qw  I11 I12 ... I16 I22 ... I66

The measurement is T_a_b (B's frame in A's: p_a = R p_b + t); the 21 numbers are the upper
triangle of the 6x6 information matrix, row by row, in g2o's error order (translation, then the
imaginary part of the error quaternion).  `semloc.alignment.pose_information` gives it for a
right perturbation by a rotation vector δθ; the quaternion's imaginary part is δθ / 2, so the
rotation rows and columns are scaled by 2 here.  The quaternion is the unit one with qw >= 0,
the one of the two that g2o normalises to.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

TAG = "EDGE_SE3:QUAT"


def edge_line(pose: np.ndarray, information: np.ndarray, id_a: int = 0, id_b: int = 1) -> str:
    """The g2o line of the edge from vertex `id_a` to `id_b` (with a trailing newline)."""
    pose = np.asarray(pose, dtype=float)
    qx, qy, qz, qw = Rotation.from_matrix(pose[:3, :3]).as_quat()
    if qw < 0:  # one of the two equal quaternions, the one g2o normalises to
        qx, qy, qz, qw = -qx, -qy, -qz, -qw
    scale = np.array([1.0, 1.0, 1.0, 2.0, 2.0, 2.0])
    quaternion_information = information * np.outer(scale, scale)
    upper = quaternion_information[np.triu_indices(6)]
    numbers = [*pose[:3, 3], qx, qy, qz, qw, *upper]
    return f"{TAG} {id_a} {id_b} " + " ".join(f"{v:.9g}" for v in numbers) + "\n"


def parse_edge(line: str) -> tuple[int, int, np.ndarray, np.ndarray]:
    """(id_a, id_b, T_a_b, information in g2o's order) of an `EDGE_SE3:QUAT` line; ValueError
    on anything else."""
    fields = line.split()
    if len(fields) != 3 + 7 + 21 or fields[0] != TAG:
        raise ValueError(f"not an {TAG} line with 30 numbers")
    id_a, id_b = int(fields[1]), int(fields[2])
    values = np.array(fields[3:], dtype=float)
    if not np.all(np.isfinite(values)):
        raise ValueError(f"an {TAG} line with a non-finite number")
    pose = np.eye(4)
    pose[:3, 3] = values[:3]
    pose[:3, :3] = Rotation.from_quat(values[3:7]).as_matrix()
    information = np.zeros((6, 6))
    information[np.triu_indices(6)] = values[7:]
    information = information + np.triu(information, 1).T
    return id_a, id_b, pose, information
