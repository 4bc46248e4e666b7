"""Training of the FCGF-style dense feature network (torch; the `train` extra only).

    semloc train-descriptor --kind fcgf-dense --out fcgf_weights.npz --seed 0

Pairs (seeded, from the training worlds of `semloc.eval.descriptors.worlds`): around a random
object of a global map, crop A holds the map's points and crop B (`local_share` of the pairs)
a simulated local map of the same place (a part of the neighbours, each seen from one side,
1 cm noise) or else the map's points thinned, with 1 cm noise; each crop is turned
by its own random yaw and shifted by a random fraction of a cell (the random rigid transforms)
and becomes a 24^3 occupancy grid of 0.1 m cells (2.4 m).  The network of
`semloc.descriptors.fcgf` runs as dense `Conv3d` layers whose outputs are multiplied by the
occupancy (the sparse network's values at occupied cells).  Positives: cells of B whose centre
falls in an occupied cell of A under the known transforms; FCGF's hardest-contrastive loss on
`positives` sampled pairs: (d(a, b) - 0.1)+^2 for the pair, and (1.4 - d)+^2 for the hardest
negative of a and of b among the sampled cells more than 0.25 m away from the true match.

Seeded, one thread, deterministic algorithms: the same arguments give the same weights.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from semloc.descriptors.fcgf import LAYERS, SPREAD, VOXEL, cell_inputs
from semloc.eval.descriptors.train import layer_weights, load_layer_weights, seeded_torch
from semloc.eval.descriptors.worlds import TrainingMap, local_view, training_maps

CROP = 24  # cells per side of a training crop


@dataclass(frozen=True)
class FcgfTrainConfig:
    seed: int = 0
    worlds: int = 8
    epochs: int = 10
    batches_per_epoch: int = 50
    local_share: float = 0.5
    pairs: int = 4
    positives: int = 256
    positive_margin: float = 0.1
    negative_margin: float = 1.4
    negative_distance: float = 0.25
    lr: float = 1e-3
    threads: int = 1


def build_model():
    """The dense torch network; `forward(grid_inputs(...))` gives (B, 32, D, H, W) unit features at
    occupied cells, zeros elsewhere (the layers run in the band of cells within `SPREAD` of
    an occupied one)."""
    import torch
    import torch.nn as nn

    class DenseFcgf(nn.Module):
        def __init__(self) -> None:
            super().__init__()
            for name, (in_c, out_c, dilation) in LAYERS.items():
                conv = nn.Conv3d(in_c, out_c, 3, padding=dilation, dilation=dilation)
                setattr(self, name, conv)

        def forward(self, x):
            occupancy = x[:, :1]
            band = torch.nn.functional.max_pool3d(occupancy, 2 * SPREAD + 1, 1, SPREAD)
            for i, name in enumerate(LAYERS):
                x = getattr(self, name)(x) * band
                if i < len(LAYERS) - 1:
                    x = torch.relu(x)
            return torch.nn.functional.normalize(x * occupancy, dim=1)

    return DenseFcgf()


def grid_inputs(grids: np.ndarray) -> np.ndarray:
    """The network's input (B, 2, D, H, W) of occupancy grids (B, D, H, W): occupancy, and
    at occupied cells the height above the grid's lowest occupied cell (`fcgf.cell_inputs`)."""
    grids = np.asarray(grids, dtype=np.float32)
    out = np.zeros((len(grids), 2, *grids.shape[1:]), dtype=np.float32)
    for i, grid in enumerate(grids):
        cells = np.argwhere(grid > 0)
        if len(cells):
            out[i, :, cells[:, 0], cells[:, 1], cells[:, 2]] = cell_inputs(cells)
    return out


def state_to_numpy(net) -> dict[str, np.ndarray]:
    """Parameters under the names `fcgf.cell_features` uses."""
    return layer_weights(net, LAYERS)


load_into = load_layer_weights  # numpy weights into a torch model (the numpy-versus-torch test)


@dataclass(frozen=True)
class Crop:
    """A crop's occupancy grid and the map from world points to its cells."""

    grid: np.ndarray  # (CROP, CROP, CROP) float32
    rotation: np.ndarray  # 3x3, world -> crop (about z)
    origin: np.ndarray  # world point of the crop's corner (after rotation)

    def cells_of(self, world: np.ndarray) -> np.ndarray:
        return np.floor(((world - self.origin) @ self.rotation.T) / VOXEL).astype(np.int64)

    def world_of(self, cells: np.ndarray) -> np.ndarray:
        return ((cells + 0.5) * VOXEL) @ self.rotation + self.origin


