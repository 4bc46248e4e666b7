"""The commands' files: reading settings (JSON or YAML), poses and results, and checking
outputs and numeric options before any work is done."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import yaml

from semloc.cli.app import fail
from semloc.io import read_json, read_regular
from semloc.io.native import MAX_JSON_BYTES
from semloc.transforms import as_pose

YAML_SUFFIXES = (".yaml", ".yml")


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


def pose_of(path: Path, value: object) -> np.ndarray:
    """A 4x4 pose read from `path`, or one line naming the file and the problem."""
    try:
        return as_pose(value)
    except ValueError as exc:
        fail(f"{path}: {exc}")
        raise  # unreachable: fail() raises


def read_pose(path: Path, what: str | None = None) -> np.ndarray:
    """The 4x4 `T_global_local` of a file holding it (a list of 4 rows, or under that key)."""
    data = read_json(path, what=what or "")
    if isinstance(data, dict):
        data = data.get("T_global_local")
    return pose_of(path, data)


def read_result(path: Path) -> tuple[np.ndarray | None, list[tuple[str, str]], str | None]:
    """Pose, best pairs and status of a result file (or the true pose of a ground_truth.json)."""
    data = read_json(path)
    if not isinstance(data, dict) or not ("pose" in data or "T_global_local" in data):
        fail(f"{path}: not a localization result (no 'pose') nor a ground truth file")
    raw = data.get("pose", data.get("T_global_local"))
    pose = None if raw is None else pose_of(path, raw)
    pairs: list[tuple[str, str]] = []
    hypotheses = data.get("hypotheses") or []
    if isinstance(hypotheses, list) and hypotheses and isinstance(hypotheses[0], dict):
        for pair in hypotheses[0].get("pairs", []):
            if isinstance(pair, dict) and "global" in pair and "local" in pair:
                pairs.append((str(pair["global"]), str(pair["local"])))
    status = data.get("status") if isinstance(data.get("status"), str) else None
    return pose, pairs, status


def check_output(path: Path, option: str = "--output") -> Path:
    """`path` if a file can be written there: not a folder, in a folder that exists."""
    if path.is_dir():
        fail(f"{path}: is a folder; {option} takes a file name")
    if not path.parent.is_dir():
        fail(f"{path}: folder {path.parent} does not exist ({option})")
    return path


def check_finite(**options: float | tuple[float, ...] | None) -> None:
    """Refuse a non-finite numeric option (`--voxel nan`, `--radius inf`) in one line."""
    for name, value in options.items():
        values = value if isinstance(value, tuple) else (value,)
        if any(v is not None and not math.isfinite(v) for v in values):
            fail(f"--{name.replace('_', '-')} must be a finite number, got {value}")
