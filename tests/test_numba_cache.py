"""The tests compile into a numba cache folder named after the package's sources."""

from __future__ import annotations

import os
import shutil

import numba
from numba_cache import CACHES, package_folder, sources_digest


def test_numba_uses_the_folder_of_these_sources():
    folder = CACHES / sources_digest(package_folder())
    assert folder.is_dir()
    assert os.environ["NUMBA_CACHE_DIR"] == str(folder)
    assert str(folder) == numba.core.config.CACHE_DIR


def test_any_change_of_a_source_names_another_folder(tmp_path):
    """A sign flipped in one compiled module (the case numba's own check missed) changes it."""
    package = tmp_path / "semloc"
    shutil.copytree(package_folder(), package, ignore=shutil.ignore_patterns("__pycache__"))
    before = sources_digest(package)
    assert sources_digest(package) == before
    closed_form = package / "closed_form.py"
    text = closed_form.read_text()
    closed_form.write_text(text.replace("-", "+", 1))
    assert sources_digest(package) != before
    closed_form.write_text(text)
    (package / "new_module.py").write_text("")
    assert sources_digest(package) != before
