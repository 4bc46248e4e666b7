"""Small helpers shared by the test packages."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

import pytest

from semloc.eval.datasets import real_sample


def real_sample_or_skip(*parts: str) -> Path:
    """A path inside the real data folder ($SEMLOC_DATA or ../shared/data/real), or skip."""
    path = real_sample(*parts)
    if path is None:
        pytest.skip(f"real data sample {'/'.join(parts)} not found (set SEMLOC_DATA)")
    return path


def benchmark_script(name: str) -> ModuleType:
    """`benchmarks/<name>.py` imported as module `name` (registered first: dataclasses look
    their module up)."""
    path = Path(__file__).resolve().parents[1] / "benchmarks" / f"{name}.py"
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module
