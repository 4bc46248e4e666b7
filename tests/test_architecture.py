"""The folder tree is the architecture: every package sits in a layer and imports only the
layers below it (`LAYERS`, the table the contributors' map in CONTRIBUTING.md describes).

Core modules (`CORE`, the top-level `semloc/*.py`) may import only each other (and numpy,
scipy, pydantic, numba, the standard library) — anywhere in the file, also inside functions.
Every import is seen: absolute and relative (`from . import x`, `from ..io import y`), at the
top of a file or inside a function, in `__init__.py` files too (`semloc/__init__.py` is the
layer `api`: what `import semloc` gives).  Function-local imports of semloc's own modules
stay few (heavy optional dependencies are the reason to import late).  `import semloc` loads
no extra.
"""

from __future__ import annotations

import ast
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import semloc

PACKAGE = Path(semloc.__file__).parent
CORE = {"maps", "pointsets", "transforms", "association", "clustering", "pose", "neighbours",
        "registration", "closed_form", "digests", "verification", "results", "decision", "localizer",
        "confidence_model", "_clustering_fast", "_verification_fast", "_decision_fast",
        "_alignment_fast", "alignment", "changes", "window", "tracking",
        "semantics", "compiling", "priors", "places", "_places_fast", "_twins_fast", "next_look",
        "coverage", "twins", "schema", "map_context", "sightings", "search",
        "copy_watch", "settings"}  # fmt: skip
LIBRARY = {"core", "descriptors", "frontend", "io", "pictures", "baselines", "sim", "eval"}
"""The layers below the adapters and the applications."""
LAYERS: dict[str, set[str]] = {
    # the library, bottom up
    "core": set(),  # the top-level modules: the paper's pipeline and its data
    "descriptors": {"core"},  # shape descriptors at run time
    "frontend": {"core"},  # RGB-D frames / 3D segments -> a local object map
    "io": {"core"},  # files: native maps, importers, atomic output, interrupts
    "pictures": {"core", "io"},  # figures, recordings, the live view, label colours
    "baselines": {"core", "descriptors", "frontend"},  # the comparison methods
    "sim": {"core", "descriptors", "frontend", "io", "pictures"},  # generated worlds, exports
    "eval": LIBRARY - {"eval"},  # the benchmark: protocol, runner, reports
    # the package's face: `import semloc` (core, io's load/save, descriptors, label colours)
    "api": {"core", "descriptors", "io", "pictures"},
    # adapters to the outside: none imports another, except ROS 2 live reusing the bags' parts
    "client": {"core", "io"},  # the service's client: standard library only, stays light
    "serve": {"core", "descriptors", "io", "api"},  # the HTTP service
    "ros": {"core", "descriptors", "frontend", "io", "pictures", "sim"},  # bags and MCAP
    "ros2": {"core", "descriptors", "frontend", "io", "pictures", "sim", "ros"},  # live DDS
    # the applications
    "tools": LIBRARY,  # demo, scandemo, merge
    "cli": LIBRARY | {"api", "client", "serve", "ros", "ros2", "tools"},  # `semloc`
    "entry": {"cli"},  # `semloc_entry` (outside the package): the script, signals held first
    "main": {"entry", "cli"},  # the `__main__.py` files: `python -m semloc` runs the script
}
"""Which layers each layer may import, besides itself (`_layer` names a file's layer)."""
EXCEPTIONS = {
    (
        "semloc/__init__.py",
        "entry",
    ): "`python -m semloc` holds Ctrl-C from the package's first line "
    "(`semloc_entry.hold_signals_for_module`, only when run with -m); semloc_entry imports "
    "nothing of semloc at its top, its `main` imports the CLI when called",
    (
        "semloc/pictures/viz.py",
        "sim",
    ): "`plot_world` draws a `semloc.sim.world.World`: imported for "
    "its type only (`if TYPE_CHECKING`), so loading pictures never loads the simulator",
}
"""(file, layer) imports allowed against the table, each with its reason."""
THIRD_PARTY_CORE = {"numpy", "scipy", "pydantic", "numba"}
EXTRAS = ("open3d", "matplotlib", "dask", "distributed", "sklearn", "torch", "rerun", "fastapi", "cv2",
          "uvicorn", "starlette", "psycopg", "prometheus_client", "rosbags", "mcap", "spark_dsg",
          "cyclonedds")  # fmt: skip
MAX_LOCAL_SEMLOC_IMPORTS = 12  # + `semloc serve` importing its extra when run, `semloc tokens`
# checking a token file with the service's own reader (the serve extra, only when run)


