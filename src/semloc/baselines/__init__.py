"""The comparison methods, one registry: every method the benchmark can run, by name.

Each entry builds a `Relocalizer` (the Localizer's interface: `update(objects, answer=True)
-> semloc.results.Result`) from a global map, the local frame's `up` and settings (fields of
its config: `LocalizerConfig` for semloc and its descriptor variants, the baseline's config
class otherwise).  All poses come from `semloc.pose`, all decisions from `semloc.decision`.
The CLI's `--methods` choices, the defaults of `semloc bench` and the plot colours come from
here.  Adding a baseline: a module with an `ObjectBaseline` subclass, and one line below.

Image methods (`Method.images`, e.g. SIFT) are built on the global map's keyframes
(`semloc.frontend.frames.KeyframeMap`) instead of an `ObjectMap`, and are fed query keyframes
(`ImageRelocalizer.update_frames`); `make_method` says so when given the wrong kind of map.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from semloc.association import DESCRIBERS
from semloc.baselines.base import BaselineConfig, ImageRelocalizer, ObjectBaseline, Relocalizer
from semloc.baselines.clipper import ClipperBaseline
from semloc.baselines.fcgf import FcgfDenseBaseline
from semloc.baselines.fpfh import FpfhRansacBaseline
from semloc.baselines.randomwalk import RandomWalkBaseline
from semloc.baselines.segmatch import SegMatchBaseline
from semloc.baselines.sift import SiftBaseline
from semloc.baselines.svl import SvlBaseline
from semloc.frontend.frames import KeyframeMap
from semloc.localizer import Localizer, LocalizerConfig
from semloc.maps import ObjectMap


@dataclass(frozen=True)
class Method:
    """A registered method: how to build it, its plot colour, whether `bench` runs it by
    default, and whether it localizes images (built on a `KeyframeMap`) rather than objects."""

    name: str
    build: Callable[[Any, Any, dict[str, Any]], Any]
    color: str
    default: bool = True
    images: bool = False


def _semloc(**fixed: Any) -> Callable[[ObjectMap, Any, dict[str, Any]], Relocalizer]:
    def build(global_map: ObjectMap, local_up: Any, settings: dict[str, Any]) -> Relocalizer:
        return Localizer(global_map, LocalizerConfig(**{**settings, **fixed}), local_up)

    return build


def _baseline(cls: type[ObjectBaseline]) -> Callable[[ObjectMap, Any, dict[str, Any]], Relocalizer]:
    def build(global_map: ObjectMap, local_up: Any, settings: dict[str, Any]) -> Relocalizer:
        return cls(global_map, cls.config_class(**settings), local_up)

    return build


def _image_baseline(
    cls: type[SiftBaseline],
) -> Callable[[KeyframeMap, Any, dict[str, Any]], ImageRelocalizer]:
    def build(keyframes: KeyframeMap, local_up: Any, settings: dict[str, Any]) -> ImageRelocalizer:
        return cls(keyframes, cls.config_class(**settings), local_up)

    return build


METHODS: dict[str, Method] = {
    m.name: m
    for m in (
        Method("semloc", _semloc(), "black"),
        Method("clipper", _baseline(ClipperBaseline), "C0"),
        Method("random-walk", _baseline(RandomWalkBaseline), "C1"),
        Method("segmatch", _baseline(SegMatchBaseline), "C2"),
        Method("fpfh-ransac", _baseline(FpfhRansacBaseline), "C3"),
        Method("svl", _baseline(SvlBaseline), "C6"),
        Method("fcgf-dense", _baseline(FcgfDenseBaseline), "C9"),
        Method("sift", _image_baseline(SiftBaseline), "C8", images=True),
        *(
            Method(f"semloc+{kind}", _semloc(descriptor=kind), f"C{4 + i}", default=False)
            for i, kind in enumerate(DESCRIBERS)
        ),
    )
}
DEFAULT_METHODS: tuple[str, ...] = tuple(name for name, m in METHODS.items() if m.default)
VARIANTS: tuple[str, ...] = tuple(name for name, m in METHODS.items() if not m.default)
"""Opt-in methods: semloc with the shape-descriptor gate of each registered kind."""


IMAGE_METHODS: tuple[str, ...] = tuple(name for name, m in METHODS.items() if m.images)
"""Methods that localize images against a map's keyframes."""


def make_method(
    name: str,
    global_map: ObjectMap | KeyframeMap,
    local_up: Any,
    settings: dict[str, Any] | None = None,
) -> Relocalizer | ImageRelocalizer:
    """The method `name` on `global_map` with `settings` (its config's fields, flat): an
    `ObjectMap` for the object methods, a `KeyframeMap` for the image methods."""
    if name not in METHODS:
        raise ValueError(f"unknown method {name!r}; choose from {', '.join(METHODS)}")
    method = METHODS[name]
    if method.images and not isinstance(global_map, KeyframeMap):
        raise ValueError(
            f"{name} localizes images: it needs the global map's keyframes (a KeyframeMap of "
            f"colour images, depth, intrinsics and poses), got {type(global_map).__name__}; "
            "object maps have no images"
        )
    if not method.images and isinstance(global_map, KeyframeMap):
        raise ValueError(f"{name} localizes objects: it needs an ObjectMap, got a KeyframeMap")
    return method.build(global_map, local_up, dict(settings or {}))


__all__ = [
    "DEFAULT_METHODS",
    "IMAGE_METHODS",
    "METHODS",
    "VARIANTS",
    "BaselineConfig",
    "ClipperBaseline",
    "FcgfDenseBaseline",
    "FpfhRansacBaseline",
    "ImageRelocalizer",
    "Method",
    "ObjectBaseline",
    "RandomWalkBaseline",
    "Relocalizer",
    "SegMatchBaseline",
    "SiftBaseline",
    "SvlBaseline",
    "make_method",
]
