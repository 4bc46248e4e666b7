"""The native semloc map file: JSON (`"format": "semloc-map"`) plus an optional `.npz` of points.

`load_map` validates everything and raises `MapError` with the file, the object id and the
problem; `save_map` writes the JSON and its `.npz` all or none (`semloc.io.output`) and keeps
unknown keys that were read, so a load/save round trip loses nothing.  `.npz` files are read
with `allow_pickle=False`, only inside the map's folder, and only the members the map names,
each checked from its header before it is read (`semloc.io.reading`).  `document_kind` says
what a JSON document that is not a map looks like (a result, an annotation, settings).
"""

from __future__ import annotations

import io
import json
import logging
import os
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from semloc.io.output import write_files
from semloc.io.reading import (
    MAX_FILE_BYTES,
    check_regular,
    npy_header,
    read_json,
)
from semloc.maps import (
    MAX_EMBEDDING_LENGTH,
    MAX_ID_LENGTH,
    MAX_OBJECTS,
    MAX_POINTS_PER_MAP,
    MAX_POINTS_PER_OBJECT,
    MapError,
    ObjectMap,
    SemanticObject,
    far_from_points,
)

__all__ = [
    "BINARY_HINTS", "EMBEDDING_MEMBER", "FORMAT", "KIND_HINTS", "VERSION", "document_kind",
    "load_map", "map_files", "map_from_dict", "map_to_dict", "points_path", "save_map",
]  # fmt: skip

FORMAT = "semloc-map"
VERSION = 1
_OBJECT_KEYS = {
    "id", "label", "position", "size", "rotation", "points", "descriptor", "seen", "score",
    "embedding",
}  # fmt: skip
_TOP_KEYS = {"format", "version", "name", "up", "objects", "points_file"}
log = logging.getLogger("semloc")
EMBEDDING_MEMBER = "embedding:"
"""An `.npz` member named `embedding:<object id>` holds that object's embedding (a vector)."""


def load_map(path: str | os.PathLike[str]) -> ObjectMap:
    """Read a native map file (and its `points_file`); raise `MapError` on any problem."""
    path = Path(path)
    try:
        document = read_json(path)
    except MapError as exc:
        hint = BINARY_HINTS.get(path.suffix.lower(), "") if path.is_file() else ""
        raise MapError(f"{exc}{hint}") from None
    try:
        objmap = map_from_dict(document, base_dir=path.parent)
    except MapError as exc:
        kind = document_kind(document)
        hint = "" if kind in (None, "a semloc map") else f" ({kind}: {KIND_HINTS[kind]})"
        raise MapError(f"{path}: {exc}{hint}") from None
    warn_far_points(objmap, path)
    return objmap


def warn_far_points(objmap: ObjectMap, source: object) -> None:
    """One warning line (the `semloc` logger) for a map with objects whose points lie far from
    their centre (`semloc.maps.far_from_points`): it loads, but such an object fits nowhere."""
    far = far_from_points(objmap)
    if not far:
        return
    first, metres = far[0]
    more = f" (and {len(far) - 1} more objects)" if len(far) > 1 else ""
    log.warning(
        f"warning: {source}: object '{first[:60]}': its points lie {metres:.1f} m from "
        f"its position{more}; move an object with SemanticObject.transformed (or replace "
        "position and points together)"
    )


BINARY_HINTS = {
    ".npz": "; a .npz holds point arrays (a map's points_file): the map is the JSON that names "
    "it, and `semloc convert` writes maps from datasets",
    ".npy": "; a .npy holds an array, not a map: `semloc convert` writes maps from datasets",
    ".ply": "; a .ply is a mesh or point cloud, not a map: `semloc convert` writes maps from "
    "datasets",
}
"""What to tell someone who gave a binary file where a map goes, by its suffix."""


