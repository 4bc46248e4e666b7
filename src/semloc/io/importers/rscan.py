"""3RScan / SGAligner importer: one object per `objectId` of a structured `data.npy`.

The file is a numpy structured array with one record per point: `x`, `y`, `z` (float),
`objectId` (instance), and class columns `NYU40`, `Eigen13`, `RIO27` (and `globalId`, the
3RScan class id, plus colours).  Each object gets its points (voxel-downsampled), the majority
class of its points in the chosen label set, an upright box and the box centre as position.
The frame is the scan frame, `up` = +z.  Points of `objectId` 0 are unannotated.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from semloc.io.geometry import upright_box
from semloc.io.importers.base import Importer, Maps
from semloc.io.labels import LABEL_SETS, class_name, is_structural, is_unlabeled
from semloc.io.reading import read_npy
from semloc.maps import MapError, ObjectMap, SemanticObject
from semloc.pointsets import voxel_downsample

UP = np.array([0.0, 0.0, 1.0])
_COLUMNS = {"nyu40": "NYU40", "eigen13": "Eigen13", "rio27": "RIO27"}


def load_rscan(
    path: str | os.PathLike[str],
    *,
    labels: str = "nyu40",
    include_structure: bool = False,
    keep_unlabeled: bool = False,
    voxel: float = 0.05,
) -> ObjectMap:
    """Objects of a 3RScan `data.npy` (or a folder holding one).

    `labels`: "nyu40", "eigen13" or "rio27" (class names of that column).  Walls, floors and
    ceilings are left out unless `include_structure`; unannotated objects (objectId 0 or class
    0) unless `keep_unlabeled`.  Points are voxel-downsampled with edge `voxel` metres.
    """
    if labels not in LABEL_SETS:
        raise ValueError(f"labels must be one of {sorted(LABEL_SETS)}, got {labels!r}")
    path = Path(path)
    if path.is_dir():
        path = path / "data.npy"
    data = read_points(path, ("x", "y", "z", "objectId", _COLUMNS[labels]))
    xyz = np.column_stack([data[c] for c in "xyz"]).astype(float)
    if not np.all(np.isfinite(xyz)):
        raise MapError(f"{path}: point coordinates are not all finite")
    object_ids = data["objectId"].astype(np.int64)
    classes = data[_COLUMNS[labels]].astype(np.int64)
    objects = []
    for object_id in np.unique(object_ids):
        mask = object_ids == object_id
        where = f"{path}: objectId {object_id}"
        label = class_name(labels, _majority(classes[mask]), where)
        if not keep_unlabeled and (object_id == 0 or is_unlabeled(label)):
            continue
        if not include_structure and is_structural(label):
            continue
        objects.append(_object(int(object_id), label, xyz[mask], voxel))
    return ObjectMap(objects, up=UP, name=path.parent.name)


def _majority(values: np.ndarray) -> int:
    """The most frequent integer (the smallest among ties)."""
    unique, counts = np.unique(values, return_counts=True)
    return int(unique[np.argmax(counts)])


def read_points(path: Path, required: tuple[str, ...]) -> np.ndarray:
    """Load a structured `.npy` (no pickles) and check it has the `required` fields."""
    data = read_npy(path)
    if not isinstance(data, np.ndarray) or data.dtype.names is None or data.ndim != 1:
        raise MapError(f"{path}: expected a 1-D structured array of points")
    missing = [name for name in required if name not in data.dtype.names]
    if missing:
        raise MapError(f"{path}: missing fields {missing} (has {list(data.dtype.names)})")
    text = [name for name in required if data.dtype[name].kind not in "iuf"]
    if text:
        raise MapError(f"{path}: fields {text} must be numbers, not {data.dtype[text[0]]}")
    return data


def _object(object_id: int, label: str, points: np.ndarray, voxel: float) -> SemanticObject:
    centre, size, rotation = upright_box(points, UP)
    return SemanticObject(
        id=str(object_id),
        label=label,
        position=centre,
        size=size,
        rotation=rotation,
        points=voxel_downsample(points, voxel),
    )


def _convert(source, *, labels, include_structure, voxel, seed, keep_unlabeled) -> Maps:
    objmap = load_rscan(
        source, labels=labels or "nyu40", include_structure=include_structure,
        keep_unlabeled=keep_unlabeled, voxel=voxel,
    )  # fmt: skip
    return objmap, None


IMPORTER = Importer(
    "3rscan", _convert, "data.npy or its folder", "nyu40|rio27|eigen13 (default nyu40)",
    frozenset({"keep_unlabeled"}),
)  # fmt: skip
