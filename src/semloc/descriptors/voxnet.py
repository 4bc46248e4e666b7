"""VoxNet-style learned descriptor: a 32^3 occupancy grid -> small 3D CNN -> unit vector.

The grid is built in the canonical object frame of `frame.canonical` (gravity up, yaw and
translation removed) with metric cells of `VOXEL` m, so the grid keeps the object's size:
x, y in [-1.12, 1.12) m around the horizontal centroid, z in [0, 2.24) m from the lowest point.

The network (trained by `semloc.eval.descriptors.train` with a triplet loss; torch only there):

    conv1  1 -> 8,  5^3, stride 2, pad 2, ReLU          32^3 -> 16^3
    conv2  8 -> 16, 3^3, pad 1, ReLU, max-pool 2         16^3 -> 8^3
    conv3 16 -> 32, 3^3, pad 1, ReLU, max-pool 2          8^3 -> 4^3
    fc1   2048 -> 128, ReLU
    fc2    128 -> 64, L2 normalisation

Inference here is plain numpy (im2col + matrix products, float32), so the package needs no
torch at run time.  Weights ship as `voxnet_weights.npz` beside this file (read with
`allow_pickle=False`); keys are the torch parameter names (`conv1.weight`, ...).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from semloc.descriptors.frame import canonical
from semloc.descriptors.layers import WeightFile, conv3d, maxpool3d

GRID = 32
VOXEL = 0.07
EMBEDDING = 64
WEIGHTS_FILE = Path(__file__).with_name("voxnet_weights.npz")
LAYERS = {  # name: (in, out, kernel, stride, pad, pool)
    "conv1": (1, 8, 5, 2, 2, 1),
    "conv2": (8, 16, 3, 1, 1, 2),
    "conv3": (16, 32, 3, 1, 1, 2),
}
FC = {"fc1": (32 * 4**3, 128), "fc2": (128, EMBEDDING)}
PARAMETERS = [f"{name}.{p}" for name in [*LAYERS, *FC] for p in ("weight", "bias")]
WEIGHTS = WeightFile(WEIGHTS_FILE, tuple(PARAMETERS), "VoxNet", "semloc train-descriptor")


def occupancy_grid(points: np.ndarray) -> np.ndarray:
    """The (32, 32, 32) float32 occupancy grid (axes x, y, z) of one object's points."""
    local = canonical(points, voxel=0.0)
    offset = np.array([GRID * VOXEL / 2, GRID * VOXEL / 2, 0.0])
    idx = np.floor((local + offset) / VOXEL).astype(np.int64)
    inside = np.all((idx >= 0) & (idx < GRID), axis=1)
    grid = np.zeros((GRID, GRID, GRID), dtype=np.float32)
    idx = idx[inside]
    grid[idx[:, 0], idx[:, 1], idx[:, 2]] = 1.0
    return grid


def load_weights(path: str | Path | None = None) -> dict[str, np.ndarray]:
    """The network parameters (float32) from an `.npz` file (default: the shipped weights)."""
    return WEIGHTS.load(path)


def forward(grids: np.ndarray, weights: dict[str, np.ndarray] | None = None) -> np.ndarray:
    """Embeddings (N, 64) float32, unit length, of occupancy grids (N, 32, 32, 32)."""
    weights = weights if weights is not None else load_weights()
    grids = np.asarray(grids, dtype=np.float32)
    if grids.ndim == 3:
        grids = grids[None]
    out = []
    for start in range(0, len(grids), 16):
        x = grids[start : start + 16, None]
        for name, (_, _, _, stride, pad, pool) in LAYERS.items():
            x = conv3d(x, weights[f"{name}.weight"], weights[f"{name}.bias"], stride, pad)
            x = maxpool3d(np.maximum(x, 0), pool)
        x = x.reshape(len(x), -1)
        x = np.maximum(x @ weights["fc1.weight"].T + weights["fc1.bias"], 0)
        x = x @ weights["fc2.weight"].T + weights["fc2.bias"]
        out.append(x / np.maximum(np.linalg.norm(x, axis=1, keepdims=True), 1e-12))
    return np.concatenate(out).astype(np.float32) if out else np.zeros((0, EMBEDDING), np.float32)
