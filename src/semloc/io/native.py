"""The native semloc map file: JSON (`"format": "semloc-map"`) plus an optional `.npz` of points.

`load_map` validates everything and raises `MapError` with the file, the object id and the
problem; `save_map` writes atomically (temporary file, then rename) and keeps unknown keys
that were read, so a load/save round trip loses nothing.  `.npz` files are read with
`allow_pickle=False`.
"""

from __future__ import annotations

import io
import json
import os
import tempfile
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from semloc.maps import MapError, ObjectMap, SemanticObject

FORMAT = "semloc-map"
VERSION = 1
_OBJECT_KEYS = {
    "id", "label", "position", "size", "rotation", "points", "descriptor", "seen", "score",
}  # fmt: skip
_TOP_KEYS = {"format", "version", "name", "up", "objects", "points_file"}


# Reading ---------------------------------------------------------------------------------------
def load_map(path: str | os.PathLike[str]) -> ObjectMap:
    """Read a native map file (and its `points_file`); raise `MapError` on any problem."""
    path = Path(path)
    document = read_json(path)
    try:
        return map_from_dict(document, base_dir=path.parent)
    except MapError as exc:
        raise MapError(f"{path}: {exc}") from None


def read_json(path: str | os.PathLike[str], what: str = "") -> Any:
    """Parse a JSON file; `MapError` naming the file on any problem (NaN/Infinity refused).

    `what` adds a hint to the not-found message (e.g. what the file was expected to be).
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise MapError(f"{path}: file not found{f' ({what})' if what else ''}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise MapError(f"{path}: cannot read ({exc.__class__.__name__}: {exc})") from None
    try:
        return json.loads(text, parse_constant=_reject_constant)
    except json.JSONDecodeError as exc:
        raise MapError(f"{path}: not valid JSON ({exc.msg} at line {exc.lineno})") from None
    except ValueError as exc:
        raise MapError(f"{path}: {exc}") from None


def _reject_constant(name: str) -> float:
    raise ValueError(f"non-finite number {name} is not allowed")


def map_from_dict(document: Any, base_dir: Path | None = None) -> ObjectMap:
    """Validate a parsed map document and build the `ObjectMap` (errors without the file name)."""
    if not isinstance(document, dict):
        raise MapError("top level must be a JSON object")
    for key in ("format", "version", "objects"):
        if key not in document:
            raise MapError(f"missing key '{key}'")
    if document["format"] != FORMAT:
        raise MapError(f"format must be '{FORMAT}', got {document['format']!r}")
    if document["version"] != VERSION:
        raise MapError(f"unsupported version {document['version']!r} (this reader knows {VERSION})")
    raw_objects = document["objects"]
    if not isinstance(raw_objects, list):
        raise MapError("'objects' must be a list")
    external = _read_points_file(document.get("points_file"), base_dir)
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
    where = f"object '{object_id}'" if object_id is not None else f"object #{index}"
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
    )


def _read_points_file(name: Any, base_dir: Path | None) -> dict[str, np.ndarray]:
    if name is None:
        return {}
    if not isinstance(name, str) or not name:
        raise MapError("'points_file' must be a relative file name")
    path = (base_dir or Path(".")) / name
    try:
        with np.load(path, allow_pickle=False) as archive:
            return {key: archive[key] for key in archive.files}
    except FileNotFoundError:
        raise MapError(f"points_file '{path}' not found") from None
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise MapError(f"points_file '{path}' is not a readable .npz ({exc})") from None


# Writing ---------------------------------------------------------------------------------------
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
    out["seen"] = obj.seen
    if obj.score is not None:
        out["score"] = obj.score
    out.update(obj.extra)
    return out


def _list(array: np.ndarray) -> list:
    return np.round(np.asarray(array, dtype=float), 6).tolist()


def save_map(objmap: ObjectMap, path: str | os.PathLike[str], points: str = "auto") -> Path:
    """Write `objmap` to `path` atomically.

    `points`: "inline" (in the JSON), "file" (a `<stem>.points.npz` beside it) or "auto"
    (a file when the map holds more than 5,000 points in all).  Returns the JSON path.
    """
    path = Path(path)
    if points not in ("auto", "inline", "file"):
        raise ValueError(f"points must be 'auto', 'inline' or 'file', got {points!r}")
    total = sum(len(o.points) for o in objmap if o.points is not None)
    use_file = total > 0 and (points == "file" or (points == "auto" and total > 5000))
    document = map_to_dict(objmap, inline_points=not use_file)
    if use_file:
        npz_name = path.name.removesuffix(".json") + ".points.npz"
        buffer = io.BytesIO()
        np.savez_compressed(
            buffer, **{o.id: o.points.astype(np.float32) for o in objmap if o.points is not None}
        )
        write_atomic(path.parent / npz_name, buffer.getvalue())
        document["points_file"] = npz_name
    write_atomic(path, (json.dumps(document, indent=1, allow_nan=False) + "\n").encode())
    return path


def require_keys(document: Any, keys: tuple[str, ...], where: str) -> dict[str, Any]:
    """`document` if it is a JSON object holding `keys`; else MapError naming `where`."""
    if not isinstance(document, dict):
        raise MapError(f"{where}: must be an object")
    for key in keys:
        if key not in document:
            raise MapError(f"{where}: missing key '{key}'")
    return document


def write_atomic(path: str | os.PathLike[str], data: bytes | str) -> Path:
    """Write `data` to `path` through a temporary file in the same folder and a rename
    (mode 0666 less the umask, like a plain write); returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    payload = data.encode() if isinstance(data, str) else data
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        os.fchmod(fd, 0o666 & ~_umask())  # mkstemp creates 0600; give the usual mode
        with os.fdopen(fd, "wb") as handle:
            handle.write(payload)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask
