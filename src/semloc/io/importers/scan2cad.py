"""Scan2CAD importer: the CAD map of a scan and the scan-derived map of the same scene.

An annotation (one entry of Scan2CAD's `full_annotations.json`) has `id_scan`, `trs` (scan to
world: `translation`, `rotation` quaternion w-x-y-z, `scale`) and `aligned_models[*]` with
`catid_cad` (ShapeNet synset), `id_cad`, `trs` (normalized CAD model to world), `bbox` (half
extents) and `center` (box centre) in model coordinates.  A model point `p` lies at
`inv(M_scan) @ M_model @ p` in the scan frame, `M = T(translation) R(rotation) S(scale)`.

The CAD map has one object per aligned model (id = its index in `aligned_models`): points
sampled on `<shapenet>/<catid>/<id>/model_normalized.obj`, the annotated box, and the class.
The scan map comes from the scan's labelled mesh (`<id_scan>_vh_clean_2.labels.ply`, a NYU40
`label` per vertex): vertices of the model's class inside a model's (slightly enlarged) box form
the scan object with the same id; the other labelled vertices are grouped by Euclidean
clustering (ids from `len(aligned_models)` on).  Both maps are in the scan frame, `up` = +z.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from semloc.io.geometry import (
    nearest_rotation,
    quaternion_matrix,
    sample_triangles,
    upright_box,
)
from semloc.io.importers.base import Importer, Maps
from semloc.io.labels import NYU40, is_structural
from semloc.io.ply import read_ply
from semloc.io.reading import read_json, require_keys
from semloc.maps import MapError, ObjectMap, SemanticObject
from semloc.pointsets import voxel_downsample

UP = np.array([0.0, 0.0, 1.0])
# ShapeNet synsets of the Scan2CAD benchmark: (ShapeNet name, NYU40 class as ScanNet maps it)
SYNSETS = {
    "02747177": ("trash bin", "otherfurniture"),
    "02773838": ("bag", "bag"),
    "02801938": ("basket", "otherprop"),
    "02808440": ("bathtub", "bathtub"),
    "02818832": ("bed", "bed"),
    "02828884": ("bench", "otherfurniture"),
    "02871439": ("bookshelf", "bookshelf"),
    "02933112": ("cabinet", "cabinet"),
    "03001627": ("chair", "chair"),
    "03211117": ("display", "television"),
    "03337140": ("file cabinet", "cabinet"),
    "03636649": ("lamp", "lamp"),
    "03691459": ("loudspeaker", "otherprop"),
    "04004475": ("printer", "otherprop"),
    "04256520": ("sofa", "sofa"),
    "04379243": ("table", "table"),
}


@dataclass(frozen=True)
class Scan2CADMaps:
    """The CAD map and the scan-derived map (None without a label mesh) of one scan.

    Objects with the same id in both maps are the same physical object; the true transform
    between the two maps is the identity (both are in the scan frame)."""

    cad: ObjectMap
    scan: ObjectMap | None


def load_scan2cad(
    annotation: str | os.PathLike[str],
    *,
    shapenet: str | os.PathLike[str] | None = None,
    scan_dir: str | os.PathLike[str] | None = None,
    scene: str | None = None,
    labels: str = "nyu40",
    include_structure: bool = False,
    points_per_model: int = 1000,
    voxel: float = 0.05,
    seed: int = 0,
) -> Scan2CADMaps:
    """Read a Scan2CAD annotation (file, or a folder with `scan2cad_annotation.json`).

    `shapenet`: the ShapeNet root (default: a `shapenet` folder beside or above the annotation);
    `scan_dir`: the folder of the scan's label mesh (default: the annotation's folder);
    `scene`: which scan of a multi-scan annotation file; `labels`: "nyu40" (both maps share the
    NYU40 vocabulary) or "shapenet" (CAD map labelled by synset name).
    """
    if labels not in ("nyu40", "shapenet"):
        raise ValueError(f"labels must be 'nyu40' or 'shapenet', got {labels!r}")
    path = _annotation_path(Path(annotation))
    entry = _select_scan(path, scene)
    root = _shapenet_root(path, shapenet)
    scan_from_world = np.linalg.inv(_trs_matrix(entry["trs"], f"{path}: trs"))
    rng = np.random.default_rng(seed)
    models, cache = [], {}
    for index, raw in enumerate(entry["aligned_models"]):
        models.append(_model(raw, index, path, root, scan_from_world, cache))
    cad = [_cad_object(m, labels, points_per_model, voxel, rng) for m in models]
    name = str(entry["id_scan"])
    cad_map = ObjectMap(cad, up=UP, name=f"{name}_cad")
    mesh = Path(scan_dir) if scan_dir is not None else path.parent
    mesh = mesh / f"{name}_vh_clean_2.labels.ply"
    scan_map = None
    if mesh.exists():
        scan_map = _scan_map(mesh, models, include_structure, voxel, name)
    return Scan2CADMaps(cad_map, scan_map)


# Annotation ------------------------------------------------------------------------------------
def _annotation_path(path: Path) -> Path:
    if path.is_dir():
        for candidate in ("scan2cad_annotation.json", "full_annotations.json"):
            if (path / candidate).exists():
                return path / candidate
        raise MapError(f"{path}: no scan2cad_annotation.json or full_annotations.json here")
    return path


def _select_scan(path: Path, scene: str | None) -> dict[str, Any]:
    document = read_json(path)
    entries = document if isinstance(document, list) else [document]
    if not entries or not all(isinstance(e, dict) for e in entries):
        raise MapError(f"{path}: expected a list of scan annotations")
    if scene is not None:
        entries = [e for e in entries if e.get("id_scan") == scene]
        if not entries:
            raise MapError(f"{path}: no annotation for scan {scene!r}")
    elif len(entries) > 1:
        raise MapError(f"{path}: {len(entries)} scans annotated; choose one with --scene")
    entry = require_keys(entries[0], ("id_scan", "trs", "aligned_models"), str(path))
    if not isinstance(entry["aligned_models"], list):
        raise MapError(f"{path}: 'aligned_models' must be a list")
    declared = entry.get("n_aligned_models", len(entry["aligned_models"]))
    if declared != len(entry["aligned_models"]):
        raise MapError(
            f"{path}: n_aligned_models is {declared} but {len(entry['aligned_models'])} "
            "models are listed"
        )
    return entry


def _shapenet_root(path: Path, shapenet: str | os.PathLike[str] | None) -> Path:
    if shapenet is not None:
        return Path(shapenet)
    for candidate in (path.parent / "shapenet", path.parent.parent / "shapenet"):
        if candidate.is_dir():
            return candidate
    raise MapError(f"{path}: no ShapeNet folder found beside it; give --shapenet")


def _trs_matrix(trs: Any, where: str) -> np.ndarray:
    try:
        t = np.asarray(trs["translation"], dtype=float)
        q = np.asarray(trs["rotation"], dtype=float)
        s = np.asarray(trs["scale"], dtype=float)
        if t.shape != (3,) or q.shape != (4,) or s.shape != (3,):
            raise ValueError("translation, rotation (w, x, y, z) and scale need 3, 4, 3 numbers")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(s)) and np.all(s > 0)):
            raise ValueError("translation and scale must be finite, scale positive")
        matrix = np.eye(4)
        matrix[:3, :3] = quaternion_matrix(*q) @ np.diag(s)
        matrix[:3, 3] = t
        return matrix
    except (KeyError, TypeError) as exc:
        raise MapError(f"{where}: missing {exc}") from None
    except ValueError as exc:
        raise MapError(f"{where}: {exc}") from None


@dataclass(frozen=True)
class _Model:
    index: int
    catid: str
    transform: np.ndarray  # model -> scan frame
    vertices: np.ndarray  # model coordinates
    faces: np.ndarray
    centre: np.ndarray  # box in the scan frame
    size: np.ndarray
    rotation: np.ndarray


def _model(
    raw: Any, index: int, path: Path, root: Path, scan_from_world: np.ndarray, cache: dict
) -> _Model:
    where = f"{path}: aligned_models[{index}]"
    require_keys(raw, ("catid_cad", "id_cad", "trs"), where)
    transform = scan_from_world @ _trs_matrix(raw["trs"], f"{where}.trs")
    obj = root / str(raw["catid_cad"]) / str(raw["id_cad"]) / "model_normalized.obj"
    if obj not in cache:
        cache[obj] = read_obj(obj)
    vertices, faces = cache[obj]
    if "bbox" in raw and "center" in raw:
        try:
            half, centre = _vec3(raw["bbox"]), _vec3(raw["center"])
        except ValueError as exc:
            raise MapError(f"{where}: bbox/center {exc}") from None
    else:
        low, high = vertices.min(axis=0), vertices.max(axis=0)
        half, centre = (high - low) / 2, (high + low) / 2
    linear = transform[:3, :3]
    scales = np.linalg.norm(linear, axis=0)
    return _Model(
        index=index,
        catid=str(raw["catid_cad"]),
        transform=transform,
        vertices=vertices,
        faces=faces,
        centre=linear @ centre + transform[:3, 3],
        size=2 * half * scales,
        rotation=nearest_rotation(linear / scales),
    )


def _vec3(value: Any) -> np.ndarray:
    array = np.asarray(value, dtype=float)
    if array.shape != (3,) or not np.all(np.isfinite(array)):
        raise ValueError("must be 3 finite numbers")
    return array


def read_obj(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (N, 3) and triangles (M, 3) of a Wavefront OBJ (polygons fanned)."""
    try:
        lines = path.read_text(encoding="utf-8", errors="replace").splitlines()
    except FileNotFoundError:
        raise MapError(f"{path}: CAD model file not found") from None
    except OSError as exc:
        raise MapError(f"{path}: cannot read ({exc})") from None
    vertices: list[list[float]] = []
    faces: list[list[int]] = []
    for number, line in enumerate(lines, start=1):
        if line.startswith("v "):
            try:
                vertices.append([float(v) for v in line.split()[1:4]])
            except ValueError:
                raise MapError(f"{path}: line {number}: bad vertex {line!r:.60}") from None
            if len(vertices[-1]) != 3:
                raise MapError(f"{path}: line {number}: vertex needs 3 coordinates")
        elif line.startswith("f "):
            faces.extend(_obj_face(line, number, len(vertices), path))
    if not vertices or not faces:
        raise MapError(f"{path}: no vertices or no faces")
    v = np.array(vertices)
    if not np.all(np.isfinite(v)):
        raise MapError(f"{path}: non-finite vertex coordinates")
    f = np.array(faces, dtype=np.int64)
    if f.max() >= len(v) or f.min() < 0:
        raise MapError(f"{path}: a face refers to a vertex that does not exist")
    return v, f


