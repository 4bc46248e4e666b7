"""Comparison methods behind the Localizer's interface: `Method(global_map, config, local_up)`
and `.update(objects) -> semloc.localizer.Result`.  All poses come from `semloc.pose`.

METHODS maps the benchmark names to factories (the Localizer is "semloc")."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from semloc.baselines.clipper import ClipperBaseline
from semloc.baselines.common import BaselineConfig, ObjectBaseline
from semloc.baselines.fpfh import FpfhRansacBaseline
from semloc.baselines.randomwalk import RandomWalkBaseline
from semloc.baselines.segmatch import SegMatchBaseline


def _semloc(global_map, config=None, local_up=None):
    from semloc.localizer import Localizer

    return Localizer(global_map, config, local_up=local_up)


METHODS: dict[str, Callable[..., Any]] = {
    "semloc": _semloc,
    "clipper": ClipperBaseline,
    "random-walk": RandomWalkBaseline,
    "segmatch": SegMatchBaseline,
    "fpfh-ransac": FpfhRansacBaseline,
}

__all__ = [
    "METHODS",
    "BaselineConfig",
    "ClipperBaseline",
    "FpfhRansacBaseline",
    "ObjectBaseline",
    "RandomWalkBaseline",
    "SegMatchBaseline",
]
