"""The native semloc map file: JSON (`"format": "semloc-map"`) plus an optional `.npz` of points.

`load_map` validates everything and raises `MapError` with the file, the object id and the
problem; `save_map` writes the JSON and its `.npz` all or none (temporary files, then renames)
and keeps unknown keys that were read, so a load/save round trip loses nothing.  `.npz` files
are read with `allow_pickle=False`, only inside the map's folder, and only the members the map
names, each checked from its header before it is read.  This module also owns the guarded file
access of the whole package: `read_regular` / `read_json` (regular files within size limits),
`write_files` / `write_atomic` (all or none, streams for devices) and `staged_folder` (a set
of files under one folder, all or none).
"""

from __future__ import annotations

import io
import json
import math
import os
import shutil
import signal
import stat
import tempfile
import tokenize
import zipfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from semloc.maps import (
    MAX_EMBEDDING_LENGTH,
    MAX_ID_LENGTH,
    MAX_OBJECTS,
    MAX_POINTS_PER_MAP,
    MAX_POINTS_PER_OBJECT,
    MapError,
    ObjectMap,
    SemanticObject,
)

FORMAT = "semloc-map"
VERSION = 1
_OBJECT_KEYS = {
    "id", "label", "position", "size", "rotation", "points", "descriptor", "seen", "score",
    "embedding",
}  # fmt: skip
_TOP_KEYS = {"format", "version", "name", "up", "objects", "points_file"}
EMBEDDING_MEMBER = "embedding:"
"""An `.npz` member named `embedding:<object id>` holds that object's embedding (a vector)."""
MAX_JSON_BYTES = 256 * 2**20
"""Largest JSON file read (maps, settings, results, dataset annotations): 256 MiB."""
MAX_FILE_BYTES = 2**30
"""Largest other input file read (points files, meshes, point arrays): 1 GiB."""


# Reading ---------------------------------------------------------------------------------------
def load_map(path: str | os.PathLike[str]) -> ObjectMap:
    """Read a native map file (and its `points_file`); raise `MapError` on any problem."""
    path = Path(path)
    try:
        document = read_json(path)
    except MapError as exc:
        hint = BINARY_HINTS.get(path.suffix.lower(), "") if path.is_file() else ""
        raise MapError(f"{exc}{hint}") from None
    try:
        return map_from_dict(document, base_dir=path.parent)
    except MapError as exc:
        kind = document_kind(document)
        hint = "" if kind in (None, "a semloc map") else f" ({kind}: {KIND_HINTS[kind]})"
        raise MapError(f"{path}: {exc}{hint}") from None


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


def check_regular(path: str | os.PathLike[str], limit: int = MAX_FILE_BYTES, what: str = "") -> int:
    """The size of `path` if it is a regular file of at most `limit` bytes; else `MapError`.

    FIFOs, devices and folders are refused before anything opens them (a FIFO would block).
    """
    path = Path(path)
    try:
        info = path.stat()
    except FileNotFoundError:
        raise MapError(f"{path}: file not found{f' ({what})' if what else ''}") from None
    except OSError as exc:
        raise MapError(f"{path}: cannot read ({exc.strerror or exc})") from None
    if stat.S_ISDIR(info.st_mode):
        raise MapError(f"{path}: is a folder, not a file{f' ({what})' if what else ''}")
    if not stat.S_ISREG(info.st_mode):
        raise MapError(f"{path}: not a regular file")
    if info.st_size > limit:
        raise MapError(f"{path}: {info.st_size:,} bytes, more than the limit of {limit:,}")
    return info.st_size


def read_regular(
    path: str | os.PathLike[str], limit: int = MAX_FILE_BYTES, what: str = ""
) -> bytes:
    """The bytes of `path` after `check_regular`; `MapError` naming the file on any problem."""
    check_regular(path, limit, what)
    try:
        with open(path, "rb") as handle:
            return handle.read(limit + 1)
    except OSError as exc:
        raise MapError(f"{path}: cannot read ({exc.strerror or exc})") from None


def read_json(path: str | os.PathLike[str], what: str = "") -> Any:
    """Parse a JSON file; `MapError` naming the file on any problem.

    Refused: NaN/Infinity, integers beyond the float range, duplicate keys in an object,
    nesting deeper than Python's recursion allows, files over `MAX_JSON_BYTES`.  `what` adds a
    hint to the not-found message (e.g. what the file was expected to be).
    """
    path = Path(path)
    data = read_regular(path, MAX_JSON_BYTES, what)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise MapError(f"{path}: not UTF-8 text (byte {exc.start})") from None
    try:
        return parse_json(text)
    except json.JSONDecodeError as exc:
        raise MapError(f"{path}: not valid JSON ({exc.msg} at line {exc.lineno})") from None
    except RecursionError:
        raise MapError(f"{path}: JSON nested too deeply") from None
    except ValueError as exc:
        raise MapError(f"{path}: {exc}") from None


