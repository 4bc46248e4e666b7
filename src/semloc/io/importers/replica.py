"""Replica importer: objects from the oriented boxes of an `info_semantic.json`.

The file has `objects[*]` = `{id, class_name, oriented_bbox: {abb: {center, sizes},
orientation: {rotation: [x, y, z, w], translation}}}` and `gravity_dir`.  A box's centre in the
scene frame is `R @ abb.center + translation` with `R` the rotation quaternion (scalar last, as
Replica and habitat-sim store it); its axes are the columns of `R` and its extents `abb.sizes`.
Each object gets points sampled uniformly on its box surface.  `up` = -`gravity_dir`.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from semloc.io.geometry import quaternion_matrix, sample_box_surface
from semloc.io.importers.base import Importer, Maps
from semloc.io.labels import is_structural, is_unlabeled
from semloc.io.reading import read_json
from semloc.maps import MapError, ObjectMap, SemanticObject, unit_vector


def load_replica(
    path: str | os.PathLike[str],
    *,
    include_structure: bool = False,
    keep_unlabeled: bool = False,
    density: float = 200.0,
    max_points: int = 1000,
    seed: int = 0,
) -> ObjectMap:
    """Objects of a Replica `info_semantic.json` (or a folder holding one).

    Walls, floors and ceilings are left out unless `include_structure`; placeholder classes
    (undefined, non-plane) unless `keep_unlabeled`.  Each box surface gets `density` points per
    square metre (at least 20, at most `max_points`), drawn with `seed`.
    """
    path = Path(path)
    if path.is_dir():
        path = path / "info_semantic.json"
    document = read_json(path)
    if not isinstance(document, dict) or not isinstance(document.get("objects"), list):
        raise MapError(f"{path}: missing key 'objects' (a list)")
    up = _up(document, path)
    rng = np.random.default_rng(seed)
    objects = []
    for index, raw in enumerate(document["objects"]):
        where = f"{path}: objects[{index}]"
        label = _class_name(raw, where)
        if not include_structure and is_structural(label):
            continue
        if not keep_unlabeled and is_unlabeled(label):
            continue
        centre, size, rotation = _box(raw, where)
        area = 2 * (size[0] * size[1] + size[1] * size[2] + size[0] * size[2])
        count = int(np.clip(round(area * density), 20, max_points))
        objects.append(
            SemanticObject(
                id=str(raw["id"]),
                label=label,
                position=centre,
                size=size,
                rotation=rotation,
                points=sample_box_surface(centre, size, rotation, count, rng),
            )
        )
    try:
        return ObjectMap(objects, up=up, name=path.parent.name)
    except MapError as exc:
        raise MapError(f"{path}: {exc}") from None


def _up(document: dict[str, Any], path: Path) -> np.ndarray | None:
    gravity = document.get("gravity_dir")
    if gravity is None:
        return None
    try:
        return -unit_vector(gravity, "'gravity_dir'")
    except MapError as exc:
        raise MapError(f"{path}: {exc}") from None


def _class_name(raw: Any, where: str) -> str:
    if not isinstance(raw, dict):
        raise MapError(f"{where}: must be an object")
    for key in ("id", "class_name", "oriented_bbox"):
        if key not in raw:
            raise MapError(f"{where}: missing key '{key}'")
    if not isinstance(raw["class_name"], str) or not raw["class_name"].strip():
        raise MapError(f"{where}: class_name must be a non-empty string")
    if isinstance(raw["id"], bool) or not isinstance(raw["id"], (int, str)):
        raise MapError(f"{where}: id must be an integer or a string")
    return raw["class_name"]


def _box(raw: dict[str, Any], where: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    box = raw["oriented_bbox"]
    try:
        centre = _vector(box["abb"]["center"], 3)
        size = _vector(box["abb"]["sizes"], 3)
        orientation = box["orientation"]
        x, y, z, w = _vector(orientation["rotation"], 4)
        translation = _vector(orientation.get("translation", [0, 0, 0]), 3)
        rotation = quaternion_matrix(w, x, y, z)
    except (KeyError, TypeError) as exc:
        raise MapError(f"{where}: oriented_bbox lacks {exc}") from None
    except ValueError as exc:
        raise MapError(f"{where}: bad oriented_bbox ({exc})") from None
    if np.any(size < 0):
        raise MapError(f"{where}: negative box size")
    return rotation @ centre + translation, size, rotation


def _vector(value: Any, length: int) -> np.ndarray:
    array = np.asarray(value, dtype=float)
    if array.shape != (length,) or not np.all(np.isfinite(array)):
        raise ValueError(f"expected {length} finite numbers, got {value!r:.60}")
    return array


def _convert(source, *, labels, include_structure, voxel, seed, keep_unlabeled) -> Maps:
    if labels is not None:
        raise ValueError("replica has one label vocabulary; --labels does not apply")
    objmap = load_replica(
        source, include_structure=include_structure, keep_unlabeled=keep_unlabeled, seed=seed
    )
    return objmap, None


IMPORTER = Importer(
    "replica", _convert, "info_semantic.json or its folder", None, frozenset({"keep_unlabeled"})
)
