"""One entry point over the dataset importers, as used by `semloc convert`.

`convert(kind, source, **options)` calls `load_scannet`, `load_scan2cad`, `load_replica` or
`load_rscan` with the options that importer understands and returns `(map, second_map)`;
`second_map` is Scan2CAD's scan-derived map and None for the other kinds.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from semloc.io.labels import read_label_map
from semloc.io.replica import load_replica
from semloc.io.rscan import load_rscan
from semloc.io.scan2cad import load_scan2cad
from semloc.io.scannet import load_scannet
from semloc.maps import ObjectMap

KINDS = ("scannet", "scan2cad", "replica", "3rscan")


def convert(
    kind: str,
    source: str | os.PathLike[str],
    *,
    labels: str | None = None,
    label_map: str | os.PathLike[str] | None = None,
    include_structure: bool = False,
    keep_unlabeled: bool = False,
    voxel: float = 0.05,
    shapenet: str | os.PathLike[str] | None = None,
    scan_dir: str | os.PathLike[str] | None = None,
    scene: str | None = None,
    seed: int = 0,
) -> tuple[ObjectMap, ObjectMap | None]:
    """Import `source` of dataset `kind`; options that do not apply to `kind` are refused."""
    if kind not in KINDS:
        raise ValueError(f"unknown kind {kind!r}; choose one of {', '.join(KINDS)}")
    _refuse(
        kind,
        label_map=label_map,
        shapenet=shapenet,
        scan_dir=scan_dir,
        scene=scene,
        keep_unlabeled=keep_unlabeled or None,
    )
    if voxel < 0:
        raise ValueError(f"voxel must be >= 0, got {voxel}")
    source = Path(source)
    if kind == "scannet":
        mapping = None if label_map is None else read_label_map(label_map)
        objmap = load_scannet(
            source,
            labels=labels or ("nyu40" if mapping else "raw"),
            label_map=mapping,
            include_structure=include_structure,
            voxel=voxel,
        )
        return objmap, None
    if kind == "scan2cad":
        maps = load_scan2cad(
            source,
            shapenet=shapenet,
            scan_dir=scan_dir,
            scene=scene,
            labels=labels or "nyu40",
            include_structure=include_structure,
            voxel=voxel,
            seed=seed,
        )
        return maps.cad, maps.scan
    if kind == "replica":
        if labels is not None:
            raise ValueError("replica has one label vocabulary; --labels does not apply")
        objmap = load_replica(
            source, include_structure=include_structure, keep_unlabeled=keep_unlabeled, seed=seed
        )
        return objmap, None
    objmap = load_rscan(
        source,
        labels=labels or "nyu40",
        include_structure=include_structure,
        keep_unlabeled=keep_unlabeled,
        voxel=voxel,
    )
    return objmap, None


_APPLIES = {
    "label_map": {"scannet"},
    "shapenet": {"scan2cad"},
    "scan_dir": {"scan2cad"},
    "scene": {"scan2cad"},
    "keep_unlabeled": {"replica", "3rscan"},
}


def _refuse(kind: str, **given: Any) -> None:
    for option, value in given.items():
        if value is not None and kind not in _APPLIES[option]:
            flag = "--" + option.replace("_", "-")
            raise ValueError(f"{flag} does not apply to {kind}")
