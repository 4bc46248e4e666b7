"""Spark-DSG / Hydra scene graphs (`semloc convert dsg GRAPH`): the object layer of a graph as a
map, by `semloc.io.dsg` (the `semloc[dsg]` extra)."""

from __future__ import annotations

from semloc.io.dsg import load_dsg
from semloc.io.importers.base import Importer, Maps


def _convert(source, *, labels, include_structure, voxel, seed) -> Maps:
    if labels is not None:
        raise ValueError("--labels does not apply to dsg: labels are the graph's label space names")
    return load_dsg(source, voxel=voxel), None


IMPORTER = Importer("dsg", _convert, "a Spark-DSG scene graph (.json or binary; the dsg extra)")
