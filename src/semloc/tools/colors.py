"""The colour of each label, the same in the PNG pictures, PLY exports and Rerun recordings.

The simulator's classes have fixed colours (`CLASS_COLORS`); other labels take palette colours
in sorted order, skipping colours already used, so that within one picture every label has its
own colour.  Pure Python: no plotting library is needed to colour an export.
"""

from __future__ import annotations

import colorsys
import itertools
from collections.abc import Iterable

CLASS_COLORS = {
    "chair": "#2ca02c", "table": "#8c564b", "desk": "#d62728", "sofa": "#9467bd",
    "armchair": "#c5b0d5", "coffee_table": "#c49c94", "bed": "#ff7f0e", "nightstand": "#ffbb78",
    "cabinet": "#1f77b4", "low_cabinet": "#aec7e8", "bookshelf": "#17becf", "monitor": "#e377c2",
    "tv": "#7f7f7f", "lamp": "#bcbd22", "plant": "#98df8a", "refrigerator": "#393b79",
    "toilet": "#9edae5", "sink": "#637939", "whiteboard": "#843c39",
}  # fmt: skip
"""Fixed colours of the simulator's classes, so a class looks the same in every picture."""

PALETTE = [
    "#ff9896", "#f7b6d2", "#dbdb8d", "#c7c7c7", "#5254a3", "#8ca252", "#bd9e39", "#ad494a",
    "#a55194", "#6b6ecf", "#b5cf6b", "#e7ba52", "#d6616b", "#ce6dbd", "#3182bd", "#e6550d",
    "#31a354", "#756bb1", "#636363", "#fd8d3c",
]  # fmt: skip
"""Colours for labels without a fixed one, all different from the fixed colours."""


def _more_colors(start: int) -> Iterable[str]:
    """Further distinct colours (golden-ratio hues) once the palette is used up."""
    i = start
    while True:
        r, g, b = colorsys.hsv_to_rgb((i * 0.618034) % 1.0, 0.65, 0.85)
        yield f"#{round(r * 255):02x}{round(g * 255):02x}{round(b * 255):02x}"
        i += 1


def label_colors(labels: Iterable[str], known: dict[str, str] | None = None) -> dict[str, str]:
    """A distinct hex colour per label (sorted): fixed for known classes, else the palette's.

    With `known` (colours already handed out), those labels keep theirs and new labels take
    colours not used yet (for labels that appear later, as in a growing local map)."""
    known = dict(known or {})
    names = sorted(set(labels) | set(known))
    colors = {label: CLASS_COLORS[label] for label in names if label in CLASS_COLORS}
    colors.update(known)
    used = set(colors.values())
    free = (c for c in itertools.chain(PALETTE, _more_colors(0)) if c not in used)
    for label in names:
        if label not in colors:
            colors[label] = next(free)
    return {label: colors[label] for label in names}


def rgb(color: str) -> tuple[int, int, int]:
    """A `#rrggbb` colour as 0-255 integers."""
    return int(color[1:3], 16), int(color[3:5], 16), int(color[5:7], 16)