KIND_HINTS = {
    "a localization result": "give it to view or export with --result",
    "a ground-truth file": "give it with --gt",
    "a ScanNet aggregation file": "make a map first with `semloc convert scannet`",
    "a Scan2CAD annotation": "make a map first with `semloc convert scan2cad`",
    "a Replica annotation": "make a map first with `semloc convert replica`",
    "a settings file": "give it with --config",
}
"""What to do with a JSON file that is not a map, by `document_kind`."""


def document_kind(document: Any) -> str | None:
    """What a parsed JSON document looks like: "a semloc map", one of `KIND_HINTS`, or None."""
    if isinstance(document, list) and document and isinstance(document[0], dict):
        document = document[0]  # Scan2CAD's full_annotations.json is a list of scans
    if not isinstance(document, dict):
        return None
    keys = set(document)
    if document.get("format") == FORMAT:
        return "a semloc map"
    if "hypotheses" in keys or {"status", "pose"} <= keys:
        return "a localization result"
    if "T_global_local" in keys:
        return "a ground-truth file"
    if "segGroups" in keys:
        return "a ScanNet aggregation file"
    if "aligned_models" in keys:
        return "a Scan2CAD annotation"
    if "objects" in keys and ("classes" in keys or "gravity_dir" in keys):
        return "a Replica annotation"
    if keys & {"association", "clustering", "pose", "decision", "gamma", "delta", "top_k"}:
        return "a settings file"
    return None


def map_from_dict(document: Any, base_dir: Path | None = None) -> ObjectMap:
    """Validate a parsed map document and build the `ObjectMap` (errors without the file name)."""
    if not isinstance(document, dict):
        raise MapError("top level must be a JSON object")
    for key in ("format", "version", "objects"):
        if key not in document:
            raise MapError(f"missing key '{key}'")
    if document["format"] != FORMAT:
        raise MapError(f"format must be '{FORMAT}', got {document['format']!r:.60}")
    version = document["version"]
    if isinstance(version, bool) or not isinstance(version, int) or version != VERSION:
        raise MapError(f"unsupported version {version!r:.60} (this reader knows {VERSION})")
    raw_objects = document["objects"]
    if not isinstance(raw_objects, list):
        raise MapError("'objects' must be a list")
    if len(raw_objects) > MAX_OBJECTS:
        raise MapError(f"{len(raw_objects):,} objects, more than the limit of {MAX_OBJECTS:,}")
    wanted = {
        str(raw.get("id")) for raw in raw_objects if isinstance(raw, dict) and "points" not in raw
    } | {
        EMBEDDING_MEMBER + str(raw.get("id"))
        for raw in raw_objects
        if isinstance(raw, dict) and "embedding" not in raw
    }
    external = _read_points_file(document.get("points_file"), base_dir, wanted)
    objects = [_object_from_dict(raw, i, external) for i, raw in enumerate(raw_objects)]
    name = document.get("name", "")
    if not isinstance(name, str):
        raise MapError("'name' must be a string")
    extra = {k: v for k, v in document.items() if k not in _TOP_KEYS}
    if "points_file" in document:
        extra["points_file"] = document["points_file"]
    return ObjectMap(objects, up=document.get("up"), name=name, extra=extra)


def _object_from_dict(raw: Any, index: int, external: dict[str, np.ndarray]) -> SemanticObject:
    if not isinstance(raw, dict):
        raise MapError(f"object #{index}: must be a JSON object")
    object_id = raw.get("id")
    where = f"object #{index}"
    if isinstance(object_id, str) and 0 < len(object_id) <= MAX_ID_LENGTH:
        where = f"object '{object_id}'"
    for key in ("id", "label", "position"):
        if key not in raw:
            raise MapError(f"{where}: missing key '{key}'")
    if isinstance(object_id, bool) or not isinstance(object_id, (str, int)):
        raise MapError(f"{where}: id must be a string or an integer")
    points = raw.get("points")
    if points is None:
        points = external.get(str(object_id))
    return SemanticObject(
        id=str(object_id),
        label=raw["label"],
        position=raw["position"],
        size=raw.get("size"),
        rotation=raw.get("rotation"),
        points=points,
        descriptor=raw.get("descriptor"),
        seen=raw.get("seen", 0),
        score=raw.get("score"),
        extra={k: v for k, v in raw.items() if k not in _OBJECT_KEYS},
        embedding=raw.get("embedding", external.get(EMBEDDING_MEMBER + str(object_id))),
    )


