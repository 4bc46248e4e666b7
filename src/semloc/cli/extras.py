"""Which optional extra each command needs, and the one-line error when it is not installed.

The core install (`pip install semloc`) runs `localize`, `convert`, `crop`, `export` and
`config`; the other commands need an extra (`pip install 'semloc[sim]'`).  `need("sim")`
checks that the extra's modules can be imported, without importing them, and otherwise
fails with one line naming the extra (exit status 2).
"""

from __future__ import annotations

import importlib.util

from semloc.cli.app import fail

EXTRAS: dict[str, tuple[str, ...]] = {
    "viz": ("matplotlib", "rerun"),
    "sim": ("open3d",),
    "bench": ("dask", "distributed", "sklearn", "matplotlib", "cv2"),
    "train": ("torch",),
    "serve": ("fastapi", "fastapi_offline", "uvicorn", "prometheus_client"),
    "ros": ("rosbags", "mcap"),
    "ros2": ("cyclonedds", "rosbags"),
    "dsg": ("spark_dsg",),
}
"""The top-level modules each extra of pyproject.toml brings."""


def missing(module: str) -> bool:
    """Whether `module` cannot be imported (checked without importing it)."""
    try:
        return importlib.util.find_spec(module) is None
    except ValueError:  # a module object without a spec (left behind by a failed import)
        return True


def need(command: str, *extras: str, modules: tuple[str, ...] | None = None) -> None:
    """Fail naming the first of `extras` whose modules (or `modules` of it) are missing."""
    for extra in extras:
        wanted = EXTRAS[extra] if modules is None else modules
        absent = [m for m in wanted if missing(m)]
        if absent:
            fail(
                f"semloc {command} needs the '{extra}' extra ({absent[0]} is not installed): "
                f"pip install 'semloc[{extra}]'"
            )
