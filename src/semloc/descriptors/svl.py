"""SVL-style semantic volume descriptor (Schönberger et al., "Semantic Visual Localization",
CVPR 2018): the encoder of a 3D convolutional variational auto-encoder over the semantic voxel
volume around an object, run in numpy.

The volume: a gravity-aligned box of 20 x 20 x 12 cells of `CELL` = 0.2 m (4 m x 4 m x 2.4 m)
centred horizontally on the object's position, from the lowest point of the map (the floor)
upwards, rotated by a yaw about the centre.  Each cell holds one channel per class of
`CLASSES` (the simulator's 19 classes, then `other` for every other label), 1 where a point of
an object of that class falls: the object itself *and its neighbourhood*, which is what makes
it distinctive (and what a moved or missing neighbour breaks).

The network (trained by `semloc.eval.descriptors.train_svl` to complete partial local
volumes into the whole map's; torch only there); the descriptor is the encoder's mean:

    conv1 20 -> 32, 4^3, stride 2, pad 1, ReLU      20x20x12 -> 10x10x6
    conv2 32 -> 64, 4^3, stride 2, pad 1, ReLU      10x10x6  -> 5x5x3
    mu    4800 -> 32

Weights ship as `svl_weights.npz` beside this file (encoder only; `allow_pickle=False`).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from semloc.descriptors.layers import WeightFile, conv3d

CLASSES: tuple[str, ...] = (
    "armchair", "bed", "bookshelf", "cabinet", "chair", "coffee_table", "desk", "lamp",
    "low_cabinet", "monitor", "nightstand", "plant", "refrigerator", "sink", "sofa", "table",
    "toilet", "tv", "whiteboard", "other",
)  # fmt: skip
CHANNELS = len(CLASSES)
GRID = (20, 20, 12)
CELL = 0.2
THIN = 0.05  # points are thinned to one per THIN cell before voxelization
LATENT = 32
YAWS = 8  # rotations of the global volumes (45 degree steps)
WEIGHTS_FILE = Path(__file__).with_name("svl_weights.npz")
LAYERS = {  # name: (in, out, kernel, stride, pad)
    "conv1": (CHANNELS, 32, 4, 2, 1),
    "conv2": (32, 64, 4, 2, 1),
}
FLAT = 64 * 5 * 5 * 3
PARAMETERS = [f"{name}.{p}" for name in [*LAYERS, "mu"] for p in ("weight", "bias")]
WEIGHTS = WeightFile(WEIGHTS_FILE, tuple(PARAMETERS), "SVL", "semloc train-descriptor --kind svl")
_CHANNEL = {name: i for i, name in enumerate(CLASSES)}


def channel_of(label: str) -> int:
    """The volume channel of a label (`other` for labels outside the simulator's classes)."""
    key = label.strip().lower().replace(" ", "_")
    return _CHANNEL.get(key, CHANNELS - 1)


def scene_points(
    points: Sequence[np.ndarray | None], labels: Sequence[str], up: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """All objects' points (thinned, z = `up`) and their class channels, as one scene."""
    R = to_z(up)
    chunks, channels = [], []
    for pts, label in zip(points, labels, strict=True):
        if pts is None or len(pts) == 0:
            continue
        p = np.asarray(pts, dtype=float) @ R.T
        keys = np.floor(p / THIN).astype(np.int64)
        _, first = np.unique(keys, axis=0, return_index=True)
        chunks.append(p[np.sort(first)])
        channels.append(np.full(len(first), channel_of(label), dtype=np.int64))
    if not chunks:
        return np.zeros((0, 3)), np.zeros(0, dtype=np.int64)
    return np.vstack(chunks), np.concatenate(channels)


def to_z(up: np.ndarray | None) -> np.ndarray:
    """A rotation taking `up` to +z (identity for None or z)."""
    if up is None:
        return np.eye(3)
    u = np.asarray(up, dtype=float) / np.linalg.norm(up)
    v = np.cross(u, [0.0, 0.0, 1.0])
    s, c = np.linalg.norm(v), float(u[2])
    if s < 1e-9:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    k = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]]) / s
    return np.eye(3) + s * k + (1 - c) * k @ k


def volumes(
    points: np.ndarray,
    channels: np.ndarray,
    centres: np.ndarray,
    yaws: Sequence[float] = (0.0,),
    floor: float | None = None,
) -> np.ndarray:
    """Semantic volumes (len(centres) * len(yaws), CHANNELS, 20, 20, 12) float32, centre-major:
    the scene (`scene_points`) around each centre (x, y; z = up), turned by -yaw about it."""
    centres = np.asarray(centres, dtype=float).reshape(-1, 3)
    out = np.zeros((len(centres) * len(yaws), CHANNELS, *GRID), dtype=np.float32)
    if len(points) == 0:
        return out
    floor = float(points[:, 2].min()) if floor is None else floor
    half = GRID[0] * CELL / 2
    near = cKDTree(points[:, :2]).query_ball_point(centres[:, :2], half * np.sqrt(2) + 1e-6)
    iz = np.floor((points[:, 2] - floor) / CELL).astype(np.int64)
    for i, (centre, members) in enumerate(zip(centres, near, strict=True)):
        m = np.asarray(members, dtype=np.int64)
        xy = points[m, :2] - centre[:2]
        for j, yaw in enumerate(yaws):
            c, s = np.cos(yaw), np.sin(yaw)
            turned = xy @ np.array([[c, -s], [s, c]])  # rows rotated by -yaw
            ix, iy = (np.floor((turned + half) / CELL).astype(np.int64)).T
            ok = (ix >= 0) & (ix < GRID[0]) & (iy >= 0) & (iy < GRID[1])
            ok &= (iz[m] >= 0) & (iz[m] < GRID[2])
            out[i * len(yaws) + j, channels[m[ok]], ix[ok], iy[ok], iz[m][ok]] = 1.0
    return out


def load_weights(path: str | Path | None = None) -> dict[str, np.ndarray]:
    """The encoder's parameters (float32) from an `.npz` file (default: the shipped weights)."""
    return WEIGHTS.load(path)


def encode(vols: np.ndarray, weights: dict[str, np.ndarray] | None = None) -> np.ndarray:
    """Descriptors (N, 32) float32: the encoder's mean of volumes (N, CHANNELS, 20, 20, 12)."""
    weights = weights if weights is not None else load_weights()
    vols = np.asarray(vols, dtype=np.float32)
    out = []
    for start in range(0, len(vols), 32):
        x = vols[start : start + 32]
        for name, (_, _, _, stride, pad) in LAYERS.items():
            x = conv3d(x, weights[f"{name}.weight"], weights[f"{name}.bias"], stride, pad)
            x = np.maximum(x, 0)
        x = x.reshape(len(x), -1)
        out.append(x @ weights["mu.weight"].T + weights["mu.bias"])
    return np.concatenate(out).astype(np.float32) if out else np.zeros((0, LATENT), np.float32)