def _read_points_file(name: Any, base_dir: Path | None, wanted: set[str]) -> dict[str, np.ndarray]:
    """The members of the map's `.npz` that `wanted` objects name, each checked from its header
    (an (N, 3) float array, N within the limit) before it is read."""
    if name is None:
        return {}
    path = _points_path(name, base_dir or Path("."))
    check_regular(path, MAX_FILE_BYTES, "points_file")
    points: dict[str, np.ndarray] = {}
    try:
        with zipfile.ZipFile(path) as archive:
            members = {m.removesuffix(".npy"): m for m in archive.namelist() if m.endswith(".npy")}
            total = 0
            for object_id in sorted(wanted & set(members)):
                info = archive.getinfo(members[object_id])
                with archive.open(info) as handle:
                    if object_id.startswith(EMBEDDING_MEMBER):
                        _embedding_shape(handle, object_id, info.file_size)
                    else:
                        total += _npy_shape(handle, object_id, info.file_size)[0]
                if total > MAX_POINTS_PER_MAP:
                    raise MapError(f"more than {MAX_POINTS_PER_MAP:,} points in all")
                with archive.open(members[object_id]) as handle:
                    points[object_id] = np.lib.format.read_array(handle, allow_pickle=False)
    except FileNotFoundError:
        raise MapError(f"points_file '{path}' not found") from None
    except (OSError, ValueError, zipfile.BadZipFile, EOFError, RuntimeError) as exc:
        if isinstance(exc, MapError):
            raise MapError(f"points_file '{path}': {exc}") from None
        raise MapError(f"points_file '{path}' is not a readable .npz ({exc})") from None
    return points


def _points_path(name: Any, base_dir: Path) -> Path:
    """`name` as a `.npz` file inside `base_dir`: relative, no `..`, no symlink leading out."""
    if not isinstance(name, str) or not name or len(name) > 255:
        raise MapError("'points_file' must be a relative file name")
    relative = Path(name)
    if relative.is_absolute() or ".." in relative.parts or "\\" in name:
        raise MapError(f"points_file {name!r:.80} must be a relative path inside the map's folder")
    if relative.suffix != ".npz":
        raise MapError(f"points_file {name!r:.80} must be a .npz file")
    path = base_dir / relative
    try:
        inside = path.resolve().is_relative_to(base_dir.resolve())
    except (OSError, RuntimeError):
        inside = False
    if not inside:
        raise MapError(f"points_file {name!r:.80} leads outside the map's folder")
    return path


def _embedding_shape(handle: Any, member: str, available: int) -> None:
    """Check an embedding member's header: a float vector of at most MAX_EMBEDDING_LENGTH."""
    shape, dtype = npy_header(handle, available)
    object_id = member.removeprefix(EMBEDDING_MEMBER)
    if len(shape) != 1 or not 0 < shape[0] <= MAX_EMBEDDING_LENGTH or dtype.kind not in "iuf":
        raise MapError(
            f"object '{object_id}': embedding must be a vector of at most "
            f"{MAX_EMBEDDING_LENGTH} numbers, got {dtype} {shape}"
        )


def _npy_shape(handle: Any, object_id: str, available: int) -> tuple[int, ...]:
    try:
        shape, dtype = npy_header(handle, available)
    except MapError as exc:
        raise MapError(f"member '{object_id[:60]}': {exc}") from None
    if dtype.kind not in "fiu" or len(shape) != 2 or shape[1] != 3:
        raise MapError(f"member '{object_id[:60]}' must be an (N, 3) array of numbers")
    if shape[0] > MAX_POINTS_PER_OBJECT:
        raise MapError(
            f"member '{object_id[:60]}' has {shape[0]:,} points, more than {MAX_POINTS_PER_OBJECT:,}"
        )
    return shape


