"""The comparison methods, one registry: every method the benchmark can run, by name.

Each entry builds a `Relocalizer` (the Localizer's interface: `update(objects, answer=True)
-> semloc.results.Result`) from a global map, the local frame's `up` and settings (fields of
its config: `LocalizerConfig` for semloc and its descriptor variants, the baseline's config
class otherwise).  All poses come from `semloc.pose`, all decisions from `semloc.decision`.
The CLI's `--methods` choices, the defaults of `semloc bench` and the plot colours come from
here.  Adding a baseline: a module with an `ObjectBaseline` subclass, and one line below.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from semloc.association import DESCRIBERS
from semloc.baselines.base import BaselineConfig, ObjectBaseline, Relocalizer
from semloc.baselines.clipper import ClipperBaseline
from semloc.baselines.fcgf import FcgfDenseBaseline
from semloc.baselines.fpfh import FpfhRansacBaseline
from semloc.baselines.randomwalk import RandomWalkBaseline
from semloc.baselines.segmatch import SegMatchBaseline
from semloc.baselines.svl import SvlBaseline
from semloc.localizer import Localizer, LocalizerConfig
from semloc.maps import ObjectMap


@dataclass(frozen=True)
class Method:
    """A registered method: how to build it, its plot colour, and whether `bench` runs it
    by default."""

    name: str
    build: Callable[[ObjectMap, Any, dict[str, Any]], Relocalizer]
    color: str
    default: bool = True


def _semloc(**fixed: Any) -> Callable[[ObjectMap, Any, dict[str, Any]], Relocalizer]:
    def build(global_map: ObjectMap, local_up: Any, settings: dict[str, Any]) -> Relocalizer:
        return Localizer(global_map, LocalizerConfig(**{**settings, **fixed}), local_up)

    return build


def _baseline(cls: type[ObjectBaseline]) -> Callable[[ObjectMap, Any, dict[str, Any]], Relocalizer]:
    def build(global_map: ObjectMap, local_up: Any, settings: dict[str, Any]) -> Relocalizer:
        return cls(global_map, cls.config_class(**settings), local_up)

    return build


METHODS: dict[str, Method] = {
    m.name: m
    for m in (
        Method("semloc", _semloc(), "black"),
        Method("clipper", _baseline(ClipperBaseline), "C0"),
        Method("random-walk", _baseline(RandomWalkBaseline), "C1"),
        Method("segmatch", _baseline(SegMatchBaseline), "C2"),
        Method("fpfh-ransac", _baseline(FpfhRansacBaseline), "C3"),
        Method("svl", _baseline(SvlBaseline), "C8"),
        Method("fcgf-dense", _baseline(FcgfDenseBaseline), "C9"),
        *(
            Method(f"semloc+{kind}", _semloc(descriptor=kind), f"C{4 + i}", default=False)
            for i, kind in enumerate(DESCRIBERS)
        ),
    )
}
DEFAULT_METHODS: tuple[str, ...] = tuple(name for name, m in METHODS.items() if m.default)
VARIANTS: tuple[str, ...] = tuple(name for name, m in METHODS.items() if not m.default)
"""Opt-in methods: semloc with the shape-descriptor gate of each registered kind."""


def make_method(
    name: str, global_map: ObjectMap, local_up: Any, settings: dict[str, Any] | None = None
) -> Relocalizer:
    """The method `name` on `global_map` with `settings` (its config's fields, flat)."""
    if name not in METHODS:
        raise ValueError(f"unknown method {name!r}; choose from {', '.join(METHODS)}")
    return METHODS[name].build(global_map, local_up, dict(settings or {}))


__all__ = [
    "DEFAULT_METHODS",
    "METHODS",
    "VARIANTS",
    "BaselineConfig",
    "ClipperBaseline",
    "FcgfDenseBaseline",
    "FpfhRansacBaseline",
    "Method",
    "ObjectBaseline",
    "RandomWalkBaseline",
    "Relocalizer",
    "SegMatchBaseline",
    "SvlBaseline",
    "make_method",
]