def _imports(path: Path, package: Path = PACKAGE) -> list[tuple[list[str], bool]]:
    """Per import statement of a file of `package`: the modules it imports, and whether it
    sits inside a function.  Relative imports are resolved (`from ..io import y` in
    `semloc/sim/x.py` imports `semloc.io.y` if that is a module, else `semloc.io`), and so is
    `from a import b` (`a.b` when it is a module, else `a`)."""
    parts = path.relative_to(package).parts[:-1] if path.is_relative_to(package) else ()
    here = ["semloc", *parts]  # the file's package
    found: list[tuple[list[str], bool]] = []

    def visit(node: ast.AST, in_function: bool) -> None:
        for child in ast.iter_child_nodes(node):
            inside = in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef))
            if isinstance(child, ast.Import):
                found.append(([alias.name for alias in child.names], inside))
            elif isinstance(child, ast.ImportFrom):
                base = here[: len(here) - child.level + 1] if child.level else []
                module = ".".join([*base, *([child.module] if child.module else [])])
                names = [f"{module}.{alias.name}" for alias in child.names]
                found.append(([n if _is_module(n, package) else module for n in names], inside))
            visit(child, inside)

    visit(ast.parse(path.read_text()), False)
    return found


def _is_module(name: str, package: Path) -> bool:
    """Whether `name` (semloc.a.b) is a module or package of the tree at `package`."""
    parts = name.split(".")
    if parts[0] != "semloc":
        return False
    where = package.joinpath(*parts[1:])
    return where.with_suffix(".py").is_file() or (where / "__init__.py").is_file()


def _file_layer(path: Path, package: Path = PACKAGE) -> str:
    """The layer of a file of the package: `main` for a `__main__.py`; else its subpackage, or
    for a top-level module `core`, or `api` (`__init__.py`: what `import semloc` gives)."""
    if path.name == "semloc_entry.py":
        return "entry"
    parts = path.relative_to(package).parts
    if path.name == "__main__.py":
        return "main"
    return parts[0] if len(parts) > 1 else "api" if parts[0] == "__init__.py" else "core"


def _module_layer(name: str, package: Path = PACKAGE) -> str | None:
    """The layer of an imported module (None: not semloc's)."""
    parts = name.split(".")
    if parts[0] == "semloc_entry":
        return "entry"
    if parts[0] != "semloc":
        return None
    if len(parts) == 1:
        return "api"
    return parts[1] if (package / parts[1]).is_dir() else "core"


def layering_violations(package: Path = PACKAGE) -> list[str]:
    """Every import of the tree at `package` that `LAYERS` (and `EXCEPTIONS`) does not allow."""
    found = []
    script = package.parent / "semloc_entry.py"  # beside the package: the layer `entry`
    for path in [*sorted(package.rglob("*.py")), *([script] if script.exists() else [])]:
        layer, name = _file_layer(path, package), path.relative_to(package.parent).as_posix()
        if layer not in LAYERS:
            found.append(f"{name}: the package {layer!r} has no row in LAYERS")
            continue
        for modules, _ in _imports(path, package):
            for module in modules:
                other = _module_layer(module, package)
                allowed = other in (None, layer) or other in LAYERS[layer]
                if not allowed and (name, other) not in EXCEPTIONS:
                    found.append(f"{name} imports {module}: {layer} may not import {other}")
    return found


def _module_files(*parts: str) -> list[Path]:
    return sorted(PACKAGE.joinpath(*parts).rglob("*.py"))


# The one optional import of the core: `ObjectMap.to_open3d` imports open3d when called
# (interop for users who have it); `_open3d_only_in_to_open3d` checks it is only there.
CORE_EXCEPTIONS = {("maps.py", "open3d")}


def _check_imports(path: Path, allowed: set[str]) -> None:
    """Only the layers `allowed`, numpy, scipy, pydantic, numba and the standard library."""
    for modules, _ in _imports(path):
        for module in modules:
            top = module.split(".")[0]
            if (path.name, top) in CORE_EXCEPTIONS:
                continue
            if top == "semloc":
                assert _module_layer(module) in allowed, f"{path.name} imports {module}"
            else:
                assert top in THIRD_PARTY_CORE or top in sys.stdlib_module_names, (
                    f"{path.name} imports {module}"
                )


def test_the_tree_keeps_the_layers():
    assert layering_violations() == []


def test_every_package_has_a_layer_and_the_layers_have_no_cycle():
    """A new subpackage gets its row in `LAYERS`; following the table downwards never comes
    back to where it started."""
    packages = {path.parent.name for path in PACKAGE.glob("*/__init__.py")}
    assert packages <= LAYERS.keys(), packages - LAYERS.keys()
    assert all(below <= LAYERS.keys() for below in LAYERS.values())

    def below(layer: str, seen: tuple[str, ...]) -> None:
        assert layer not in seen, " -> ".join([*seen, layer])
        for lower in LAYERS[layer]:
            below(lower, (*seen, layer))

    for layer in LAYERS:
        below(layer, ())


