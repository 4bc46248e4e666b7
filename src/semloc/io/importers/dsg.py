"""Spark-DSG / Hydra scene graphs (`semloc convert dsg GRAPH`): the object layer of a graph as a
map, by `semloc.io.dsg` (the `semloc[dsg]` extra).  `--label-map` (JSON `{"3": "chair"}`) names
label numbers the graph's label space does not (older graphs carry none)."""

from __future__ import annotations

from semloc.io.dsg import load_dsg
from semloc.io.importers.base import Importer, Maps
from semloc.io.labels import read_label_map
from semloc.maps import MapError


def _convert(source, *, labels, include_structure, voxel, seed, label_map) -> Maps:
    if labels is not None:
        raise ValueError("--labels does not apply to dsg: labels are the graph's label space names")
    names = None if label_map is None else _numbered(label_map)
    return load_dsg(source, voxel=voxel, names=names), None


def _numbered(path) -> dict[int, str]:
    """A label map of label numbers to names."""
    names = {}
    for key, name in read_label_map(path).items():
        try:
            names[int(key)] = name.strip()
        except ValueError:
            raise MapError(
                f"{path}: for dsg the label map's keys are label numbers, got {key!r}"
            ) from None
    return names


IMPORTER = Importer(
    "dsg", _convert, "a Spark-DSG scene graph (.json or binary; the dsg extra)",
    options=frozenset({"label_map"}),
)  # fmt: skip
