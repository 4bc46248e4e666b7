"""The numpy side of the learned descriptors: 3D convolution and pooling as torch computes them
(float32, im2col + matrix products), and reading a shipped weight file safely.

Every learned model of the package (VoxNet, SVL, FCGF-style) is trained in torch
(`semloc.eval.descriptors`, the `train` extra) and run here without torch.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import numpy as np


def conv3d(x: np.ndarray, weight: np.ndarray, bias: np.ndarray, stride: int = 1, pad: int = 0):
    """3D convolution (cross-correlation, like torch's `Conv3d`) of x (N, C, D, H, W)."""
    out_c, in_c, k = weight.shape[0], weight.shape[1], weight.shape[2]
    x = np.pad(x, ((0, 0), (0, 0), (pad, pad), (pad, pad), (pad, pad)))
    windows = np.lib.stride_tricks.sliding_window_view(x, (k, k, k), axis=(2, 3, 4))
    windows = windows[:, :, ::stride, ::stride, ::stride]
    n, _, d, h, w = windows.shape[:5]
    cols = windows.transpose(0, 2, 3, 4, 1, 5, 6, 7).reshape(n * d * h * w, in_c * k**3)
    out = cols @ weight.reshape(out_c, -1).T + bias
    return out.reshape(n, d, h, w, out_c).transpose(0, 4, 1, 2, 3)


def maxpool3d(x: np.ndarray, size: int) -> np.ndarray:
    """Non-overlapping max pooling of x (N, C, D, H, W) by `size` (dimensions divisible)."""
    if size == 1:
        return x
    n, c, d, h, w = x.shape
    x = x.reshape(n, c, d // size, size, h // size, size, w // size, size)
    return x.max(axis=(3, 5, 7))


def read_weights(
    path: str | Path, parameters: Iterable[str], what: str, command: str
) -> dict[str, np.ndarray]:
    """Float32 arrays of an `.npz` weight file (no pickles); a one-line error when the file is
    missing, is not an `.npz` archive or lacks one of `parameters` (`what`: the model's name
    in the message, `command`: how to make the file)."""
    path = Path(path)
    try:
        data = np.load(path, allow_pickle=False)
    except FileNotFoundError:
        raise FileNotFoundError(f"{path}: {what} weights not found (run `{command}`)") from None
    except (OSError, ValueError, EOFError) as exc:
        raise ValueError(f"{path}: not a {what} weight file ({exc})") from None
    if not isinstance(data, np.lib.npyio.NpzFile):
        raise ValueError(f"{path}: not a {what} weight file (an .npy array, not an .npz archive)")
    with data:
        try:
            weights = {k: np.asarray(data[k], dtype=np.float32) for k in data.files}
        except (OSError, ValueError, EOFError) as exc:
            raise ValueError(f"{path}: not a {what} weight file ({exc})") from None
    missing = [k for k in parameters if k not in weights]
    if missing:
        raise ValueError(f"{path}: not {what} weights (missing {', '.join(missing)})")
    return weights


@dataclass(frozen=True)
class WeightFile:
    """A model's weights: the shipped file (read once per process), its parameter names, the
    model's name in messages and the command that makes the file."""

    shipped: Path
    parameters: tuple[str, ...]
    what: str
    command: str

    def load(self, path: str | Path | None = None) -> dict[str, np.ndarray]:
        """The parameters (float32) from `path` (default: the shipped file, read once)."""
        path = Path(path) if path is not None else self.shipped
        return _shipped(self) if path == self.shipped else self.read(path)

    def read(self, path: str | Path) -> dict[str, np.ndarray]:
        return read_weights(path, self.parameters, self.what, self.command)


@cache
def _shipped(weights: WeightFile) -> dict[str, np.ndarray]:
    return weights.read(weights.shipped)
