"""Reading and writing maps: the native semloc format, and importers for public datasets.

The dataset importers (`load_scannet`, `load_scan2cad`, `load_replica`, `load_rscan`) are
imported on first use, so that `import semloc` stays light.
"""

from typing import Any

from semloc.io.native import (
    load_map,
    map_from_dict,
    map_to_dict,
    read_json,
    save_map,
    write_atomic,
)

_IMPORTERS = {
    "load_scannet": "semloc.io.scannet",
    "load_scan2cad": "semloc.io.scan2cad",
    "load_replica": "semloc.io.replica",
    "load_rscan": "semloc.io.rscan",
}

__all__ = [
    "read_json",
    "load_map",
    "map_from_dict",
    "map_to_dict",
    "save_map",
    "write_atomic",
    *_IMPORTERS,
]


def __getattr__(name: str) -> Any:
    if name in _IMPORTERS:
        import importlib

        return getattr(importlib.import_module(_IMPORTERS[name]), name)
    raise AttributeError(f"module 'semloc.io' has no attribute {name!r}")
