"""A numba cache folder that cannot be stale: named after a hash of the package's sources.

numba's `cache=True` checks only the source file of the function it loads: a cached kernel
that calls a compiled function of another module (or reads a constant from one) keeps the old
callee after that module changed.  The tests therefore compile into a folder named after a
hash of every `.py` file of the `semloc` package being tested: any change to the sources
means a new, empty folder (one compilation, about two minutes on 2 cores), and an unchanged
tree reuses the warm one.  Imported by `conftest.py` before anything imports numba or semloc;
this module imports neither.
"""

from __future__ import annotations

import hashlib
import importlib.util
import os
import shutil
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CACHES = ROOT / ".pytest_cache" / "numba"
"""Where the per-source-hash folders live (`make clean` removes them with .pytest_cache)."""
UNUSED_SECONDS = 24 * 3600
"""Folders of other source trees not used for this long are removed."""


def package_folder() -> Path:
    """The folder of the `semloc` package that the tests import (found without importing it)."""
    spec = importlib.util.find_spec("semloc")
    if spec is None or not spec.submodule_search_locations:
        raise RuntimeError("semloc is not importable: install it or set PYTHONPATH=src")
    return Path(next(iter(spec.submodule_search_locations)))


def sources_digest(package: Path) -> str:
    """A 16-hex-digit BLAKE2b digest of the package's `.py` files: their paths and contents."""
    digest = hashlib.blake2b(digest_size=8)
    for path in sorted(package.rglob("*.py")):
        digest.update(path.relative_to(package).as_posix().encode() + b"\0")
        digest.update(path.read_bytes() + b"\0")
    return digest.hexdigest()


def use_fresh_cache(caches: Path = CACHES) -> Path:
    """Point numba at the folder of the current sources (NUMBA_CACHE_DIR, also inherited by
    the subprocesses the tests start) and remove folders of other trees unused for a day."""
    folder = caches / sources_digest(package_folder())
    folder.mkdir(parents=True, exist_ok=True)
    os.utime(folder)
    os.environ["NUMBA_CACHE_DIR"] = str(folder)
    if "numba" in sys.modules:  # imported already (a plugin): make it read the variable again
        sys.modules["numba"].core.config.reload_config()
    for other in caches.iterdir():
        if other != folder and time.time() - other.stat().st_mtime > UNUSED_SECONDS:
            shutil.rmtree(other, ignore_errors=True)
    return folder