def make_crop(points: np.ndarray, centre: np.ndarray, floor: float, rng) -> Crop:
    """A yawed, shifted crop of `points` around `centre` (x, y) from `floor` up."""
    yaw = rng.uniform(-np.pi, np.pi)
    c, s = np.cos(yaw), np.sin(yaw)
    R = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    half = CROP * VOXEL / 2
    corner = np.array([-half, -half, 0.0]) + rng.uniform(0, VOXEL, 3)
    origin = np.array([centre[0], centre[1], floor]) + corner @ R  # world of crop (0, 0, 0)
    crop = Crop(np.zeros((CROP,) * 3, np.float32), R, origin)
    cells = crop.cells_of(points)
    cells = cells[np.all((cells >= 0) & (cells < CROP), axis=1)]
    crop.grid[cells[:, 0], cells[:, 1], cells[:, 2]] = 1.0
    return crop


class PairSampler:
    """Seeded (crop A, crop B, positives) from the training maps."""

    def __init__(self, maps: list[TrainingMap], config: FcgfTrainConfig) -> None:
        self.maps, self.config = maps, config
        self.clouds = [np.vstack([p for p in m.points if len(p)]) for m in maps]
        self.rng = np.random.default_rng([config.seed, 606])

    def one(self) -> tuple[Crop, Crop, np.ndarray, np.ndarray]:
        rng = self.rng
        m = int(rng.integers(len(self.maps)))
        tmap, cloud = self.maps[m], self.clouds[m]
        i = int(rng.integers(len(tmap.labels)))
        floor = float(cloud[:, 2].min())
        centre = tmap.positions[i] + np.array([*rng.normal(0, 0.3, 2), 0.0])
        a = make_crop(cloud, centre, floor, rng)
        if rng.random() < self.config.local_share:
            seen = np.vstack(local_view(tmap, i, rng)[0])
        else:  # the map itself, thinned and noisy: invariance to the turn and the cell grid
            seen = cloud[rng.random(len(cloud)) < rng.uniform(0.3, 1.0)]
            seen = seen + rng.normal(scale=0.01, size=seen.shape)
        b = make_crop(seen, centre, floor, rng)
        b_cells = np.argwhere(b.grid > 0)
        in_a = a.cells_of(b.world_of(b_cells))
        ok = np.all((in_a >= 0) & (in_a < CROP), axis=1)
        ok[ok] = a.grid[in_a[ok, 0], in_a[ok, 1], in_a[ok, 2]] > 0
        b_cells, in_a = b_cells[ok], in_a[ok]
        pick = rng.choice(len(b_cells), min(len(b_cells), self.config.positives), replace=False)
        return a, b, in_a[pick], b_cells[pick]


def contrastive_loss(fa, fb, world, config: FcgfTrainConfig):
    """FCGF's hardest-contrastive loss of matching rows fa, fb (K, 32) at true positions
    `world` (K, 3)."""
    import torch

    positive = torch.relu(torch.norm(fa - fb, dim=1) - config.positive_margin) ** 2
    distance = torch.cdist(fa, fb)
    far = torch.cdist(world, world) > config.negative_distance
    big = torch.tensor(1e6)
    hardest_a = torch.where(far, distance, big).min(dim=1).values
    hardest_b = torch.where(far, distance, big).min(dim=0).values
    negative = (torch.relu(config.negative_margin - hardest_a) ** 2).mean()
    negative = negative + (torch.relu(config.negative_margin - hardest_b) ** 2).mean()
    return positive.mean() + 0.5 * negative, float(torch.norm(fa - fb, dim=1).mean().detach())


def train(
    config: FcgfTrainConfig, log: Callable[[str], None] = print
) -> tuple[dict[str, np.ndarray], dict]:
    """Train; return the numpy weights and a summary (losses, time)."""
    torch = seeded_torch(config.seed, config.threads)
    start = time.perf_counter()
    sampler = PairSampler(training_maps(config.worlds, log), config)
    log(f"data: {len(sampler.maps)} maps ({time.perf_counter() - start:.0f} s)")
    net = build_model()
    optimiser = torch.optim.Adam(net.parameters(), lr=config.lr)
    losses = []
    for epoch in range(config.epochs):
        totals = np.zeros(2)
        for _ in range(config.batches_per_epoch):
            samples = [sampler.one() for _ in range(config.pairs)]
            grids = grid_inputs(np.stack([c.grid for s in samples for c in s[:2]]))
            features = net(torch.from_numpy(grids))
            loss = torch.zeros(())
            distance = 0.0
            for k, (a, _, ca, cb) in enumerate(samples):
                fa = features[2 * k, :, ca[:, 0], ca[:, 1], ca[:, 2]].T
                fb = features[2 * k + 1, :, cb[:, 0], cb[:, 1], cb[:, 2]].T
                world = torch.from_numpy(a.world_of(ca).astype(np.float32))
                part, d = contrastive_loss(fa, fb, world, config)
                loss = loss + part / config.pairs
                distance += d / config.pairs
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
            totals += (loss.item(), distance)
        totals /= config.batches_per_epoch
        losses.append(totals.tolist())
        log(f"epoch {epoch + 1}/{config.epochs}: loss {totals[0]:.4f}, "
            f"positive distance {totals[1]:.3f}")  # fmt: skip
    summary = {"seconds": time.perf_counter() - start, "losses": losses, "config": config.__dict__}
    return state_to_numpy(net), summary
