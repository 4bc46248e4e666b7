"""The commands' files: reading settings (JSON or YAML), poses and results (their fields are
checked by `semloc.results`), and checking outputs and numeric options before any work is
done."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import yaml

from semloc.cli.app import fail
from semloc.io import read_json, read_regular, write_atomic
from semloc.io.native import document_kind, points_path
from semloc.io.reading import MAX_JSON_BYTES
from semloc.maps import ObjectMap
from semloc.results import SavedResult, saved_pose, saved_result

YAML_SUFFIXES = (".yaml", ".yml")
ResultFile = SavedResult
"""What `view`, `export` and `update-map --result` use of a result file (`semloc.results`)."""


def read_config(path: Path | None) -> dict:
    """The settings of a `--config` file (an object in JSON, or YAML for .yaml/.yml), or {}."""
    if path is None:
        return {}
    data = _read_yaml(path) if path.suffix.lower() in YAML_SUFFIXES else read_json(path)
    if not isinstance(data, dict):
        fail(f"{path}: must hold an object (mapping) of settings")
    return data


def read_label_map(path: Path) -> dict[str, str]:
    """A `--label-map` file: an object (JSON, or YAML for .yaml/.yml) of label -> label."""
    data = _read_yaml(path) if path.suffix.lower() in YAML_SUFFIXES else read_json(path)
    if not isinstance(data, dict) or not all(
        isinstance(k, str) and k.strip() and isinstance(v, str) and v.strip()
        for k, v in data.items()
    ):
        fail(f"{path}: a label map must be an object of non-empty strings (local -> map label)")
    return dict(data)


def _read_yaml(path: Path) -> object:
    try:
        text = read_regular(path, MAX_JSON_BYTES).decode("utf-8")
    except UnicodeDecodeError as exc:
        fail(f"{path}: not UTF-8 text (byte {exc.start})")
    try:
        return yaml.safe_load(text)
    except RecursionError:
        fail(f"{path}: YAML nested too deeply")
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark is not None else ""
        fail(f"{path}: not valid YAML ({getattr(exc, 'problem', None) or exc}{where})")
        raise  # unreachable: fail() raises


def pose_of(path: Path, value: object, what: str = "pose") -> np.ndarray:
    """A 4x4 pose read from `path` (translation within the maps' coordinate limit), or one line
    naming the file, the key and the problem."""
    try:
        return saved_pose(value, what)
    except ValueError as exc:
        fail(f"{path}: {exc}")
        raise  # unreachable: fail() raises


def read_pose(path: Path, what: str | None = None) -> np.ndarray:
    """The 4x4 `T_global_local` of a file holding it (a list of 4 rows, or under that key).

    A file without that key gets one line naming the key and what the file looks like
    (a map, a result: `semloc.io.native.document_kind`)."""
    data = read_json(path, what=what or "")
    if isinstance(data, dict) and "T_global_local" not in data:
        kind = document_kind(data) or "an object without it"
        usage = f" ({what})" if what else ""
        fail(f"{path}: no 'T_global_local' key: this is {kind}{usage}")
    if isinstance(data, dict):
        return pose_of(path, data["T_global_local"], "T_global_local")
    return pose_of(path, data)


def read_result(path: Path) -> ResultFile:
    """A result file (`localize --format json`, or a ground-truth file), every field checked
    (`semloc.results.saved_result`): a field of the wrong type is one line naming the file, the
    field and what it must be."""
    data = read_json(path)
    if not isinstance(data, dict) or not ("pose" in data or "T_global_local" in data):
        kind = document_kind(data)
        seems = f" (this is {kind})" if kind else ""
        fail(f"{path}: not a localization result (no 'pose') nor a ground truth file{seems}")
    try:
        return saved_result(data)
    except ValueError as exc:
        fail(f"{path}: {exc}")
        raise  # unreachable: fail() raises


def check_output(path: Path, option: str = "--output") -> Path:
    """`path` if a file can be written there: not a folder, in a folder that exists."""
    if path.is_dir():
        fail(f"{path}: is a folder; {option} takes a file name")
    if not path.parent.is_dir():
        fail(f"{path}: folder {path.parent} does not exist ({option})")
    return path


def check_suffix(path: Path | None, suffix: str, option: str, what: str) -> None:
    """Refuse a file name whose suffix says another format than the one `option` writes
    (`view -o x.txt` wrote a PNG named x.txt); a stream (`/dev/stdout`) takes any."""
    if path is None or path.suffix.lower() == suffix or (path.exists() and not path.is_file()):
        return
    fail(f"{path}: {option} writes {what}; give a file name ending in {suffix}")


def map_paths(path: Path, objmap: ObjectMap, what: str) -> dict[Path, str]:
    """The files the map `what` was read from (the JSON and the points file it names), each
    with what it is."""
    points_file = objmap.extra.get("points_file")
    if not isinstance(points_file, str):
        return {path: what}
    return {path: what, path.parent / points_file: f"the points file of {what}"}


def map_outputs(path: Path | None) -> list[Path]:
    """The files a map written to `path` may take: the JSON and its points file."""
    return [] if path is None else [path, points_path(path)]


def check_separate(
    outputs: dict[str, list[Path] | Path | None], inputs: dict[Path | None, str]
) -> None:
    """Refuse, in one line, an output that would overwrite an input or two outputs that would
    write one file, before anything is written (every command that writes files calls it).

    `outputs`: option -> the file(s) it writes, a map's points file too (`map_outputs`);
    `inputs`: file -> what it is (a map's points file too: `map_paths`); None entries are
    skipped.  Files are compared as the file system sees them (symlinks, hard links, `./`).
    Written over, an input map is lost, and its points file written over leaves the map
    naming the points of other objects."""
    read = {_identity(path): what for path, what in inputs.items() if path is not None}
    written: dict[object, str] = {}
    for option, paths in outputs.items():
        for path in [paths] if isinstance(paths, Path) else paths or []:
            key = _identity(path)
            if key in read:
                fail(f"{path}: {option} would overwrite {read[key]}, an input")
            if written.setdefault(key, option) != option:
                fail(
                    f"{path}: {written[key]} and {option} would both write it; "
                    "they must name different files"
                )


def _identity(path: Path) -> object:
    """What names one file: its device and inode when it exists, else its resolved path."""
    try:
        info = path.stat()
    except OSError:
        return path.resolve()
    return (info.st_dev, info.st_ino)


def check_finite(**options: float | tuple[float, ...] | None) -> None:
    """Refuse a non-finite numeric option (`--voxel nan`, `--radius inf`) in one line."""
    for name, value in options.items():
        values = value if isinstance(value, tuple) else (value,)
        if any(v is not None and not math.isfinite(v) for v in values):
            fail(f"--{name.replace('_', '-')} must be a finite number, got {value}")


def emit(text: str, output: Path | None) -> None:
    """`text` on stdout, or written to `output` all or nothing."""
    if output is None:
        sys.stdout.write(text)
    else:
        write_atomic(output, text)
