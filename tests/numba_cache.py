"""A numba cache folder that cannot be stale: named after a hash of the compiled sources.

numba's `cache=True` checks only the source file of the function it loads: a cached kernel
that calls a compiled function of another module (or reads a constant from one) keeps the old
callee after that module changed.  The tests therefore compile into a folder named after a
hash of the package's compiled modules (those defining numba-compiled functions: the `_*_fast`
loops, `closed_form`, `neighbours`, `registration`, ...) and of the semloc modules whose names
their compiled functions use (the callees and constants numba freezes in): a change there means
a new, empty folder (one compilation, about two minutes on 2 cores); a change anywhere else
(a help string, the CLI, the service) keeps the warm one, where numba's own check of each
function's file is enough.  Imported by `conftest.py` before anything imports numba or semloc;
this module imports neither (it reads the sources with `ast`).
"""

from __future__ import annotations

import ast
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


COMPILERS = {"njit", "jit", "vectorize", "guvectorize", "cfunc", "stencil", "generated_jit"}
"""numba's decorators: a function decorated with one of them is compiled."""


def _decorator_name(decorator: ast.expr) -> str:
    """`njit` of `@njit`, `@njit(...)`, `@numba.njit(...)`."""
    target = decorator.func if isinstance(decorator, ast.Call) else decorator
    return target.attr if isinstance(target, ast.Attribute) else getattr(target, "id", "")


def _compiled_functions(tree: ast.Module) -> list[ast.FunctionDef]:
    return [node for node in ast.walk(tree) if isinstance(node, ast.FunctionDef)
            and any(_decorator_name(d) in COMPILERS for d in node.decorator_list)]  # fmt: skip


def _imported_names(tree: ast.Module, package: list[str]) -> dict[str, str]:
    """Local name -> the semloc module it comes from (`from semloc.x import y`: y -> semloc.x;
    `import semloc.x as z`: z -> semloc.x); relative imports resolved from `package` (the
    parts of the importing module's package)."""
    names: dict[str, str] = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                names[alias.asname or alias.name.split(".")[0]] = alias.name
        elif isinstance(node, ast.ImportFrom):
            base = package[: len(package) - node.level + 1] if node.level else []
            source = ".".join([*base, *([node.module] if node.module else [])])
            for alias in node.names:
                names[alias.asname or alias.name] = source
    return {name: source for name, source in names.items() if source.split(".")[0] == "semloc"}


def compiled_sources(package: Path) -> list[Path]:
    """The package's compiled modules and the semloc modules whose names their compiled
    functions use (sorted).  A module `semloc.a.b` is `a/b.py` or `a/b/__init__.py`."""
    found: set[Path] = set()
    for path in package.rglob("*.py"):
        source = path.read_bytes()
        if not any(name.encode() in source for name in COMPILERS):
            continue  # (parsing every module takes a while)
        tree = ast.parse(source)
        functions = _compiled_functions(tree)
        if not functions:
            continue
        found.add(path)
        imported = _imported_names(tree, ["semloc", *path.relative_to(package).parts[:-1]])
        used = {n.id for f in functions for n in ast.walk(f) if isinstance(n, ast.Name)}
        for name in used & imported.keys():
            relative = Path(*imported[name].split(".")[1:])
            for candidate in (
                package / relative.with_suffix(".py"),
                package / relative / "__init__.py",
            ):
                if candidate.is_file():
                    found.add(candidate)
    return sorted(found)


def sources_digest(package: Path) -> str:
    """A 16-hex-digit BLAKE2b digest of the package's compiled sources (`compiled_sources`):
    their paths and contents."""
    digest = hashlib.blake2b(digest_size=8)
    for path in compiled_sources(package):
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