def _obj_face(line: str, number: int, count: int, path: Path) -> list[list[int]]:
    try:
        ids = [int(token.split("/")[0]) for token in line.split()[1:]]
    except ValueError:
        raise MapError(f"{path}: line {number}: bad face {line!r:.60}") from None
    if len(ids) < 3:
        raise MapError(f"{path}: line {number}: a face needs 3 vertices")
    ids = [i - 1 if i > 0 else count + i for i in ids]
    return [[ids[0], ids[k], ids[k + 1]] for k in range(1, len(ids) - 1)]


# Maps ------------------------------------------------------------------------------------------
def _label(catid: str, labels: str) -> str:
    name, nyu = SYNSETS.get(catid, (catid, catid))
    return nyu if labels == "nyu40" else name


def _cad_object(
    model: _Model, labels: str, count: int, voxel: float, rng: np.random.Generator
) -> SemanticObject:
    sampled = sample_triangles(model.vertices, model.faces, count, rng)
    points = sampled @ model.transform[:3, :3].T + model.transform[:3, 3]
    return SemanticObject(
        id=str(model.index),
        label=_label(model.catid, labels),
        position=model.centre,
        size=model.size,
        rotation=model.rotation,
        points=voxel_downsample(points, voxel),
        extra={"catid_cad": model.catid},
    )