def map_to_dict(objmap: ObjectMap, inline_points: bool = True) -> dict[str, Any]:
    """The JSON document for a map; points inline unless `inline_points` is False."""
    document: dict[str, Any] = {"format": FORMAT, "version": VERSION, "name": objmap.name}
    if objmap.up is not None:
        document["up"] = _list(objmap.up)
    document["objects"] = [_object_to_dict(o, inline_points) for o in objmap]
    document.update({k: v for k, v in objmap.extra.items() if k != "points_file"})
    return document


def _object_to_dict(obj: SemanticObject, inline_points: bool) -> dict[str, Any]:
    out: dict[str, Any] = {"id": obj.id, "label": obj.label, "position": _list(obj.position)}
    if obj.size is not None:
        out["size"] = _list(obj.size)
    if obj.rotation is not None:
        out["rotation"] = _list(obj.rotation)
    if obj.points is not None and inline_points:
        out["points"] = _list(obj.points)
    if obj.descriptor is not None:
        out["descriptor"] = _list(obj.descriptor)
    if obj.embedding is not None:
        out["embedding"] = np.asarray(obj.embedding, dtype=float).tolist()
    out["seen"] = obj.seen
    if obj.score is not None:
        out["score"] = obj.score
    out.update(obj.extra)
    return out


def _list(array: np.ndarray) -> list:
    array = np.asarray(array, dtype=float)
    with np.errstate(over="ignore", invalid="ignore"):
        rounded = np.round(array, 6)  # overflows to inf for |x| near the float maximum
    return np.where(np.isfinite(rounded), rounded, array).tolist()


def points_path(path: str | os.PathLike[str]) -> Path:
    """Where `save_map` puts the points of a map written to `path` when they go to a file:
    `<name without .json>.points.npz` beside it."""
    path = Path(path)
    return path.parent / (path.name.removesuffix(".json") + ".points.npz")


def map_files(
    objmap: ObjectMap, path: str | os.PathLike[str], points: str = "auto"
) -> list[tuple[Path, bytes]]:
    """The files `save_map` writes, as `(path, content)`: the points `.npz` (if any), then the
    JSON (the index, last).  Everything is encoded before anything is written."""
    path = Path(path)
    if points not in ("auto", "inline", "file"):
        raise ValueError(f"points must be 'auto', 'inline' or 'file', got {points!r}")
    total = sum(len(o.points) for o in objmap if o.points is not None)
    use_file = total > 0 and (points == "file" or (points == "auto" and total > 5000))
    document = map_to_dict(objmap, inline_points=not use_file)
    files: list[tuple[Path, bytes]] = []
    if use_file:
        npz_path = points_path(path)
        buffer = io.BytesIO()
        np.savez_compressed(
            buffer, **{o.id: o.points.astype(np.float32) for o in objmap if o.points is not None}
        )
        files.append((npz_path, buffer.getvalue()))
        document["points_file"] = npz_path.name
    try:
        text = json.dumps(document, indent=1, allow_nan=False) + "\n"
    except (ValueError, TypeError) as exc:
        raise MapError(f"{path}: cannot write the map ({exc})") from None
    files.append((path, text.encode()))
    return files


def save_map(objmap: ObjectMap, path: str | os.PathLike[str], points: str = "auto") -> Path:
    """Write `objmap` to `path`, all files or none (`write_files`).

    `points`: "inline" (in the JSON), "file" (a `<stem>.points.npz` beside it) or "auto"
    (a file when the map holds more than 5,000 points in all).  Returns the JSON path.
    """
    write_files(map_files(objmap, path, points))
    return Path(path)
