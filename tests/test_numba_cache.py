"""The tests compile into a numba cache folder named after the package's compiled sources."""

from __future__ import annotations

import importlib
import os
import shutil
import sys

import numba
import pytest
from numba.core.dispatcher import Dispatcher
from numba_cache import CACHES, compiled_sources, package_folder, sources_digest


def test_numba_uses_the_folder_of_these_sources():
    folder = CACHES / sources_digest(package_folder())
    assert folder.is_dir()
    assert os.environ["NUMBA_CACHE_DIR"] == str(folder)
    assert str(folder) == numba.core.config.CACHE_DIR


@pytest.fixture
def package(tmp_path):
    copy = tmp_path / "semloc"
    shutil.copytree(package_folder(), copy, ignore=shutil.ignore_patterns("__pycache__"))
    return copy


def edited(path, old: str, new: str) -> None:
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new, 1))


def test_a_change_of_a_compiled_module_names_another_folder(package):
    """A sign flipped in one compiled module (the case numba's own check missed) changes it;
    so does a new compiled module."""
    before = sources_digest(package)
    assert sources_digest(package) == before
    closed_form = package / "closed_form.py"
    text = closed_form.read_text()
    edited(closed_form, "-", "+")
    assert sources_digest(package) != before
    closed_form.write_text(text)
    assert sources_digest(package) == before
    edited(package / "_clustering_fast.py", "import numpy as np", "import numpy as np  # edited")
    assert sources_digest(package) != before


def test_a_new_compiled_module_names_another_folder(package):
    before = sources_digest(package)
    (package / "new_loops.py").write_text(
        "import numba\n\n\n@numba.njit(cache=True)\ndef twice(x):\n    return 2 * x\n"
    )
    assert sources_digest(package) != before


def test_a_change_outside_the_compiled_modules_keeps_the_folder(package):
    """A help string, the CLI, a new plain module, the localizer's Python: the warm cache
    stays (numba's own check of each compiled function's file covers them)."""
    before = sources_digest(package)
    edited(package / "cli" / "app.py", '"""', '"""Edited. ')
    edited(package / "localizer.py", "import", "import os  # edited\nimport")
    (package / "new_module.py").write_text("NOTHING_COMPILED = 1\n")
    assert sources_digest(package) == before


def test_a_module_whose_names_a_compiled_function_uses_counts(package):
    """A constant a compiled function reads from a plain module is frozen into the compiled
    code: that module is part of the key."""
    (package / "constants.py").write_text("LIMIT = 3\n")
    (package / "loops.py").write_text(
        "import numba\n\nfrom semloc.constants import LIMIT\n\n\n"
        "@numba.njit(cache=True)\ndef capped(x):\n    return min(x, LIMIT)\n"
    )
    assert package / "constants.py" in compiled_sources(package)
    before = sources_digest(package)
    edited(package / "constants.py", "3", "4")
    assert sources_digest(package) != before


def test_every_module_numba_compiles_is_in_the_key():
    """What numba really compiles (the dispatchers of every importable semloc module) is found
    by reading the sources."""
    package = package_folder()
    for path in package.rglob("*.py"):
        parts = path.relative_to(package).with_suffix("").parts
        if parts[-1] == "__main__":
            continue
        name = ".".join(["semloc", *parts[: -1 if parts[-1] == "__init__" else None]])
        try:
            importlib.import_module(name)
        except ImportError:
            continue  # an optional extra that is not installed
    dispatched = {
        sys.modules[value.py_func.__module__].__file__
        for name, module in list(sys.modules.items())
        if name.split(".")[0] == "semloc"
        for value in vars(module).values()
        if isinstance(value, Dispatcher) and value.py_func.__module__.split(".")[0] == "semloc"
    }
    assert dispatched and dispatched <= {str(path) for path in compiled_sources(package)}