def _scan_map(
    mesh: Path, models: list[_Model], include_structure: bool, voxel: float, name: str
) -> ObjectMap:
    vertices = read_ply(mesh).vertices
    names = vertices.dtype.names or ()
    if not {"x", "y", "z", "label"} <= set(names):
        raise MapError(f"{mesh}: vertex element needs x, y, z and label")
    xyz = np.column_stack([vertices[c] for c in "xyz"]).astype(float)
    classes = vertices["label"].astype(np.int64)
    if classes.max(initial=0) >= len(NYU40):
        raise MapError(f"{mesh}: labels go up to {classes.max()}, not NYU40 ids")
    owner = _assign_to_models(xyz, classes, models)
    objects = []
    for model in models:
        mask = owner == model.index
        if mask.any():
            objects.append(
                _scan_object(str(model.index), _label(model.catid, "nyu40"), xyz[mask], voxel)
            )
    free = (owner < 0) & (classes > 0)
    next_id = len(models)
    for label_id in np.unique(classes[free]):
        label = NYU40[label_id]
        if not include_structure and is_structural(label):
            continue
        for cluster in _clusters(xyz[free & (classes == label_id)]):
            objects.append(_scan_object(str(next_id), label, cluster, voxel))
            next_id += 1
    return ObjectMap(objects, up=UP, name=f"{name}_scan")


