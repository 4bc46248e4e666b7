"""PLY reading: round trips, header parsing (property-based), and precise errors."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from semloc.io.ply import _TYPES, parse_header, read_ply, write_ply
from semloc.maps import MapError


def _vertices(n: int) -> np.ndarray:
    v = np.zeros(n, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("label", "<u2")])
    v["x"], v["y"], v["z"] = np.arange(n), np.arange(n) * 2, -np.arange(n)
    v["label"] = np.arange(n) % 7
    return v


@pytest.mark.parametrize("binary", [True, False])
def test_round_trip(tmp_path, binary):
    vertices, faces = _vertices(10), np.array([[0, 1, 2], [3, 4, 5], [7, 8, 9]])
    write_ply(tmp_path / "m.ply", vertices, faces, binary=binary)
    mesh = read_ply(tmp_path / "m.ply")
    assert mesh.vertices.dtype.names == ("x", "y", "z", "label")
    for name in ("x", "y", "z", "label"):
        np.testing.assert_array_equal(mesh.vertices[name], vertices[name])
    np.testing.assert_array_equal(mesh.faces, faces)


def test_polygons_are_fanned(tmp_path):
    header = b"ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
    header += b"property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
    body = b"end_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n"
    (tmp_path / "q.ply").write_bytes(header + body)
    np.testing.assert_array_equal(read_ply(tmp_path / "q.ply").faces, [[0, 1, 2], [0, 2, 3]])


def test_truncated_binary_names_file_and_counts(tmp_path):
    write_ply(tmp_path / "m.ply", _vertices(50), np.array([[0, 1, 2]] * 20))
    data = (tmp_path / "m.ply").read_bytes()
    (tmp_path / "cut.ply").write_bytes(data[: len(data) - 400])
    with pytest.raises(MapError, match=r"cut\.ply: truncated: element 'vertex' declares 50"):
        read_ply(tmp_path / "cut.ply")
    (tmp_path / "cut2.ply").write_bytes(data[:-5])
    with pytest.raises(MapError, match=r"cut2\.ply: truncated: face"):
        read_ply(tmp_path / "cut2.ply")


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b"PK\x03\x04 not a ply", "no 'ply' magic"),
        (b"ply\nformat binary_little_endian 1.0\nelement vertex 3\n", "no 'end_header'"),
        (b"ply\nformat weird 1.0\nend_header\n", "unsupported format"),
        (
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float128 x\nend_header\n",
            "bad property",
        ),
        (b"ply\nformat ascii 1.0\nelement face 0\nend_header\n", "no 'vertex' element"),
        (
            b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nend_header\n1\n",
            "declares 2 lines, found 1",
        ),
        (
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n1 2\n",
            "2 values for 1 properties",
        ),
    ],
)
def test_bad_files(tmp_path, content, message):
    (tmp_path / "bad.ply").write_bytes(content)
    with pytest.raises(MapError, match=message) as info:
        read_ply(tmp_path / "bad.ply")
    assert "bad.ply" in str(info.value)


def test_face_index_out_of_range(tmp_path):
    write_ply(tmp_path / "m.ply", _vertices(3), np.array([[0, 1, 5]]))
    with pytest.raises(MapError, match="face refers to vertex 5 but there are 3"):
        read_ply(tmp_path / "m.ply")


def test_missing_file(tmp_path):
    with pytest.raises(MapError, match="nope.ply: file not found"):
        read_ply(tmp_path / "nope.ply")


_names = st.text("abcdefghij_", min_size=1, max_size=8)
_element = st.tuples(
    _names,
    st.integers(0, 10**6),
    st.lists(
        st.tuples(_names, st.sampled_from(sorted(_TYPES))),
        min_size=1,
        max_size=6,
        unique_by=lambda p: p[0],
    ),  # property names are unique within an element
)


@settings(max_examples=60)
@given(
    fmt=st.sampled_from(["ascii", "binary_little_endian", "binary_big_endian"]),
    elements=st.lists(_element, min_size=1, max_size=4),
    comments=st.lists(st.text("abc xyz", max_size=10), max_size=3),
)
def test_header_parser_recovers_declared_structure(fmt, elements, comments):
    lines = ["ply", f"format {fmt} 1.0", *(f"comment {c}" for c in comments)]
    for name, count, props in elements:
        lines.append(f"element {name} {count}")
        lines += [f"property {t} {p}" for p, t in props]
    text = "\n".join([*lines, "end_header"]) + "\n"
    header = parse_header(text.encode() + b"\x00\x01body")
    assert header.length == len(text)
    assert header.format == {"ascii": "ascii", "binary_little_endian": "<"}.get(fmt, ">")
    assert [(e.name, e.count) for e in header.elements] == [(n, c) for n, c, _ in elements]
    for element, (_, _, props) in zip(header.elements, elements, strict=True):
        assert [(p.name, p.dtype) for p in element.properties] == [(p, _TYPES[t]) for p, t in props]
