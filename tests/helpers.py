"""Small helpers shared by the test packages."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

from semloc.eval.datasets import real_sample
from semloc.maps import ObjectMap, SemanticObject
from semloc.transforms import yaw_pose as _yaw_pose


def real_sample_or_skip(*parts: str) -> Path:
    """A path inside the real data folder ($SEMLOC_DATA or ../shared/data/real), or skip."""
    path = real_sample(*parts)
    if path is None:
        pytest.skip(f"real data sample {'/'.join(parts)} not found (set SEMLOC_DATA)")
    return path


def box_points(rng: np.random.Generator, obj: SemanticObject, n: int = 600) -> np.ndarray:
    """`n` points on the faces of an object's box (a 0.5 m cube without one)."""
    size = np.asarray(obj.size if obj.size is not None else [0.5, 0.5, 0.5], dtype=float)
    p = rng.uniform(-0.5, 0.5, (n, 3)) * size
    axis = rng.integers(0, 3, n)
    p[np.arange(n), axis] = np.sign(rng.uniform(-1, 1, n)) * size[axis] / 2
    return p + obj.position


def benchmark_script(name: str) -> ModuleType:
    """`benchmarks/<name>.py` imported as module `name` (registered first: dataclasses look
    their module up)."""
    path = Path(__file__).resolve().parents[1] / "benchmarks" / f"{name}.py"
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


# Two sessions of one hand-built room (alignment tests) -----------------------------------
LABELS = ["chair", "table", "lamp", "sofa", "bin", "shelf", "plant", "tv"]
T_A_B = _yaw_pose(2.1, [4.0, -7.5, 0.0])


def room(n: int, seed: int = 3) -> ObjectMap:
    """A hand-built irregular room of n objects (labels cycle, positions random, 1 m apart)."""
    rng = np.random.default_rng(seed)
    xyz: list[np.ndarray] = []
    while len(xyz) < n:
        p = np.append(rng.uniform(0, 4 + n / 4, 2), rng.uniform(0.2, 1.5))
        if all(np.linalg.norm(p - q) > 1.0 for q in xyz):
            xyz.append(p)
    objects = [SemanticObject(f"a{i}", LABELS[i % len(LABELS)], p) for i, p in enumerate(xyz)]
    return ObjectMap(objects, up=[0, 0, 1], name="A")


def second_session(a: ObjectMap, keep: slice = slice(None)) -> ObjectMap:
    """Objects of A (those in `keep`) in B's own frame, with B's own ids."""
    to_b = np.linalg.inv(T_A_B)
    objects = [o.transformed(to_b).replace(id=o.id.replace("a", "b")) for o in list(a)[keep]]
    return ObjectMap(objects, up=[0, 0, 1], name="B")
