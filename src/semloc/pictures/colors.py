"""The colour of each label, the same in the PNG pictures, PLY exports and Rerun recordings.

The simulator's classes have fixed colours (`CLASS_COLORS`); other labels, in sorted order,
each take the candidate colour least like all those already used in the picture (distance in
CIELAB, where it follows perceived difference), so that within one picture every label has its
own, clearly different colour.  Pure Python: no plotting library is needed to colour an export.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterable

CLASS_COLORS = {
    "chair": "#2ca02c", "table": "#8c564b", "desk": "#d62728", "sofa": "#9467bd",
    "armchair": "#c5b0d5", "coffee_table": "#c49c94", "bed": "#ff7f0e", "nightstand": "#ffbb78",
    "cabinet": "#1f77b4", "low_cabinet": "#aec7e8", "bookshelf": "#17becf", "monitor": "#e377c2",
    "tv": "#7f7f7f", "lamp": "#bcbd22", "plant": "#98df8a", "refrigerator": "#393b79",
    "toilet": "#9edae5", "sink": "#637939", "whiteboard": "#843c39",
}  # fmt: skip
"""Fixed colours of the simulator's classes, so a class looks the same in every picture."""


def rgb(color: str) -> tuple[int, int, int]:
    """A `#rrggbb` colour as 0-255 integers."""
    return int(color[1:3], 16), int(color[3:5], 16), int(color[5:7], 16)


LEVELS = (0, 51, 102, 153, 204, 255)
"""Channel values of the candidate colours for labels without a fixed one (a 6x6x6 grid)."""
LIGHTNESS = (25.0, 80.0)
"""CIELAB lightness range of candidates: darker looks black, lighter vanishes on white."""


@functools.cache
def _lab(color: str) -> tuple[float, float, float]:
    """A `#rrggbb` colour in CIELAB (D65), where distances follow perceived differences."""

    def linear(c: float) -> float:
        return c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4

    r, g, b = (linear(v / 255) for v in rgb(color))
    xyz = (
        (0.4124 * r + 0.3576 * g + 0.1805 * b) / 0.95047,
        0.2126 * r + 0.7152 * g + 0.0722 * b,
        (0.0193 * r + 0.1192 * g + 0.9505 * b) / 1.08883,
    )
    fx, fy, fz = (t ** (1 / 3) if t > 0.008856 else 7.787 * t + 16 / 116 for t in xyz)
    return 116 * fy - 16, 500 * (fx - fy), 200 * (fy - fz)


def color_distance(a: str, b: str) -> float:
    """Perceived difference of two colours (CIE76 ΔE: about 2 is just noticeable)."""
    return math.dist(_lab(a), _lab(b))


CANDIDATES = [
    color
    for color in (f"#{r:02x}{g:02x}{b:02x}" for r in LEVELS for g in LEVELS for b in LEVELS)
    if LIGHTNESS[0] <= _lab(color)[0] <= LIGHTNESS[1]
]
"""Colours a label without a fixed one can get."""


def _farthest(used: list[str]) -> str:
    """The candidate farthest (least similar) from every colour in `used`; the first on ties."""
    labs = [_lab(c) for c in used]
    return max(CANDIDATES, key=lambda c: min((math.dist(_lab(c), u) for u in labs), default=0.0))


def label_colors(labels: Iterable[str], known: dict[str, str] | None = None) -> dict[str, str]:
    """A distinct hex colour per label (sorted): fixed for known classes, else the candidate
    least like every colour handed out so far (so ~30 labels stay told apart).

    With `known` (colours already handed out), those labels keep theirs and new labels take
    colours unlike them (for labels that appear later, as in a growing local map)."""
    known = dict(known or {})
    names = sorted(set(labels) | set(known))
    colors = {label: CLASS_COLORS[label] for label in names if label in CLASS_COLORS}
    colors.update(known)
    used = list(colors.values())
    for label in names:
        if label not in colors:
            colors[label] = _farthest(used)
            used.append(colors[label])
    return {label: colors[label] for label in names}