def test_every_exception_is_still_needed():
    used = {(path.relative_to(PACKAGE.parent).as_posix(), _module_layer(module))
            for path in _module_files() for modules, _ in _imports(path) for module in modules}  # fmt: skip
    assert EXCEPTIONS.keys() <= used, EXCEPTIONS.keys() - used


@pytest.fixture
def tree(tmp_path: Path) -> Path:
    """A copy of the package's Python files and the script beside it, to plant imports in."""
    copy = tmp_path / "semloc"
    shutil.copytree(PACKAGE, copy, ignore=lambda folder, names: [
        n for n in names if not n.endswith(".py") and not (Path(folder) / n).is_dir()
        or n == "__pycache__"])  # fmt: skip
    shutil.copy(PACKAGE.parent / "semloc_entry.py", tmp_path)  # the script beside it
    assert layering_violations(copy) == []
    return copy


PLANTED = [  # (file, planted line(s), the layers the rule must name)
    ("io/planted.py", "from ..serve import app\n", "io may not import serve"),
    ("eval/report.py", "def late():\n    from semloc import client\n", "eval may not import client"),
    ("client/__init__.py", "from semloc.ros2.node import LiveNode\n", "client may not import ros2"),
    ("serve/app.py", "from ..ros import bag\n", "serve may not import ros"),
    ("__init__.py", "from semloc_entry import main\nfrom . import cli\n", "api may not import cli"),
    ("maps.py", "def f():\n    from .sim import world\n", "core may not import sim"),
    ("sim/world.py", "from .. import tools\n", "sim may not import tools"),
    ("pictures/live.py", "from semloc.sim.world import World\n", "pictures may not import sim"),
    ("newpart/__init__.py", "", "the package 'newpart' has no row in LAYERS"),
    ("../semloc_entry.py", "import semloc.serve\n", "entry may not import serve"),
]  # fmt: skip


@pytest.mark.parametrize(("file", "planted", "named"), PLANTED, ids=[p[0] for p in PLANTED])
def test_a_planted_import_is_caught_by_the_rule(tree, file, planted, named):
    """The rule itself (`layering_violations`), on a copy of the tree with one bad import
    planted: relative, inside a function, in an `__init__.py`, in a new file."""
    path = tree / file
    path.parent.mkdir(exist_ok=True)
    path.write_text((path.read_text() if path.exists() else "") + "\n" + planted)
    found = layering_violations(tree)
    assert len(found) == 1 and named in found[0], found


def test_core_imports_only_the_core():
    for name in CORE:
        _check_imports(PACKAGE / f"{name}.py", {"core"})


def test_the_top_level_is_the_core_alone():
    """Applications (the demo) live in `semloc.tools`, pictures in `semloc.pictures`, not
    beside the core."""
    top = {path.stem for path in PACKAGE.glob("*.py")} - {"__init__", "__main__"}
    assert top == CORE


def test_open3d_is_imported_only_in_to_open3d():
    tree = ast.parse((PACKAGE / "maps.py").read_text())
    places = [
        function.name
        for function in ast.walk(tree)
        if isinstance(function, ast.FunctionDef)
        for node in ast.walk(function)
        if isinstance(node, ast.Import) and any(a.name == "open3d" for a in node.names)
    ]
    every = [n for n in ast.walk(tree) if isinstance(n, (ast.Import, ast.ImportFrom))
             and "open3d" in [a.name for a in n.names] + [getattr(n, "module", None)]]  # fmt: skip
    assert places == ["to_open3d"] and len(every) == 1


def test_runtime_descriptors_import_only_the_core_and_themselves():
    for path in _module_files("descriptors"):
        _check_imports(path, {"core", "descriptors"})


def test_few_function_local_imports_of_semloc_modules():
    local = [
        f"{path.relative_to(PACKAGE)}: {modules[0]}"
        for path in _module_files()
        for modules, inside in _imports(path)
        if inside and modules[0].split(".")[0] == "semloc"
    ]
    assert len(local) <= MAX_LOCAL_SEMLOC_IMPORTS, local


def test_import_semloc_loads_no_extra():
    code = "import sys, semloc; print(','.join(m for m in sys.modules if m.split('.')[0] in %r))"
    out = subprocess.run(
        [sys.executable, "-c", code % (EXTRAS,)], capture_output=True, text=True, check=True
    ).stdout.strip()
    assert out == "", f"import semloc loaded {out}"


def test_the_contributors_map_names_every_module_and_package():
    """CONTRIBUTING.md's map of the code matches the tree: every top-level module (`x.py`)
    and every package (`x/`) of `src/semloc` is in it."""
    guide = (PACKAGE.parents[1] / "CONTRIBUTING.md").read_text()
    names = [f"{path.name}" for path in PACKAGE.glob("*.py")]
    names += [f"{path.parent.name}/" for path in PACKAGE.glob("*/__init__.py")]
    assert [name for name in names if not re.search(rf"(?<![\w/]){re.escape(name)}", guide)] == []
