"""Guarded reading of the package's input files: regular files within size limits, JSON
with the limits of a map file, `.npy` arrays checked from their header.

`read_regular` / `read_json` refuse FIFOs, devices and folders before anything opens them, files
over `MAX_FILE_BYTES` / `MAX_JSON_BYTES`, and (JSON) NaN / Infinity, huge integers, duplicate
keys and deep nesting; every problem is a `MapError` naming the file.  `npy_header` reads an
array's shape and dtype without its data (no pickles).
"""

from __future__ import annotations

import json
import math
import os
import stat
import tokenize
from pathlib import Path
from typing import Any

import numpy as np

from semloc.maps import MapError

MAX_JSON_BYTES = 256 * 2**20
"""Largest JSON file read (maps, settings, results, dataset annotations): 256 MiB."""
MAX_FILE_BYTES = 2**30
"""Largest other input file read (points files, meshes, point arrays): 1 GiB."""


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


def require_keys(document: Any, keys: tuple[str, ...], where: str) -> dict[str, Any]:
    """`document` if it is a JSON object holding `keys`; else MapError naming `where`."""
    if not isinstance(document, dict):
        raise MapError(f"{where}: must be an object")
    for key in keys:
        if key not in document:
            raise MapError(f"{where}: missing key '{key}'")
    return document
