"""The dataset importers, one registry: `IMPORTERS` (name -> `Importer`), and `convert`.

Each module of this package reads one dataset (ScanNet, Scan2CAD, Replica, 3RScan, Spark-DSG
scene graphs) and defines
`IMPORTER`; adding a dataset is one new module and one entry in the tuple below.  `semloc
convert`'s kinds and help are built from the registry.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from semloc.io.importers import dsg, replica, rscan, scan2cad, scannet
from semloc.io.importers.base import COMMON_OPTIONS, Importer, Maps

IMPORTERS: dict[str, Importer] = {
    m.IMPORTER.name: m.IMPORTER for m in (scannet, scan2cad, replica, rscan, dsg)
}

_DEFAULTS: dict[str, Any] = {"label_map": None, "shapenet": None, "scan_dir": None, "scene": None,
                             "keep_unlabeled": False}  # fmt: skip


def convert(kind: str, source: str | os.PathLike[str], **options: Any) -> Maps:
    """Import `source` of dataset `kind`: `(map, second map or None)`.

    Options: the common ones (`labels`, `include_structure`, `voxel`, `seed`) and those the
    importer accepts; another option given with a non-default value is refused."""
    if kind not in IMPORTERS:
        raise ValueError(f"unknown kind {kind!r}; choose one of {', '.join(IMPORTERS)}")
    importer = IMPORTERS[kind]
    unknown = set(options) - set(COMMON_OPTIONS) - set(_DEFAULTS)
    if unknown:
        raise TypeError(f"unknown options {sorted(unknown)}")
    for option, default in _DEFAULTS.items():
        if option not in importer.options and options.get(option, default) not in (None, default):
            raise ValueError(f"--{option.replace('_', '-')} does not apply to {kind}")
    if options.get("voxel", 0.05) < 0:
        raise ValueError(f"voxel must be >= 0, got {options['voxel']}")
    given = {"labels": None, "include_structure": False, "voxel": 0.05, "seed": 0}
    given.update({k: v for k, v in options.items() if k in COMMON_OPTIONS})
    given.update({k: options.get(k, _DEFAULTS[k]) for k in importer.options})
    return importer(Path(source), **given)


__all__ = ["IMPORTERS", "Importer", "convert"]
