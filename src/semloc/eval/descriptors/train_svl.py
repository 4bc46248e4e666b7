"""Training of the SVL-style semantic volume VAE (torch; the `train` extra only).

    semloc train-descriptor --kind svl --out svl_weights.npz --seed 0

As in SVL (Schönberger et al., CVPR 2018), the auto-encoder learns to *complete* a partial
local observation into the whole scene: every sample is the semantic volume
(`semloc.descriptors.svl.volumes`) around an object of a training world's global map
(`semloc.eval.descriptors.worlds`), at a random yaw; the input is the volume of a simulated
local map around that object (a part of its neighbours, each seen from one side; a quarter of
the inputs are the complete volume itself, which is what global-map descriptors encode), the
target the complete volume.  Loss: the variational bound, per-cell binary cross-entropy of the
class channels (occupied cells weighted `positive_weight`) plus the KL divergence of the latent
code; the descriptor is the encoder's mean.

Seeded, one thread, deterministic algorithms: the same arguments give the same weights.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from semloc.descriptors.svl import CHANNELS, FLAT, LATENT, LAYERS, scene_points, volumes
from semloc.eval.descriptors.train import layer_weights, load_layer_weights, seeded_torch
from semloc.eval.descriptors.worlds import TrainingMap, local_view, training_maps


@dataclass(frozen=True)
class SvlTrainConfig:
    seed: int = 0
    worlds: int = 8
    epochs: int = 10
    batches_per_epoch: int = 60
    batch: int = 32
    complete_share: float = 0.25
    positive_weight: float = 4.0
    beta: float = 1.0
    lr: float = 1e-3
    threads: int = 1


def build_model():
    """The torch VAE; its encoder (conv1, conv2, mu) is what `svl.encode` runs in numpy."""
    import torch
    import torch.nn as nn

    class SvlVae(nn.Module):
        def __init__(self) -> None:
            super().__init__()
            for name, (in_c, out_c, k, stride, pad) in LAYERS.items():
                setattr(self, name, nn.Conv3d(in_c, out_c, k, stride=stride, padding=pad))
            self.mu = nn.Linear(FLAT, LATENT)
            self.logvar = nn.Linear(FLAT, LATENT)
            self.expand = nn.Linear(LATENT, FLAT)
            self.up1 = nn.ConvTranspose3d(64, 32, 4, stride=2, padding=1)
            self.up2 = nn.ConvTranspose3d(32, CHANNELS, 4, stride=2, padding=1)

        def encode(self, x):
            for name in LAYERS:
                x = torch.relu(getattr(self, name)(x))
            x = x.flatten(1)
            return self.mu(x), self.logvar(x)

        def decode(self, z):
            x = torch.relu(self.expand(z)).view(len(z), 64, 5, 5, 3)
            return self.up2(torch.relu(self.up1(x)))

        def forward(self, x, noise):
            mu, logvar = self.encode(x)
            z = mu + noise * torch.exp(0.5 * logvar)
            return self.decode(z), mu, logvar

    return SvlVae()


def state_to_numpy(net) -> dict[str, np.ndarray]:
    """The encoder's parameters under the names `svl.encode` uses."""
    return layer_weights(net, [*LAYERS, "mu"])


load_into = load_layer_weights  # numpy weights into a torch model (the numpy-versus-torch test)


class Sampler:
    """Seeded (input, target) volume pairs from the training maps."""

    def __init__(self, maps: list[TrainingMap], config: SvlTrainConfig) -> None:
        self.maps = maps
        self.config = config
        self.scenes = [scene_points(m.points, m.labels) for m in maps]
        self.rng = np.random.default_rng([config.seed, 505])

    def one(self) -> tuple[np.ndarray, np.ndarray]:
        rng = self.rng
        m = int(rng.integers(len(self.maps)))
        tmap, (points, channels) = self.maps[m], self.scenes[m]
        i = int(rng.integers(len(tmap.labels)))
        yaw = float(rng.uniform(-np.pi, np.pi))
        floor = float(points[:, 2].min())
        target = volumes(points, channels, tmap.positions[i], [yaw], floor)[0]
        if rng.random() < self.config.complete_share:
            return target, target
        local_points, labels = local_view(tmap, i, rng)
        if not local_points:
            return target, target
        lp, lc = scene_points(local_points, labels)
        centre = local_points[0].mean(axis=0)
        return volumes(lp, lc, centre, [yaw])[0], target

    def batch(self, size: int) -> tuple[np.ndarray, np.ndarray]:
        pairs = [self.one() for _ in range(size)]
        return np.stack([p[0] for p in pairs]), np.stack([p[1] for p in pairs])


def train(
    config: SvlTrainConfig, log: Callable[[str], None] = print
) -> tuple[dict[str, np.ndarray], dict]:
    """Train; return the encoder's numpy weights and a summary (losses, time)."""
    torch = seeded_torch(config.seed, config.threads)
    start = time.perf_counter()
    sampler = Sampler(training_maps(config.worlds, log), config)
    log(f"data: {len(sampler.maps)} maps ({time.perf_counter() - start:.0f} s)")
    net = build_model()
    optimiser = torch.optim.Adam(net.parameters(), lr=config.lr)
    weight = torch.tensor(config.positive_weight)
    losses = []
    for epoch in range(config.epochs):
        totals = np.zeros(2)
        for _ in range(config.batches_per_epoch):
            x, y = (torch.from_numpy(a) for a in sampler.batch(config.batch))
            noise = torch.randn(len(x), LATENT)
            logits, mu, logvar = net(x, noise)
            recon = torch.nn.functional.binary_cross_entropy_with_logits(
                logits, y, pos_weight=weight, reduction="sum"
            ) / len(x)
            kl = -0.5 * torch.sum(1 + logvar - mu**2 - logvar.exp()) / len(x)
            loss = recon + config.beta * kl
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
            totals += (recon.item(), kl.item())
        totals /= config.batches_per_epoch
        losses.append(totals.tolist())
        log(
            f"epoch {epoch + 1}/{config.epochs}: reconstruction {totals[0]:.1f}, KL {totals[1]:.1f}"
        )
    summary = {"seconds": time.perf_counter() - start, "losses": losses, "config": config.__dict__}
    return state_to_numpy(net), summary