def parse_json(text: str) -> Any:
    """`json.loads` with the limits of `read_json` (ValueError / RecursionError otherwise)."""
    return json.loads(
        text,
        parse_constant=_reject_constant,
        parse_int=_parse_int,
        object_pairs_hook=_unique_keys,
    )


def _reject_constant(name: str) -> float:
    raise ValueError(f"non-finite number {name} is not allowed")


def _parse_int(text: str) -> int | float:
    if len(text) <= 18:
        return int(text)
    value = float(text)  # beyond int64 the value is only usable as a float
    if not math.isfinite(value):
        raise ValueError(f"number {text[:12]}... ({len(text)} digits) is too large")
    return value


def _unique_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    document = dict(pairs)
    if len(document) != len(pairs):
        seen: set[str] = set()
        for key, _ in pairs:
            if key in seen:
                raise ValueError(f"key {key[:60]!r} occurs more than once in an object")
            seen.add(key)
    return document


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


def npy_header(handle: Any, available: int | None = None) -> tuple[tuple[int, ...], np.dtype]:
    """Shape and dtype from the header of the `.npy` stream `handle`, without reading the data;
    `MapError` for a damaged header, object (pickled) data, or more data declared than the
    `available` bytes."""
    try:
        version = np.lib.format.read_magic(handle)
        if version == (1, 0):
            shape, _, dtype = np.lib.format.read_array_header_1_0(handle)
        elif version == (2, 0):
            shape, _, dtype = np.lib.format.read_array_header_2_0(handle)
        else:
            raise MapError(f"unsupported .npy version {version}")
    except MapError:
        raise
    except (ValueError, SyntaxError, TypeError, EOFError, OSError, tokenize.TokenError) as exc:
        raise MapError(f"damaged .npy header ({str(exc)[:80]})") from None
    if dtype.hasobject:
        raise MapError("object arrays are not read (no pickles)")
    declared = math.prod(shape) * dtype.itemsize
    if available is not None and declared > available:
        raise MapError(f"header declares {declared:,} bytes of data; the file holds fewer")
    return shape, dtype


def read_npy(path: str | os.PathLike[str]) -> np.ndarray:
    """A `.npy` array (no pickles), its header checked against the file size before the data is
    read; `MapError` naming the file on any problem."""
    path = Path(path)
    size = check_regular(path, MAX_FILE_BYTES)
    try:
        with open(path, "rb") as handle:
            npy_header(handle, size)
            handle.seek(0)
            return np.lib.format.read_array(handle, allow_pickle=False)
    except MapError as exc:
        raise MapError(f"{path}: not a readable .npy array ({exc})") from None
    except (OSError, ValueError, EOFError) as exc:
        raise MapError(f"{path}: not a readable .npy array ({str(exc)[:80]})") from None


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


def require_keys(document: Any, keys: tuple[str, ...], where: str) -> dict[str, Any]:
    """`document` if it is a JSON object holding `keys`; else MapError naming `where`."""
    if not isinstance(document, dict):
        raise MapError(f"{where}: must be an object")
    for key in keys:
        if key not in document:
            raise MapError(f"{where}: missing key '{key}'")
    return document


def write_atomic(path: str | os.PathLike[str], data: bytes | str) -> Path:
    """Write `data` to `path` atomically (`write_files` with one file); returns the path."""
    write_files([(Path(path), data)])
    return Path(path)


def write_files(files: list[tuple[Path, bytes | str]]) -> list[Path]:
    """Write several files all or none; the last one should be the index that names the others.

    Each regular file is written to a temporary file in its own folder (mode 0666 less the
    umask, like a plain write); only when all are written are they renamed into place, in order,
    with SIGINT and SIGTERM held.  A target that exists and is not a regular file (`/dev/full`,
    `/dev/stdout`, a FIFO) is written as a stream, never renamed over, before the renames: a
    stream that fails leaves the regular files as they were.  The folders must exist.
    `MapError` naming the file on any problem.
    """
    staged: list[tuple[str, Path]] = []
    streams: list[tuple[Path, bytes]] = []
    try:
        for path, data in files:
            path = Path(path)
            payload = data.encode() if isinstance(data, str) else data
            if _is_stream(path):
                streams.append((path, payload))
            else:
                staged.append((_write_temporary(path, payload), path))
        for path, payload in streams:
            _write_stream(path, payload)
        with signals_held():
            while staged:
                tmp, path = staged[0]
                try:
                    os.replace(tmp, path)
                except OSError as exc:
                    raise MapError(f"{path}: cannot write ({exc.strerror or exc})") from None
                staged.pop(0)
    finally:
        for tmp, _ in staged:
            if os.path.exists(tmp):
                os.unlink(tmp)
    return [Path(path) for path, _ in files]


