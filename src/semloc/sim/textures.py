"""Deterministic procedural surface textures of the simulated worlds (for colour images).

Every surface gets a *solid* texture: its colour is a function of the 3D point in the surface's
own frame (the object's model frame, or the world for floor and walls), so it sticks to the
surface from every viewpoint and moves with its object.  A texture is an albedo base colour
modulated by two layers of lattice noise, hashed from integer cell coordinates and the texture's
seed: smooth value noise (trilinear, `smooth` metres per cell) and sharp-edged tiles (`tiles`
metres per cell), which give images corners and blobs for keypoint detectors such as SIFT.

`texture_for(key)` derives a texture from any string key by a stable hash (blake2b), so the
same key gives the same texture in every process and run: identical object models share their
key (label and style), so repeated instances look alike, as real furniture does.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np

_MASK = np.uint64(0xFFFFFFFFFFFFFFFF)
_PRIMES = (np.uint64(0x9E3779B97F4A7C15), np.uint64(0xC2B2AE3D27D4EB4F),
           np.uint64(0x165667B19E3779F9))  # fmt: skip


def _mix(h: np.ndarray) -> np.ndarray:
    """splitmix64's finaliser: a well-spread 64-bit hash of each element (uint64 wraps)."""
    h = (h ^ (h >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    h = (h ^ (h >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return h ^ (h >> np.uint64(31))


def lattice_values(cells: np.ndarray, seed: int, channels: int = 3) -> np.ndarray:
    """Pseudo-random values in [0, 1) for integer lattice cells (N, 3): (N, channels)."""
    c = np.asarray(cells, dtype=np.int64).astype(np.uint64)
    with np.errstate(over="ignore"):
        h = _mix(np.uint64(seed & 0xFFFFFFFF) * _PRIMES[0] + np.zeros(len(c), np.uint64))
        for axis in range(3):
            h = _mix(h ^ (c[:, axis] * _PRIMES[axis]))
        out = np.empty((len(c), channels))
        for k in range(channels):
            h = _mix(h + _PRIMES[k % 3])
            out[:, k] = (h >> np.uint64(11)).astype(np.float64) / float(1 << 53)
    return out


def value_noise(points: np.ndarray, cell: float, seed: int, channels: int = 3) -> np.ndarray:
    """Smooth value noise in [0, 1) at `points` (N, 3), `cell` metres per lattice step."""
    p = np.asarray(points, dtype=float) / cell
    base = np.floor(p)
    f = p - base
    f = f * f * (3 - 2 * f)  # smoothstep: no creases at the cell borders
    base = base.astype(np.int64)
    out = np.zeros((len(p), channels))
    for corner in range(8):
        offset = np.array([(corner >> axis) & 1 for axis in range(3)])
        weight = np.prod(np.where(offset, f, 1 - f), axis=1)
        out += weight[:, None] * lattice_values(base + offset, seed, channels)
    return out


def tile_noise(points: np.ndarray, cell: float, seed: int, channels: int = 3) -> np.ndarray:
    """Piecewise-constant noise in [0, 1): one random value per lattice cell (sharp edges)."""
    cells = np.floor(np.asarray(points, dtype=float) / cell).astype(np.int64)
    return lattice_values(cells, seed, channels)


@dataclass(frozen=True)
class Texture:
    """A solid texture: `base` albedo (RGB in [0, 1]) modulated by smooth and tile noise."""

    seed: int
    base: tuple[float, float, float]
    contrast: float = 0.45
    smooth: float = 0.23
    tiles: float = 0.09

    def colour(self, points: np.ndarray) -> np.ndarray:
        """Albedo (N, 3) in [0, 1] at `points` (N, 3) of the surface's own frame."""
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        smooth = value_noise(points, self.smooth, self.seed)
        tiles = tile_noise(points, self.tiles, self.seed + 1)
        # luminance pattern (shared by the channels) plus a weaker per-channel tint
        lum = 0.55 * smooth.mean(axis=1, keepdims=True) + 0.45 * tiles[:, :1]
        tint = 0.5 * (smooth - smooth.mean(axis=1, keepdims=True)) + 0.2 * (tiles - 0.5)
        albedo = np.asarray(self.base) * (1 + self.contrast * (2 * lum - 1)) + 0.25 * tint
        return np.clip(albedo, 0.0, 1.0)


def texture_for(key: str) -> Texture:
    """The texture of a surface named `key` (stable across processes; see the module doc)."""
    seed = int.from_bytes(hashlib.blake2b(key.encode(), digest_size=4).digest(), "little")
    rng = np.random.default_rng(seed)
    base = rng.uniform(0.25, 0.8, size=3)
    return Texture(seed, (float(base[0]), float(base[1]), float(base[2])))
