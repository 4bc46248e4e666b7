"""ScanNet importer: one object per annotated instance of a ScanNet v2 scene.

A scene folder holds `<scene>_vh_clean_2.ply` (the mesh: float x, y, z per vertex),
`<scene>_vh_clean_2.0.010000.segs.json` (`segIndices`: one over-segment id per vertex),
`<scene>.aggregation.json` (`segGroups[*]` = `{objectId, label, segments}`) and optionally
`<scene>_vh_clean_2.labels.ply` (a per-vertex NYU40 `label`).  A vertex belongs to instance
`objectId` when its segment is in that group's `segments`.  Each object gets the instance's
points (voxel-downsampled), its raw label (or its NYU40 class), an upright oriented box and the
box centre as position.  The frame is the mesh frame, `up` = +z.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from semloc.io.geometry import upright_box
from semloc.io.importers.base import Importer, Maps
from semloc.io.labels import NYU40, is_structural, read_label_map
from semloc.io.ply import read_ply
from semloc.io.reading import read_json, require_keys
from semloc.maps import MapError, ObjectMap, SemanticObject
from semloc.pointsets import voxel_downsample

UP = np.array([0.0, 0.0, 1.0])


def load_scannet(
    scene: str | os.PathLike[str],
    *,
    labels: str = "raw",
    label_map: Mapping[str, str] | None = None,
    include_structure: bool = False,
    voxel: float = 0.05,
) -> ObjectMap:
    """Objects of a ScanNet scene (folder, or its `.aggregation.json`).

    `labels`: "raw" (the annotators' label) or "nyu40" (from `label_map` when given, else the
    majority NYU40 class of the instance's vertices in `.labels.ply`).  `label_map` alone maps
    raw labels (unmapped ones stay raw).  Walls, floors and ceilings are left out unless
    `include_structure`.  Points are voxel-downsampled with edge `voxel` metres (0: all).
    """
    if labels not in ("raw", "nyu40"):
        raise ValueError(f"labels must be 'raw' or 'nyu40', got {labels!r}")
    files = scene_files(scene)
    groups = read_aggregation(files["aggregation"])
    segments = read_segments(files["segs"])
    mesh = read_ply(files["mesh"])
    points = _xyz(mesh.vertices, files["mesh"])
    if len(points) != len(segments):
        raise MapError(
            f"{files['segs']}: {len(segments)} segment indices but the mesh "
            f"{files['mesh'].name} has {len(points)} vertices"
        )
    nyu = None
    if labels == "nyu40" and label_map is None:
        nyu = _vertex_nyu40(files, len(points))
        _check_nyu40(nyu, groups, segments, files["labels"])
    objects = []
    for group in groups:
        vertex_ids = np.flatnonzero(np.isin(segments, group["segments"]))
        if len(vertex_ids) == 0:
            raise MapError(
                f"{files['aggregation']}: objectId {group['objectId']} has no vertex in the mesh"
            )
        label = _label(group["label"], vertex_ids, nyu, label_map)
        if not include_structure and (is_structural(label) or is_structural(group["label"])):
            continue
        objects.append(_object(group, label, points[vertex_ids], voxel))
    return _as_map(objects, files["aggregation"], files["name"])


def scene_files(scene: str | os.PathLike[str]) -> dict[str, Any]:
    """Locate the aggregation, segments, mesh and (optional) label mesh of a scene."""
    path = Path(scene)
    if path.is_file() and path.name.endswith(".aggregation.json"):
        folder, aggregation = path.parent, path
    elif path.is_file():  # another file of the scene (its mesh, segments...): its folder
        folder = path.parent
        aggregation = _one(folder, f"{scene_name(path.name)}*.aggregation.json", path)
    elif path.is_dir():
        folder = path
        found = sorted(folder.glob("*.aggregation.json"))
        if not found:
            raise MapError(f"{folder}: no *.aggregation.json in this folder")
        aggregation = found[0]
    else:
        raise MapError(f"{path}: no such file or folder")
    name = scene_name(aggregation.name)
    return {
        "name": name,
        "aggregation": aggregation,
        "segs": _one(folder, f"{name}_vh_clean_2*.segs.json"),
        "mesh": _one(folder, f"{name}_vh_clean_2.ply"),
        "labels": folder / f"{name}_vh_clean_2.labels.ply",
    }


def scene_name(file_name: str) -> str:
    """The scene a ScanNet file belongs to: `scene0000_00` of `scene0000_00_vh_clean_2.ply`,
    `scene0000_00.aggregation.json` or `scene0000_00_vh_clean.aggregation.json`."""
    stem = file_name.split(".")[0]
    return stem.removesuffix("_vh_clean_2").removesuffix("_vh_clean")


def _one(folder: Path, pattern: str, given: Path | None = None) -> Path:
    found = sorted(folder.glob(pattern))
    if not found and given is not None:
        raise MapError(
            f"{given}: no {pattern} beside it (scannet takes the scene folder or its "
            ".aggregation.json)"
        )
    if not found:
        raise MapError(f"{folder}: missing {pattern}")
    return found[0]


def read_aggregation(path: Path) -> list[dict[str, Any]]:
    """The `segGroups` of an aggregation file, validated (objectId, label, segments)."""
    document = read_json(path)
    if not isinstance(document, dict) or "segGroups" not in document:
        raise MapError(f"{path}: missing key 'segGroups'")
    groups = document["segGroups"]
    if not isinstance(groups, list):
        raise MapError(f"{path}: 'segGroups' must be a list")
    seen: set[int] = set()
    for index, group in enumerate(groups):
        where = f"{path}: segGroups[{index}]"
        require_keys(group, ("objectId", "label", "segments"), where)
        if not isinstance(group["objectId"], int) or group["objectId"] in seen:
            raise MapError(f"{where}: objectId {group['objectId']!r} is not a new integer")
        seen.add(group["objectId"])
        if not isinstance(group["label"], str) or not group["label"].strip():
            raise MapError(f"{where}: label must be a non-empty string")
        if not isinstance(group["segments"], list) or not all(
            isinstance(s, int) for s in group["segments"]
        ):
            raise MapError(f"{where}: segments must be a list of integers")
    return groups


def read_segments(path: Path) -> np.ndarray:
    """The per-vertex segment ids (`segIndices`) of a `.segs.json` file."""
    document = read_json(path)
    if not isinstance(document, dict) or "segIndices" not in document:
        raise MapError(f"{path}: missing key 'segIndices'")
    try:  # no dtype: floats, booleans and strings must not be converted silently
        segments = np.asarray(document["segIndices"])
    except (TypeError, ValueError, OverflowError):
        raise MapError(f"{path}: 'segIndices' must be a list of integers") from None
    if segments.ndim != 1:
        raise MapError(f"{path}: 'segIndices' must be a flat list of integers")
    raw = document["segIndices"]
    booleans = isinstance(raw, list) and any(isinstance(v, bool) for v in raw)
    if booleans or (segments.size and segments.dtype.kind not in "iu"):
        raise MapError(f"{path}: 'segIndices' must be a list of integers")
    return segments.astype(np.int64)


def _xyz(vertices: np.ndarray, path: Path) -> np.ndarray:
    names = vertices.dtype.names or ()
    missing = [c for c in "xyz" if c not in names]
    if missing:
        raise MapError(f"{path}: vertex element lacks properties {missing}")
    points = np.column_stack([vertices[c] for c in "xyz"]).astype(float)
    if not np.all(np.isfinite(points)):
        raise MapError(f"{path}: vertex coordinates are not all finite")
    return points


def _vertex_nyu40(files: dict[str, Any], count: int) -> np.ndarray:
    path = files["labels"]
    if not path.exists():
        raise MapError(f"{path}: missing; NYU40 labels need it or a --label-map")
    vertices = read_ply(path).vertices
    if "label" not in (vertices.dtype.names or ()):
        raise MapError(f"{path}: vertex element has no 'label' property")
    if len(vertices) != count:
        raise MapError(f"{path}: {len(vertices)} vertices but the mesh has {count}")
    return vertices["label"].astype(np.int64)


def _check_nyu40(
    nyu: np.ndarray, groups: list[dict[str, Any]], segments: np.ndarray, path: Path
) -> None:
    """Refuse label meshes whose ids are not NYU40 (some hold ScanNet category ids instead).

    Ids above 40 are not NYU40; and instances whose raw label is itself a NYU40 class name
    must mostly carry that class's id."""
    if nyu.max(initial=0) >= len(NYU40):
        raise MapError(
            f"{path}: per-vertex labels go up to {nyu.max()}, so they are not NYU40 ids "
            "(ScanNet category ids?); give a --label-map instead"
        )
    named = [g for g in groups if g["label"].strip().lower() in NYU40[1:]]
    agree = 0
    for group in named:
        classes = nyu[np.isin(segments, group["segments"])]
        agree += bool(len(classes)) and NYU40[int(np.bincount(classes).argmax())] == (
            group["label"].strip().lower()
        )
    if named and agree < 0.5 * len(named):
        raise MapError(
            f"{path}: per-vertex labels disagree with the NYU40 classes of the aggregation "
            f"({agree} of {len(named)} instances agree), so they are not NYU40 ids; "
            "give a --label-map instead"
        )


def _label(
    raw: str,
    vertex_ids: np.ndarray,
    nyu: np.ndarray | None,
    label_map: Mapping[str, str] | None,
) -> str:
    if label_map is not None:
        return label_map.get(raw.strip().lower(), raw)
    if nyu is None:
        return raw
    classes = nyu[vertex_ids]
    classes = classes[(classes > 0) & (classes < len(NYU40))]
    if len(classes) == 0:
        return NYU40[0]
    return NYU40[int(np.bincount(classes).argmax())]


def _object(group: dict[str, Any], label: str, points: np.ndarray, voxel: float) -> SemanticObject:
    centre, size, rotation = upright_box(points, UP)
    return SemanticObject(
        id=str(group["objectId"]),
        label=label,
        position=centre,
        size=size,
        rotation=rotation,
        points=voxel_downsample(points, voxel),
        extra={"raw_label": group["label"]} if label != group["label"] else {},
    )


def _as_map(objects: list[SemanticObject], source: Path, name: str) -> ObjectMap:
    try:
        return ObjectMap(objects, up=UP, name=name)
    except MapError as exc:
        raise MapError(f"{source}: {exc}") from None


def _convert(source, *, labels, label_map, include_structure, voxel, seed) -> Maps:
    mapping = None if label_map is None else read_label_map(label_map)
    objmap = load_scannet(
        source, labels=labels or ("nyu40" if mapping else "raw"), label_map=mapping,
        include_structure=include_structure, voxel=voxel,
    )  # fmt: skip
    return objmap, None


IMPORTER = Importer(
    "scannet", _convert, "scene folder or .aggregation.json", "raw|nyu40 (default raw)",
    frozenset({"label_map"}),
)  # fmt: skip
