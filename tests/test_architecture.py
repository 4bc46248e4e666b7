"""The folder tree is the architecture: the core imports nothing from the applications.

Core modules (`CORE`) may import only each other (and numpy, scipy, pydantic, numba,
the standard library) — anywhere in the file, also inside functions.  The run-time
descriptors import only the core.  Function-local imports of semloc's own modules stay few
(heavy optional dependencies are the reason to import late).  `import semloc` loads no extra.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import semloc

PACKAGE = Path(semloc.__file__).parent
CORE = {"maps", "pointsets", "transforms", "association", "clustering", "pose", "neighbours",
        "registration", "closed_form", "digests", "verification", "results", "decision", "localizer",
        "confidence_model", "_clustering_fast", "_verification_fast", "_decision_fast",
        "_alignment_fast", "alignment", "changes", "window", "tracking",
        "semantics", "compiling", "priors", "places", "_places_fast", "next_look",
        "coverage"}  # fmt: skip
APPLICATIONS = {"tools", "cli"}
"""The applications: nothing below them imports them."""
BELOW_APPLICATIONS = ("io", "pictures", "sim", "eval", "baselines", "frontend", "descriptors")
THIRD_PARTY_CORE = {"numpy", "scipy", "pydantic", "numba"}
EXTRAS = ("open3d", "matplotlib", "dask", "distributed", "sklearn", "torch", "rerun", "fastapi", "cv2",
          "uvicorn", "starlette", "psycopg", "prometheus_client", "rosbags", "mcap", "spark_dsg",
          "cyclonedds")  # fmt: skip
MAX_LOCAL_SEMLOC_IMPORTS = 11  # + `semloc serve` importing its extra when run


def _imports(path: Path) -> list[tuple[list[str], bool]]:
    """Per import statement of a file: the modules it may load, and whether it sits inside a
    function.  `from a import b` may load `a` and `a.b`."""
    found: list[tuple[list[str], bool]] = []

    def visit(node: ast.AST, in_function: bool) -> None:
        for child in ast.iter_child_nodes(node):
            inside = in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef))
            if isinstance(child, ast.Import):
                found.append(([alias.name for alias in child.names], inside))
            elif isinstance(child, ast.ImportFrom) and child.level == 0 and child.module:
                names = [f"{child.module}.{alias.name}" for alias in child.names]
                found.append(([child.module, *names], inside))
            visit(child, inside)

    visit(ast.parse(path.read_text()), False)
    return found


def _semloc_part(module: str) -> str | None:
    """The first part below `semloc` of a module name (None for other modules)."""
    parts = module.split(".")
    return parts[1] if parts[0] == "semloc" and len(parts) > 1 else None


def _module_files(*parts: str) -> list[Path]:
    return sorted(PACKAGE.joinpath(*parts).rglob("*.py"))


# The one optional import of the core: `ObjectMap.to_open3d` imports open3d when called
# (interop for users who have it); `_open3d_only_in_to_open3d` checks it is only there.
CORE_EXCEPTIONS = {("maps.py", "open3d")}


def _check_imports(path: Path, allowed: set[str]) -> None:
    for modules, _ in _imports(path):
        top = modules[0].split(".")[0]
        if (path.name, top) in CORE_EXCEPTIONS:
            continue
        if top == "semloc":
            part = _semloc_part(modules[0])
            assert part in allowed, f"{path.name} imports {modules[0]}"
        else:
            assert top in THIRD_PARTY_CORE or top in sys.stdlib_module_names, (
                f"{path.name} imports {modules[0]}"
            )


def test_core_imports_only_the_core():
    for name in CORE:
        _check_imports(PACKAGE / f"{name}.py", CORE)


def test_nothing_below_the_applications_imports_them():
    """The simulator's exports and the evaluation's reports draw with `semloc.pictures`, and
    the package's top level (`import semloc`) loads no application: no import climbs up."""
    files = [
        PACKAGE / "__init__.py",
        *(f for part in BELOW_APPLICATIONS for f in _module_files(part)),
    ]
    for path in files:
        for modules, _ in _imports(path):
            part = _semloc_part(modules[0])
            assert part not in APPLICATIONS, f"{path.relative_to(PACKAGE)} imports {modules[0]}"


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
        _check_imports(path, CORE | {"descriptors"})


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


def test_a_planted_upward_import_is_caught(tmp_path):
    bad = tmp_path / "bad.py"
    bad.write_text("def f():\n    from semloc.sim.world import World\n    return World\n")
    assert (["semloc.sim.world", "semloc.sim.world.World"], True) in _imports(bad)
