"""FCGF-style dense geometric point features (after Choy, Park and Koltun, "Fully
Convolutional Geometric Features", ICCV 2019), run in numpy.

FCGF computes a feature for every occupied voxel of a cloud with a sparse convolutional
network (MinkowskiEngine, which needs CUDA).  This is the same idea with ordinary *dense* 3D
convolutions: the cloud becomes an occupancy grid of `VOXEL` = 0.1 m cells, and every layer is
a 3^3 convolution whose output is kept in a band around the surfaces (the cells within
`SPREAD` = 2 cells of an occupied one; zero elsewhere), so that context spreads along and
between nearby surfaces while empty space stays empty; dilations 1, 2, 4, 1.  Besides
occupancy, each occupied cell's input holds its height above the lowest occupied cell (the
floor, in a room's map): gravity is known, as for every method here, and a seat and a table
top of the same shape are not the same place.  The features of
the occupied cells are unit vectors of 32 dimensions:

    conv1  2 -> 16, dilation 1, ReLU        (inputs: 1, height above the lowest cell / 2.4 m)
    conv2 16 -> 32, dilation 2, ReLU
    conv3 32 -> 32, dilation 4, ReLU
    conv4 32 -> 32, dilation 1, L2 normalisation

Trained in torch with dense convolutions over 2.4 m crops (`semloc.eval.descriptors.train_fcgf`,
FCGF's hardest-contrastive loss, the band as a mask); here the same layers are evaluated at the
band's cells only (gathering each cell's 27 neighbours), which gives the dense network's
outputs there.
Weights ship as `fcgf_weights.npz` beside this file (`allow_pickle=False`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy import ndimage

from semloc.descriptors.layers import WeightFile

VOXEL = 0.1
SPREAD = 2  # the layers run at cells within 2 cells of an occupied one
HEIGHT = 2.4  # the height input is metres above the lowest occupied cell / HEIGHT
FEATURE = 32
WEIGHTS_FILE = Path(__file__).with_name("fcgf_weights.npz")
LAYERS = {  # name: (in, out, dilation)
    "conv1": (2, 16, 1),
    "conv2": (16, 32, 2),
    "conv3": (32, 32, 4),
    "conv4": (32, FEATURE, 1),
}
PARAMETERS = [f"{name}.{p}" for name in LAYERS for p in ("weight", "bias")]
WEIGHTS = WeightFile(
    WEIGHTS_FILE, tuple(PARAMETERS), "FCGF-style", "semloc train-descriptor --kind fcgf-dense"
)
OFFSETS = np.stack(np.meshgrid(*[np.arange(-1, 2)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
"""The 27 kernel offsets in the order of torch's weight[:, :, i, j, k]."""
_ROWS = 8192


def voxelize(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(occupied cells (M, 3) int64, cell of every point (N,)) at `VOXEL`."""
    keys = np.floor(np.asarray(points, dtype=float) / VOXEL).astype(np.int64)
    cells, inverse = np.unique(keys, axis=0, return_inverse=True)
    return cells, inverse.reshape(-1)


def load_weights(path: str | Path | None = None) -> dict[str, np.ndarray]:
    """The network parameters (float32) from an `.npz` file (default: the shipped weights)."""
    return WEIGHTS.load(path)


def active_cells(cells: np.ndarray) -> np.ndarray:
    """The cells the layers are computed at: the occupied ones first (in their order), then
    every other cell within `SPREAD` cells (Chebyshev) of one, sorted."""
    if len(cells) == 0:
        return cells
    lo = cells.min(axis=0) - SPREAD
    occupied = np.zeros(cells.max(axis=0) + SPREAD - lo + 1, dtype=bool)
    occupied[tuple((cells - lo).T)] = True
    band = ndimage.maximum_filter(occupied, size=2 * SPREAD + 1, mode="constant")
    return np.vstack([cells, np.argwhere(band & ~occupied) + lo])


def _neighbours(cells: np.ndarray, dilation: int) -> np.ndarray:
    """(M, 27) row of each cell's neighbour at every kernel offset (M: not a cell)."""
    lo = cells.min(axis=0) - dilation
    shape = cells.max(axis=0) + dilation - lo + 1
    index = np.full(shape, len(cells), dtype=np.int64)
    rel = cells - lo
    index[rel[:, 0], rel[:, 1], rel[:, 2]] = np.arange(len(cells))
    at = rel[:, None, :] + dilation * OFFSETS[None]
    return index[at[..., 0], at[..., 1], at[..., 2]]


def cell_inputs(cells: np.ndarray) -> np.ndarray:
    """The input channels (M, 2) of occupied cells: 1, and the height above the lowest one."""
    height = (cells[:, 2] - cells[:, 2].min()) * (VOXEL / HEIGHT)
    return np.stack([np.ones(len(cells)), height], axis=1).astype(np.float32)


def cell_features(cells: np.ndarray, weights: dict[str, np.ndarray] | None = None) -> np.ndarray:
    """Unit features (M, 32) float32 of distinct occupied cells (M, 3) (the dense network's
    output there)."""
    weights = weights if weights is not None else load_weights()
    if len(cells) == 0:
        return np.zeros((0, FEATURE), np.float32)
    cells = np.asarray(cells, dtype=np.int64)
    active = active_cells(cells)
    x = np.zeros((len(active), 2), dtype=np.float32)
    x[: len(cells)] = cell_inputs(cells)
    for i, (name, (in_c, out_c, dilation)) in enumerate(LAYERS.items()):
        rows = _neighbours(active, dilation)
        padded = np.vstack([x, np.zeros((1, in_c), np.float32)])
        w = weights[f"{name}.weight"].reshape(out_c, in_c, 27).transpose(2, 1, 0)
        w = w.reshape(27 * in_c, out_c)
        x = np.empty((len(active), out_c), dtype=np.float32)
        for start in range(0, len(active), _ROWS):  # bounded memory: 27 neighbours each
            block = rows[start : start + _ROWS]
            x[start : start + len(block)] = padded[block].reshape(len(block), -1) @ w
        x += weights[f"{name}.bias"]
        if i < len(LAYERS) - 1:
            x = np.maximum(x, 0)
    x = x[: len(cells)]
    x = x / np.maximum(np.linalg.norm(x, axis=1, keepdims=True), 1e-12)
    return x.astype(np.float32)


def point_features(points: np.ndarray, weights: dict[str, np.ndarray] | None = None):
    """Unit features (N, 32) float32 of points: the feature of the cell each point falls in."""
    cells, inverse = voxelize(points)
    return cell_features(cells, weights)[inverse]
