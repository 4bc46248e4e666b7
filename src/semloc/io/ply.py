"""Reading PLY files (ScanNet meshes and label meshes) with numpy, and precise errors.

A PLY file is a text header (`ply`, `format ...`, `element NAME COUNT`, `property TYPE NAME`,
`property list COUNT_TYPE ITEM_TYPE NAME`, `end_header`) followed by the element data, binary
(little or big endian) or ASCII.  `read_ply` returns the vertex records as a numpy structured
array and the faces as an (M, 3) index array (triangles; polygons are fanned).  A truncated
body, a count that does not match the data or an unsupported layout raises `MapError` naming
the file and the problem.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from semloc.io.output import write_atomic
from semloc.io.reading import read_regular
from semloc.maps import MapError

_TYPES = {
    "char": "i1",
    "int8": "i1",
    "uchar": "u1",
    "uint8": "u1",
    "short": "i2",
    "int16": "i2",
    "ushort": "u2",
    "uint16": "u2",
    "int": "i4",
    "int32": "i4",
    "uint": "u4",
    "uint32": "u4",
    "float": "f4",
    "float32": "f4",
    "double": "f8",
    "float64": "f8",
}
_FORMATS = {"binary_little_endian": "<", "binary_big_endian": ">", "ascii": "ascii"}


@dataclass(frozen=True)
class PlyProperty:
    name: str
    dtype: str  # numpy type code without byte order
    count_dtype: str | None = None  # set for list properties


@dataclass(frozen=True)
class PlyElement:
    name: str
    count: int
    properties: tuple[PlyProperty, ...]


@dataclass(frozen=True)
class PlyHeader:
    format: str  # "<", ">" or "ascii"
    elements: tuple[PlyElement, ...]
    length: int  # bytes up to and including the end_header line


@dataclass(frozen=True)
class PlyMesh:
    vertices: np.ndarray  # structured array, one record per vertex
    faces: np.ndarray  # (M, 3) int64 vertex indices; (0, 3) when the file has no faces


def parse_header(data: bytes) -> PlyHeader:
    """Parse the header at the start of `data`; raise `MapError` (without file name) if bad."""
    if not data.startswith(b"ply"):
        raise MapError("not a PLY file (no 'ply' magic)")
    end = data.find(b"end_header")
    if end < 0:
        raise MapError("PLY header has no 'end_header'")
    newline = data.find(b"\n", end)
    length = len(data) if newline < 0 else newline + 1
    try:
        lines = data[:end].decode("ascii").splitlines()[1:]
    except UnicodeDecodeError:
        raise MapError("PLY header is not ASCII") from None
    fmt: str | None = None
    elements: list[tuple[str, int, list[PlyProperty]]] = []
    for number, line in enumerate(lines, start=2):
        words = line.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        fmt = _header_line(words, number, fmt, elements)
    if fmt is None:
        raise MapError("PLY header has no 'format' line")
    return PlyHeader(fmt, tuple(PlyElement(n, c, tuple(p)) for n, c, p in elements), length)


def _header_line(words: list[str], number: int, fmt: str | None, elements: list) -> str | None:
    keyword = words[0]
    if keyword == "format":
        if len(words) != 3 or words[1] not in _FORMATS:
            raise MapError(f"PLY header line {number}: unsupported format {' '.join(words[1:])!r}")
        return _FORMATS[words[1]]
    if keyword == "element":
        if len(words) != 3 or not words[2].isdigit():
            raise MapError(f"PLY header line {number}: bad element line {' '.join(words)!r}")
        elements.append((words[1], int(words[2]), []))
        return fmt
    if keyword == "property":
        if not elements:
            raise MapError(f"PLY header line {number}: property before any element")
        prop = _property(words, number)
        if any(p.name == prop.name for p in elements[-1][2]):
            raise MapError(
                f"PLY header line {number}: property {prop.name!r} occurs more than once"
            )
        elements[-1][2].append(prop)
        return fmt
    raise MapError(f"PLY header line {number}: unknown keyword {keyword!r}")


def _property(words: list[str], number: int) -> PlyProperty:
    if len(words) == 5 and words[1] == "list":
        if words[2] not in _TYPES or words[3] not in _TYPES:
            raise MapError(f"PLY header line {number}: unknown list type in {' '.join(words)!r}")
        return PlyProperty(words[4], _TYPES[words[3]], _TYPES[words[2]])
    if len(words) != 3 or words[1] not in _TYPES:
        raise MapError(f"PLY header line {number}: bad property line {' '.join(words)!r}")
    return PlyProperty(words[2], _TYPES[words[1]])


def read_ply(path: str | os.PathLike[str]) -> PlyMesh:
    """Read the `vertex` and `face` elements of a PLY file; raise `MapError` naming the file."""
    path = Path(path)
    data = read_regular(path)
    try:
        return _read(data)
    except MapError as exc:
        raise MapError(f"{path}: {exc}") from None


def _read(data: bytes) -> PlyMesh:
    header = parse_header(data)
    names = [e.name for e in header.elements]
    if "vertex" not in names:
        raise MapError("PLY file has no 'vertex' element")
    if header.format == "ascii":
        return _read_ascii(data[header.length :], header)
    offset = header.length
    vertices, faces = None, np.zeros((0, 3), dtype=np.int64)
    for element in header.elements:
        if element.name == "face":
            faces, offset = _binary_faces(data, offset, element, header.format)
        else:
            records, offset = _binary_records(data, offset, element, header.format)
            if element.name == "vertex":
                vertices = records
    assert vertices is not None
    if faces.size and faces.max() >= len(vertices):
        raise MapError(f"face refers to vertex {faces.max()} but there are {len(vertices)}")
    if faces.size and faces.min() < 0:
        raise MapError(f"face refers to vertex {faces.min()} (negative index)")
    return PlyMesh(vertices, faces)


def _binary_records(
    data: bytes, offset: int, element: PlyElement, order: str
) -> tuple[np.ndarray, int]:
    if any(p.count_dtype for p in element.properties):
        raise MapError(f"list properties in element '{element.name}' are not supported")
    dtype = np.dtype([(p.name, order + p.dtype) for p in element.properties])
    need = dtype.itemsize * element.count
    if len(data) - offset < need:
        raise MapError(
            f"truncated: element '{element.name}' declares {element.count} records "
            f"({need} bytes) but only {max(len(data) - offset, 0)} bytes remain"
        )
    records = np.frombuffer(data, dtype=dtype, count=element.count, offset=offset)
    return records, offset + need


def _binary_faces(
    data: bytes, offset: int, element: PlyElement, order: str
) -> tuple[np.ndarray, int]:
    lists = [p for p in element.properties if p.count_dtype]
    if len(lists) != 1 or len(element.properties) != 1:
        raise MapError("face element must have exactly one list property (vertex_indices)")
    prop = lists[0]
    count_type, item_type = np.dtype(order + prop.count_dtype), np.dtype(order + prop.dtype)
    triangle = np.dtype([("n", count_type), ("v", item_type, (3,))])
    need = triangle.itemsize * element.count
    if len(data) - offset >= need and element.count:
        faces = np.frombuffer(data, dtype=triangle, count=element.count, offset=offset)
        if np.all(faces["n"] == 3):
            return faces["v"].astype(np.int64), offset + need
    return _binary_polygons(data, offset, element.count, count_type, item_type)


def _binary_polygons(
    data: bytes, offset: int, count: int, count_type: np.dtype, item_type: np.dtype
) -> tuple[np.ndarray, int]:
    triangles: list[list[int]] = []
    for index in range(count):
        if offset + count_type.itemsize > len(data):
            raise MapError(f"truncated: face {index} of {count} is missing")
        n = int(np.frombuffer(data, count_type, 1, offset)[0])
        offset += count_type.itemsize
        if offset + n * item_type.itemsize > len(data):
            raise MapError(f"truncated: face {index} of {count} is incomplete")
        ids = np.frombuffer(data, item_type, n, offset).tolist()
        offset += n * item_type.itemsize
        triangles.extend([ids[0], ids[k], ids[k + 1]] for k in range(1, n - 1))
    return np.array(triangles, dtype=np.int64).reshape(-1, 3), offset


def _read_ascii(body: bytes, header: PlyHeader) -> PlyMesh:
    lines = body.decode("ascii", errors="replace").splitlines()
    lines = [line for line in lines if line.strip()]
    position = 0
    vertices, faces = None, np.zeros((0, 3), dtype=np.int64)
    for element in header.elements:
        rows = lines[position : position + element.count]
        if len(rows) < element.count:
            raise MapError(
                f"truncated: element '{element.name}' declares {element.count} lines, "
                f"found {len(rows)}"
            )
        position += element.count
        if element.name == "face":
            faces = _ascii_faces(rows)
        elif element.name == "vertex":
            vertices = _ascii_records(rows, element)
    if position < len(lines):
        raise MapError(f"{len(lines) - position} lines more than the header declares")
    assert vertices is not None
    if faces.size and faces.max() >= len(vertices):
        raise MapError(f"face refers to vertex {faces.max()} but there are {len(vertices)}")
    if faces.size and faces.min() < 0:
        raise MapError(f"face refers to vertex {faces.min()} (negative index)")
    return PlyMesh(vertices, faces)


def _ascii_records(rows: list[str], element: PlyElement) -> np.ndarray:
    dtype = np.dtype([(p.name, p.dtype) for p in element.properties])
    out = np.zeros(len(rows), dtype=dtype)
    for i, row in enumerate(rows):
        values = row.split()
        if len(values) != len(element.properties):
            raise MapError(
                f"{element.name} {i}: {len(values)} values for {len(element.properties)} properties"
            )
        try:
            out[i] = tuple(float(v) for v in values)
        except ValueError:
            raise MapError(f"{element.name} {i}: not a number in {row!r:.60}") from None
    return out


def _ascii_faces(rows: list[str]) -> np.ndarray:
    triangles: list[list[int]] = []
    for i, row in enumerate(rows):
        try:
            values = [int(v) for v in row.split()]
        except ValueError:
            raise MapError(f"face {i}: not an integer in {row!r:.60}") from None
        if not values or values[0] != len(values) - 1 or values[0] < 3:
            raise MapError(f"face {i}: bad vertex list {row!r:.60}")
        ids = values[1:]
        triangles.extend([ids[0], ids[k], ids[k + 1]] for k in range(1, len(ids) - 1))
    return np.array(triangles, dtype=np.int64).reshape(-1, 3)


def write_ply(
    path: str | os.PathLike[str],
    vertices: np.ndarray,
    faces: np.ndarray | None = None,
    binary: bool = True,
) -> None:
    """Write a structured vertex array (and triangles) as PLY; used for fixtures and exports."""

    inverse = {v: k for k, v in reversed(_TYPES.items())}
    faces = np.zeros((0, 3), dtype=np.int64) if faces is None else np.asarray(faces)
    fmt = "binary_little_endian" if binary else "ascii"
    lines = ["ply", f"format {fmt} 1.0", f"element vertex {len(vertices)}"]
    for name in vertices.dtype.names:
        lines.append(f"property {inverse[vertices.dtype[name].str[1:]]} {name}")
    if len(faces):
        lines += [f"element face {len(faces)}", "property list uchar int vertex_indices"]
    header = ("\n".join([*lines, "end_header"]) + "\n").encode("ascii")
    if binary:
        little = vertices.astype(vertices.dtype.newbyteorder("<"))
        tri = np.zeros(len(faces), dtype=[("n", "u1"), ("v", "<i4", (3,))])
        tri["n"], tri["v"] = 3, faces
        body = little.tobytes() + tri.tobytes()
    else:
        rows = [" ".join(str(x) for x in record) for record in vertices.tolist()]
        rows += [f"3 {a} {b} {c}" for a, b, c in faces.tolist()]
        body = ("\n".join(rows) + "\n").encode("ascii")
    write_atomic(path, header + body)