def _assign_to_models(xyz: np.ndarray, classes: np.ndarray, models: list[_Model]) -> np.ndarray:
    """Index of the model whose enlarged box holds each vertex of the model's class, or -1."""
    best = np.full(len(xyz), np.inf)
    owner = np.full(len(xyz), -1)
    for model in models:
        nyu = _label(model.catid, "nyu40")
        if nyu not in NYU40:
            continue
        local = (xyz - model.centre) @ model.rotation
        extent = model.size / 2 * 1.1 + 0.05
        reach = np.max(np.abs(local) / extent, axis=1)
        take = (classes == NYU40.index(nyu)) & (reach <= 1) & (reach < best)
        best[take], owner[take] = reach[take], model.index
    return owner


def _clusters(points: np.ndarray, radius: float = 0.1, min_size: int = 100) -> list[np.ndarray]:
    if len(points) < min_size:
        return []
    pairs = cKDTree(points).query_pairs(radius, output_type="ndarray")
    graph = coo_matrix(
        (np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(points), len(points))
    )
    _, component = connected_components(graph, directed=False)
    sizes = np.bincount(component)
    return [points[component == c] for c in np.flatnonzero(sizes >= min_size)]


def _scan_object(object_id: str, label: str, points: np.ndarray, voxel: float) -> SemanticObject:
    centre, size, rotation = upright_box(points, UP)
    return SemanticObject(
        id=object_id,
        label=label,
        position=centre,
        size=size,
        rotation=rotation,
        points=voxel_downsample(points, voxel),
    )


def _convert(source, *, labels, include_structure, voxel, seed, shapenet, scan_dir, scene) -> Maps:
    maps = load_scan2cad(
        source, shapenet=shapenet, scan_dir=scan_dir, scene=scene, labels=labels or "nyu40",
        include_structure=include_structure, voxel=voxel, seed=seed,
    )  # fmt: skip
    return maps.cad, maps.scan


IMPORTER = Importer(
    "scan2cad", _convert, "annotation JSON or its folder", "nyu40|shapenet (default nyu40)",
    frozenset({"shapenet", "scan_dir", "scene"}),
)  # fmt: skip