def _write_stream(path: Path, payload: bytes) -> None:
    try:
        with open(path, "wb") as handle:
            handle.write(payload)
    except OSError as exc:
        raise MapError(f"{path}: cannot write ({exc.strerror or exc})") from None


def _is_stream(path: Path) -> bool:
    """Whether `path` is an existing non-regular file; `MapError` for a folder or no folder."""
    try:
        info = path.stat()
    except FileNotFoundError:
        if not path.parent.is_dir():
            raise MapError(f"{path}: folder {path.parent} does not exist") from None
        return False
    except OSError as exc:
        raise MapError(f"{path}: cannot write ({exc.strerror or exc})") from None
    if stat.S_ISDIR(info.st_mode):
        raise MapError(f"{path}: is a folder, not a file")
    return not stat.S_ISREG(info.st_mode)


def _write_temporary(path: Path, payload: bytes) -> str:
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name[:100]}.", suffix=".tmp", dir=path.parent)
    except OSError as exc:
        raise MapError(f"{path}: cannot write ({exc.strerror or exc})") from None
    try:
        os.fchmod(fd, 0o666 & ~_umask())  # mkstemp creates 0600; give the usual mode
        with os.fdopen(fd, "wb") as handle:
            handle.write(payload)
            handle.flush()
            os.fsync(handle.fileno())
    except BaseException as exc:
        os.unlink(tmp)
        if isinstance(exc, OSError):
            raise MapError(f"{path}: cannot write ({exc.strerror or exc})") from None
        raise
    return tmp


_DEFERRING = [0]  # blocks inside `interrupts_deferred` now (nested ones count)


@contextmanager
def interrupts_deferred() -> Iterator[None]:
    """Ask the command's interrupt handler (`semloc.cli`) to let the block finish before it
    raises.  Unlike `signals_held` nothing is blocked, so the processes started inside (they
    inherit the signal mask) still end on SIGINT and SIGTERM."""
    _DEFERRING[0] += 1
    try:
        yield
    finally:
        _DEFERRING[0] -= 1


def interrupts_wait() -> bool:
    """Whether an interrupt arriving now must wait (see `interrupts_deferred`)."""
    return _DEFERRING[0] > 0


@contextmanager
def signals_held() -> Iterator[None]:
    """Hold SIGINT and SIGTERM (delivered when the block ends), so that a group of renames is
    not cut in the middle by an interrupt."""
    held = {signal.SIGINT, signal.SIGTERM}
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, held)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


@contextmanager
def staged_folder(out: str | os.PathLike[str], index: str | None = None) -> Iterator[Path]:
    """A temporary folder beside `out` to write a set of files into, moved into `out` at the end.

    When the block ends normally, a missing `out` is the staged folder renamed (one atomic
    step); into an existing `out` the files move one by one with SIGINT/SIGTERM held, the file
    named `index` last.  On an error or an interrupt the staged folder is removed and `out` is
    left as it was: all files or none.  Missing parent folders of `out` are created.
    """
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise MapError(f"{out}: exists and is not a folder")
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        stage = Path(
            tempfile.mkdtemp(prefix=f".{out.name[:100]}.", suffix=".partial", dir=out.parent)
        )
        os.chmod(stage, 0o777 & ~_umask())
    except OSError as exc:
        raise MapError(f"{out}: cannot create the folder ({exc.strerror or exc})") from None
    try:
        yield stage
        with signals_held():
            _move_into(stage, out, index)
    finally:
        shutil.rmtree(stage, ignore_errors=True)


def _move_into(stage: Path, out: Path, index: str | None) -> None:
    try:
        if not out.exists():
            os.rename(stage, out)
            return
        files = sorted(p for p in stage.rglob("*") if not p.is_dir())
        files.sort(key=lambda p: p.relative_to(stage).as_posix() == index)
        for source in files:
            target = out / source.relative_to(stage)
            target.parent.mkdir(parents=True, exist_ok=True)
            os.replace(source, target)
    except OSError as exc:
        raise MapError(
            f"{out}: cannot move the results into place ({exc.strerror or exc})"
        ) from None


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask
