"""Reading and writing maps: the native semloc format, and importers for public datasets.

One module per concern: `native` (the map file), `reading` (guarded reading of input files:
size limits, strict JSON, `.npy` headers), `output` (files written all or none),
`interrupts` (all handling of SIGINT and SIGTERM), `ply`, `labels`, `g2o`, `geometry`, and `importers/`.  The names below are the
package's own API.

The dataset importers (`semloc.io.importers`, one registry; `load_scannet`, `load_scan2cad`,
`load_replica`, `load_rscan` here) are imported on first use, so that `import semloc` stays
light.
"""

from typing import Any

from semloc.io.native import load_map, map_files, map_from_dict, map_to_dict, save_map
from semloc.io.output import staged_folder, write_atomic, write_files
from semloc.io.reading import read_json, read_regular

_LOADERS = ("load_scannet", "load_scan2cad", "load_replica", "load_rscan")

__all__ = [
    "read_json",
    "load_map",
    "map_from_dict",
    "map_to_dict",
    "save_map",
    "write_atomic",
    "write_files",
    "map_files",
    "read_regular",
    "staged_folder",
    *_LOADERS,
]


def __getattr__(name: str) -> Any:
    if name in _LOADERS:  # semloc.io.importers.<dataset>.load_<dataset>, read on first use
        import importlib

        module = importlib.import_module(f"semloc.io.importers.{name.removeprefix('load_')}")
        return getattr(module, name)
    raise AttributeError(f"module 'semloc.io' has no attribute {name!r}")
