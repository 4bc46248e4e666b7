"""Training of the VoxNet descriptor with a triplet loss (torch; the `train` extra only).

    semloc train-descriptor --out voxnet_weights.npz --seed 0 --epochs 6

Data (seeded, `semloc.eval.descriptors.data`): for every training instance (class, style; the
`HELD_OUT` styles excluded) `views` partial scans from random viewpoints with depth and
segmentation noise, and `full_views` CAD-style samples of the whole surface.  Each batch takes
`instances_per_batch` instances with 4 partial and 2 full views each; the loss is the
batch-all triplet loss over (anchor, positive: another view of the same instance, negative: a
view of another instance, which includes same-class other styles and other classes).
Augmentation: a random half turn about gravity and a random mirror of the canonical grid.

Everything is seeded and runs on CPU with a fixed thread count, so the same arguments give the
same weights.  torch is imported inside `train` only.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from semloc.descriptors.voxnet import EMBEDDING, FC, LAYERS, occupancy_grid
from semloc.eval.descriptors.data import full_view, instances, partial_view
from semloc.io import write_atomic

TORCH_HINT = "training needs torch: pip install 'semloc[train]'"


def seeded_torch(seed: int, threads: int):
    """torch, seeded and deterministic on `threads` threads (an ImportError with the install
    hint when it is missing): what every training command starts with."""
    try:
        import torch
    except ImportError as exc:
        raise ImportError(TORCH_HINT) from exc
    torch.manual_seed(seed)
    torch.set_num_threads(threads)
    torch.use_deterministic_algorithms(True)
    return torch


@dataclass(frozen=True)
class TrainConfig:
    seed: int = 0
    epochs: int = 6
    views: int = 48
    full_views: int = 12
    batches_per_epoch: int = 30
    instances_per_batch: int = 16
    margin: float = 0.3
    lr: float = 1e-3
    threads: int = 2


def layer_weights(net, layers) -> dict[str, np.ndarray]:
    """The weight and bias (float32 numpy) of each named layer of a torch model, as
    `<layer>.weight` / `<layer>.bias`: the names the numpy models read."""
    return {
        f"{name}.{p}": getattr(getattr(net, name), p).detach().cpu().numpy().astype(np.float32)
        for name in layers
        for p in ("weight", "bias")
    }


def load_layer_weights(net, weights: dict[str, np.ndarray]) -> None:
    """Copy `layer_weights`-named numpy arrays into a torch model (the numpy-versus-torch
    tests)."""
    import torch

    with torch.no_grad():
        for key, value in weights.items():
            name, p = key.split(".")
            getattr(getattr(net, name), p).copy_(torch.from_numpy(value))


def make_dataset(seed: int, views: int, full_views: int, split: str = "train"):
    """Grids (M, 32, 32, 32) uint8, instance index (M,), is-full flag (M,), instance list."""
    rng = np.random.default_rng([seed, 101])
    insts = instances(split)
    grids, owner, full = [], [], []
    for i, (label, style) in enumerate(insts):
        for _ in range(views):
            grids.append(occupancy_grid(partial_view(label, style, rng)).astype(np.uint8))
            owner.append(i)
            full.append(False)
        for _ in range(full_views):
            grids.append(occupancy_grid(full_view(label, style, rng)).astype(np.uint8))
            owner.append(i)
            full.append(True)
    return np.stack(grids), np.array(owner), np.array(full), insts


def build_model():
    """The torch network matching `voxnet.forward` (without the final normalisation)."""
    import torch.nn as nn

    layers: list = []
    for in_c, out_c, k, stride, pad, pool in LAYERS.values():
        layers += [nn.Conv3d(in_c, out_c, k, stride=stride, padding=pad), nn.ReLU()]
        if pool > 1:
            layers.append(nn.MaxPool3d(pool))
    (fc1_in, fc1_out), (fc2_in, fc2_out) = FC.values()
    layers += [nn.Flatten(), nn.Linear(fc1_in, fc1_out), nn.ReLU(), nn.Linear(fc2_in, fc2_out)]
    net = nn.Sequential(*layers)
    assert fc2_out == EMBEDDING
    return net


def state_to_numpy(net) -> dict[str, np.ndarray]:
    """Parameters under the names `voxnet.forward` uses (conv1.weight, ..., fc2.bias)."""
    names = [*LAYERS, *FC]
    modules = [m for m in net if hasattr(m, "weight")]
    out = {}
    for name, module in zip(names, modules, strict=True):
        out[f"{name}.weight"] = module.weight.detach().cpu().numpy().astype(np.float32)
        out[f"{name}.bias"] = module.bias.detach().cpu().numpy().astype(np.float32)
    return out


def embed(net, grids: np.ndarray) -> np.ndarray:
    """Torch forward (unit vectors) of grids (N, 32, 32, 32); float32 numpy."""
    import torch

    with torch.no_grad():
        x = torch.from_numpy(np.asarray(grids, np.float32))[:, None]
        y = torch.nn.functional.normalize(net(x), dim=1)
    return y.numpy()


def triplet_loss(dist, same, margin: float):
    """Batch-all triplet loss: mean of relu(d(a, p) - d(a, n) + margin) over the triplets
    (anchor, positive of the same instance, negative of another) that still violate it."""
    import torch

    eye = torch.eye(len(dist), dtype=torch.bool)
    positive = same & ~eye
    valid = positive[:, :, None] & ~same[:, None, :]
    losses = torch.relu(dist[:, :, None] - dist[:, None, :] + margin) * valid
    active = (losses > 1e-12).sum()
    return losses.sum() / active.clamp(min=1), float(active) / max(int(valid.sum()), 1)


def _augment(batch: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    out = batch.copy()
    for i in range(len(out)):
        if rng.random() < 0.5:
            out[i] = out[i, ::-1, ::-1]
        if rng.random() < 0.5:
            out[i] = out[i, :, ::-1]
    return out


def train(
    config: TrainConfig, log: Callable[[str], None] = print
) -> tuple[dict[str, np.ndarray], dict]:
    """Train; return the numpy weights and a summary (loss per epoch, time, data sizes)."""
    torch = seeded_torch(config.seed, config.threads)
    start = time.perf_counter()
    grids, owner, full, insts = make_dataset(config.seed, config.views, config.full_views)
    log(f"data: {len(grids)} grids of {len(insts)} instances ({time.perf_counter() - start:.0f} s)")
    rng = np.random.default_rng([config.seed, 202])
    net = build_model()
    optimiser = torch.optim.Adam(net.parameters(), lr=config.lr)
    partial_of = [np.flatnonzero((owner == i) & ~full) for i in range(len(insts))]
    full_of = [np.flatnonzero((owner == i) & full) for i in range(len(insts))]
    losses = []
    for epoch in range(config.epochs):
        total = share = 0.0
        for _ in range(config.batches_per_epoch):
            chosen = rng.choice(len(insts), size=config.instances_per_batch, replace=False)
            index = np.concatenate(
                [
                    np.concatenate(
                        [rng.choice(partial_of[i], 4, replace=False), rng.choice(full_of[i], 2)]
                    )
                    for i in chosen
                ]
            )
            x = torch.from_numpy(_augment(grids[index], rng).astype(np.float32))[:, None]
            y = torch.from_numpy(owner[index])
            emb = torch.nn.functional.normalize(net(x), dim=1)
            dist = torch.cdist(emb, emb)
            same = y[:, None] == y[None, :]
            loss, active = triplet_loss(dist, same, config.margin)
            share += active
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
            total += loss.item()
        losses.append(total / config.batches_per_epoch)
        share /= config.batches_per_epoch
        log(f"epoch {epoch + 1}/{config.epochs}: loss {losses[-1]:.4f}, violating {share:.3f}")
    net.eval()
    summary = {
        "seconds": time.perf_counter() - start,
        "losses": losses,
        "grids": len(grids),
        "instances": len(insts),
        "config": config.__dict__,
    }
    weights = state_to_numpy(net)
    summary["fixture"] = _fixture(net, config.seed)
    return weights, summary


def _fixture(net, seed: int) -> dict[str, np.ndarray]:
    """A few held-out grids and their torch embeddings, for the numpy-forward test."""
    rng = np.random.default_rng([seed, 303])
    grids = []
    for label, style in instances("held_out")[:3]:
        grids.append(occupancy_grid(partial_view(label, style, rng)))
    grids.append(occupancy_grid(full_view("chair", 0, rng)))
    grids = np.stack(grids).astype(np.uint8)
    return {"grids": grids, "embeddings": embed(net, grids)}


def save_weights(weights: dict[str, np.ndarray], path: str | Path) -> Path:
    """Write weights as a compressed `.npz` (atomically)."""
    import io

    buffer = io.BytesIO()
    np.savez_compressed(buffer, **weights)
    path = Path(path)
    write_atomic(path, buffer.getvalue())
    return path
