"""Label vocabularies of the public datasets (NYU40, Eigen13, RIO27), structural classes and
user label maps (`--label-map`: a JSON object `{"raw": "mapped"}` or ScanNet's
`scannetv2-labels.combined.tsv` with `raw_category` and `nyu40class` columns)."""

from __future__ import annotations

import csv
import os
from pathlib import Path

from semloc.io.reading import MAX_JSON_BYTES, read_json, read_regular
from semloc.maps import MapError

NYU40 = (
    "unlabeled",
    "wall",
    "floor",
    "cabinet",
    "bed",
    "chair",
    "sofa",
    "table",
    "door",
    "window",
    "bookshelf",
    "picture",
    "counter",
    "blinds",
    "desk",
    "shelves",
    "curtain",
    "dresser",
    "pillow",
    "mirror",
    "floor mat",
    "clothes",
    "ceiling",
    "books",
    "refrigerator",
    "television",
    "paper",
    "towel",
    "shower curtain",
    "box",
    "whiteboard",
    "person",
    "nightstand",
    "toilet",
    "sink",
    "lamp",
    "bathtub",
    "bag",
    "otherstructure",
    "otherfurniture",
    "otherprop",
)
EIGEN13 = (
    "unlabeled",
    "bed",
    "books",
    "ceiling",
    "chair",
    "floor",
    "furniture",
    "objects",
    "picture",
    "sofa",
    "table",
    "tv",
    "wall",
    "window",
)
RIO27 = (
    "unlabeled",
    "wall",
    "floor",
    "cabinet",
    "bed",
    "chair",
    "sofa",
    "table",
    "door",
    "window",
    "counter",
    "shelf",
    "curtain",
    "pillow",
    "clothes",
    "ceiling",
    "fridge",
    "tv",
    "towel",
    "plant",
    "box",
    "nightstand",
    "toilet",
    "sink",
    "lamp",
    "bathtub",
    "object",
    "blanket",
)
LABEL_SETS = {"nyu40": NYU40, "eigen13": EIGEN13, "rio27": RIO27}

STRUCTURAL = frozenset({"wall", "walls", "floor", "ceiling"})
UNLABELED = frozenset({"", "unlabeled", "unlabelled", "undefined", "unknown", "non-plane"})


def is_structural(label: str) -> bool:
    """Wall, floor or ceiling (case-insensitive)."""
    return label.strip().lower() in STRUCTURAL


def is_unlabeled(label: str) -> bool:
    """A placeholder class for unannotated geometry (unlabeled, undefined, non-plane ...)."""
    return label.strip().lower() in UNLABELED


def class_name(label_set: str, index: int, where: str) -> str:
    """Name of class `index` in `label_set`; `MapError` mentioning `where` when out of range."""
    names = LABEL_SETS[label_set]
    if not 0 <= index < len(names):
        raise MapError(f"{where}: unknown {label_set.upper()} class id {index}")
    return names[index]


def read_label_map(path: str | os.PathLike[str]) -> dict[str, str]:
    """Read a label map: JSON `{"raw": "mapped"}` or a TSV with `raw_category`, `nyu40class`."""
    path = Path(path)
    if path.suffix.lower() == ".json":
        mapping = read_json(path, "label map")
        if not isinstance(mapping, dict) or not all(
            isinstance(k, str) and isinstance(v, str) and v.strip() for k, v in mapping.items()
        ):
            raise MapError(f"{path}: label map must be an object of non-empty strings")
        return {k.strip().lower(): v for k, v in mapping.items()}
    try:
        text = read_regular(path, MAX_JSON_BYTES, "label map").decode("utf-8")
    except UnicodeDecodeError as exc:
        raise MapError(f"{path}: label map is not UTF-8 text (byte {exc.start})") from None
    try:
        rows = list(csv.DictReader(text.splitlines(), delimiter="\t"))
    except csv.Error as exc:
        raise MapError(f"{path}: not a readable TSV label map ({exc})") from None
    columns = set(rows[0]) if rows else set()
    if not {"raw_category", "nyu40class"} <= columns:
        raise MapError(f"{path}: label map TSV needs columns 'raw_category' and 'nyu40class'")
    return {
        row["raw_category"].strip().lower(): row["nyu40class"].strip()
        for row in rows
        if row["raw_category"] and row["nyu40class"] and row["nyu40class"].strip()
    }
