"""Illumination models for the day / night experiment: relighting rendered daylight images.

The simulator renders every image under daylight (`semloc.sim.colour`).  A query taken under
another illumination is that image passed through this model, pixel by pixel, with x the
daylight colour in [0, 1] and z the pixel's depth (m):

1. light: x * exposure * white_balance * 1 / (1 + (z / falloff)^2) — a dim, warm artificial
   light carried at the camera replaces the daylight (the falloff term; none for `day`),
   tungsten white balance (red kept, blue cut);
2. sensor noise: shot noise (Gaussian, variance `shot_noise` * signal) plus read noise
   (`read_noise`), then clipping to [0, 1];
3. tone curve: y = x ** gamma (gamma > 1 crushes the shadows), and 8-bit quantisation.

`NIGHT` darkens an image to about a fifth of its mean brightness with strong noise in the
dark parts; `DAY` is the identity.  Relighting is deterministic for a given random generator
(the evaluation seeds one per keyframe).  Depth is unchanged: an RGB-D sensor's depth does not
depend on visible light.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from semloc.frontend.frames import RGBDFrame


@dataclass(frozen=True)
class Illumination:
    """One illumination (see the module docstring for the model)."""

    name: str
    exposure: float = 1.0
    white_balance: tuple[float, float, float] = (1.0, 1.0, 1.0)
    falloff: float | None = None  # metres; None: uniform light
    shot_noise: float = 0.0
    read_noise: float = 0.0
    gamma: float = 1.0

    @property
    def identity(self) -> bool:
        return self == Illumination(self.name)


DAY = Illumination("day")
NIGHT = Illumination(
    "night", exposure=1.0, white_balance=(1.0, 0.72, 0.42), falloff=2.5,
    shot_noise=0.003, read_noise=0.015, gamma=1.3,
)  # fmt: skip
ILLUMINATIONS: dict[str, Illumination] = {"day": DAY, "night": NIGHT}


def relight(frame: RGBDFrame, light: Illumination, rng: np.random.Generator) -> RGBDFrame:
    """`frame` (rendered under daylight) as seen under `light`; its depth unchanged."""
    if light.identity:
        return frame
    x = frame.rgb.astype(np.float64) / 255.0
    gain = light.exposure * np.asarray(light.white_balance)
    if light.falloff is not None:
        z = np.asarray(frame.depth, dtype=np.float64)[..., None]
        gain = gain / (1.0 + (z / light.falloff) ** 2)
    x = x * gain
    sigma = np.sqrt(light.shot_noise * x + light.read_noise**2)
    x = np.clip(x + rng.normal(size=x.shape) * sigma, 0.0, 1.0) ** light.gamma
    rgb = np.round(x * 255.0).astype(np.uint8)
    return replace(frame, rgb=rgb)
