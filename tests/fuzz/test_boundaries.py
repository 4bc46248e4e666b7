"""Property-based checks of the parsers (map schema, PLY, ScanNet segments) and the public
boundary: only `MapError` / `TypeError` / `ValueError` with a message, outputs all or none,
devices and FIFOs written as streams, every written number finite."""

from __future__ import annotations

import json
import os
import stat
import threading
from pathlib import Path

import numpy as np
import pytest
from cases import valid_map
from format_fixtures import write_replica
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import semloc
from semloc.io import load_map, save_map, write_atomic, write_files
from semloc.io.importers.scannet import read_segments
from semloc.io.ply import read_ply
from semloc.io.reading import MAX_FILE_BYTES, MAX_JSON_BYTES, parse_json
from semloc.localizer import Localizer, localize
from semloc.maps import MAX_LABEL_LENGTH, MapError, ObjectMap, SemanticObject
from semloc.pictures.display import DISPLAY_LENGTH, for_matplotlib, for_rich, printable, shorten

HOSTILE = st.one_of(
    st.none(), st.booleans(), st.text(max_size=4), st.integers(-(10**30), 10**30),
    st.floats(allow_nan=False, allow_infinity=False), st.just(1e308), st.just([]),
    st.lists(st.floats(-1e308, 1e308), max_size=4),
)  # fmt: skip
FIELDS = ["id", "label", "position", "size", "rotation", "points", "descriptor", "seen", "score",
          "embedding"]  # fmt: skip
TOP = ["format", "version", "name", "up", "objects", "points_file"]
QUIET = settings(max_examples=60, suppress_health_check=list(HealthCheck))


@QUIET
@given(
    where=st.sampled_from(FIELDS + TOP), value=HOSTILE, index=st.integers(0, 5),
    scale=st.sampled_from([1.0, 1e5, 1e300]),
)  # fmt: skip
def test_map_schema_fields_hostile_values(tmp_path_factory, where, value, index, scale):
    """One field of a valid map replaced by a hostile value (or all coordinates scaled): the
    reader builds a valid map or raises MapError naming the file; what it builds saves and
    loads again with finite numbers."""
    folder = tmp_path_factory.mktemp("schema")
    document = valid_map()
    for obj in document["objects"]:
        obj["position"] = [v * scale for v in obj["position"]]
    if where in TOP:
        document[where] = value
    else:
        document["objects"][index][where] = value
    path = folder / "m.json"
    path.write_text(json.dumps(document))
    try:
        objmap = load_map(path)
    except MapError as exc:
        assert str(path) in str(exc)
        return
    again = load_map(save_map(objmap.transformed(np.eye(4)), folder / "again.json"))
    assert len(again) == len(objmap)
    assert np.all(np.isfinite(again.positions))


@QUIET
@given(st.recursive(HOSTILE, lambda c: st.lists(c, max_size=3) | st.dictionaries(st.text(max_size=3), c, max_size=3), max_leaves=12))  # fmt: skip
def test_parse_json_reads_back_what_json_writes(document):
    """Every document `json.dumps` writes (with these values) is read back equal, except that
    integers of more than 18 characters become floats (the reader's rule)."""
    parsed = parse_json(json.dumps(document))
    assert json.dumps(parsed) == json.dumps(_as_read(document))


def _as_read(value):
    """`value` as `parse_json` returns it: long integers as floats, the rest unchanged."""
    if isinstance(value, list):
        return [_as_read(v) for v in value]
    if isinstance(value, dict):
        return {k: _as_read(v) for k, v in value.items()}
    if isinstance(value, int) and not isinstance(value, bool) and len(str(value)) > 18:
        return float(value)
    return value


def test_parse_json_limits():
    with pytest.raises(ValueError, match="occurs more than once"):
        parse_json('{"a": 1, "a": 2}')
    with pytest.raises(ValueError, match="too large"):
        parse_json("1" + "0" * 400)
    assert parse_json("1" + "0" * 30) == 1e30  # beyond int64: a float, refused where ints go
    with pytest.raises(RecursionError):
        parse_json("[" * 100_000)


PLY_HEADERS = st.builds(
    lambda fmt, count, props, faces: (
        f"ply\nformat {fmt} 1.0\nelement vertex {count}\n"
        + "".join(f"property {t} {n}\n" for t, n in props)
        + (f"element face {faces}\nproperty list uchar int vertex_indices\n" if faces is not None else "")
        + "end_header\n"
    ).encode(),
    st.sampled_from(["ascii", "binary_little_endian", "binary_big_endian", "bogus"]),
    st.sampled_from(["0", "3", "-1", "99999999999", "x"]),
    st.lists(st.tuples(st.sampled_from(["float", "double", "uchar", "int", "list"]),
                       st.sampled_from(["x", "y", "z", "label", "x"])), max_size=5),
    st.one_of(st.none(), st.sampled_from(["1", "-2", "1000000000"])),
)  # fmt: skip


@QUIET
@given(header=PLY_HEADERS, body=st.binary(max_size=200))
def test_ply_reader_raises_only_map_errors(tmp_path_factory, header, body):
    path = tmp_path_factory.mktemp("ply") / "m.ply"
    path.write_bytes(header + body)
    try:
        mesh = read_ply(path)
    except MapError as exc:
        assert str(path) in str(exc)
        return
    assert mesh.faces.size == 0 or 0 <= mesh.faces.min() <= mesh.faces.max() < len(mesh.vertices)


@QUIET
@given(st.lists(st.one_of(st.integers(-5, 10**6), st.floats(), st.booleans(), st.text(max_size=2)), max_size=6))  # fmt: skip
def test_segment_indices_are_integers_or_refused(tmp_path_factory, values):
    path = tmp_path_factory.mktemp("segs") / "s.segs.json"
    path.write_text(json.dumps({"segIndices": values}))
    try:
        segments = read_segments(path)
    except MapError as exc:
        assert str(path) in str(exc)
        assert not all(type(v) is int for v in values)
        return
    assert all(type(v) is int for v in values)
    assert segments.tolist() == values


# The Python API at its boundary ----------------------------------------------------------------
def small_map() -> ObjectMap:
    return ObjectMap([SemanticObject(f"o{i}", "chair", [i, i * i % 3, 0]) for i in range(5)])


def test_localizer_and_localize_refuse_wrong_types_with_a_message():
    g = small_map()
    with pytest.raises(TypeError, match="ObjectMap"):
        Localizer(None)
    with pytest.raises(TypeError, match="LocalizerConfig"):
        Localizer(g, {"gamma": 0.7})
    with pytest.raises(TypeError, match="local map"):
        localize(g, None)
    with pytest.raises(TypeError, match="SemanticObjects"):
        Localizer(g).update(None)
    with pytest.raises(MapError, match="local_up"):
        Localizer(g, local_up=[0, 0, 0])


def test_update_refuses_duplicate_ids_in_one_call():
    obj = SemanticObject("a", "chair", [0, 0, 0])
    with pytest.raises(MapError, match="'a' occurs more than once"):
        Localizer(small_map()).update([obj, obj.replace(position=[1, 0, 0])])


def test_from_arrays_checks_every_column_length():
    ids, labels, positions = ["a", "b"], ["chair", "lamp"], np.zeros((2, 3))
    with pytest.raises(MapError, match="sizes has 1 entries for 2 objects"):
        ObjectMap.from_arrays(ids, labels, positions, sizes=[[1, 1, 1]])
    with pytest.raises(MapError, match="rotations has 1 entries"):
        ObjectMap.from_arrays(ids, labels, positions, rotations=[np.eye(3)])


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"label": "x" * 201}, "more than 200"),
        ({"position": [0, 0, 2e6]}, "input limit"),
        ({"position": ["1", "2", "3"]}, "must be numbers"),
        ({"position": [True, 0, 0]}, "must be numbers"),
        ({"seen": -1}, "keyframe index"),
        ({"score": 10**400}, "not finite"),
        ({"label": "\ud800"}, "surrogate"),
    ],
)  # fmt: skip
def test_object_limits_and_strict_types(change, message):
    with pytest.raises(MapError, match=message):
        SemanticObject(**{"id": "a", "label": "chair", "position": [0, 0, 0], **change})


def test_up_whose_length_overflows_is_refused():
    """[1e308, 1e308, 0] has an infinite length in plain arithmetic: a damaged file, refused."""
    with pytest.raises(MapError, match=r"up .* too large to normalise"):
        ObjectMap([], up=[1e308, 1e308, 0])
    assert np.allclose(ObjectMap([], up=[1e6, 1e6, 0]).up, [2**-0.5, 2**-0.5, 0])


@given(st.lists(st.floats(allow_nan=False), min_size=3, max_size=3))
def test_up_is_a_unit_vector_or_refused(up):
    """Any three numbers: a finite unit vector, or one MapError naming `up`."""
    try:
        unit = ObjectMap([], up=up).up
    except MapError as exc:
        assert str(exc).startswith("up ")
        return
    assert np.all(np.isfinite(unit)) and abs(np.linalg.norm(unit) - 1) < 1e-12


def test_files_over_the_size_limits_are_refused_before_reading(tmp_path):
    """Sparse files a byte over the limits (256 MiB JSON, 1 GiB other): refused from their size."""
    for name, limit, read in (("m.json", MAX_JSON_BYTES, load_map),
                              ("m.ply", MAX_FILE_BYTES, read_ply)):  # fmt: skip
        path = tmp_path / name
        with open(path, "wb") as handle:
            handle.truncate(limit + 1)
        with pytest.raises(MapError, match=f"{path}: {limit + 1:,} bytes, more than the limit"):
            read(path)


def test_user_text_is_shortened_printable_and_escaped():
    long = "x" * MAX_LABEL_LENGTH
    assert shorten(long) == "x" * (DISPLAY_LENGTH - 1) + "…"
    assert for_rich("[/x0]" + long).startswith(r"\[/x0]") and len(shorten(long)) == DISPLAY_LENGTH
    assert for_matplotlib("$\\undefinedcommand{$") == "\\$\\undefinedcommand{\\$"
    shown = printable("a\ud800b\x1b[31m")
    assert shown.encode("utf-8") and shown.isprintable() and "\x1b" not in shown


def test_huge_gravity_is_refused_in_one_line(tmp_path, capsys):
    """Replica `gravity_dir` [1e308, 1e308, 0]: exit 2, one line naming the file and the key."""
    from semloc.cli import main

    scene = write_replica(tmp_path / "replica", gravity=(1e308, 1e308, 0.0))
    assert main(["convert", "replica", str(scene), "-o", str(tmp_path / "m.json")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "'gravity_dir'" in err and str(scene) in err, err
    assert not (tmp_path / "m.json").exists()


@pytest.mark.slow
def test_object_count_limit():
    objects = [SemanticObject(str(i), "c", [0, 0, 0]) for i in range(semloc.maps.MAX_OBJECTS + 1)]
    with pytest.raises(MapError, match="more than the limit"):
        ObjectMap(objects)


# Outputs ---------------------------------------------------------------------------------------
def test_failed_save_leaves_no_orphan(tmp_path):
    big = ObjectMap([SemanticObject("a", "chair", [0, 0, 0], points=np.zeros((6000, 3)))])
    target = tmp_path / "missing" / "m.json"
    with pytest.raises(MapError, match="does not exist"):
        save_map(big, target)
    assert not (tmp_path / "missing").exists()
    save_map(big, tmp_path / "m.json")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.json", "m.points.npz", "missing"][:2]


def test_fifo_output_is_streamed_not_replaced(tmp_path):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    received = []
    reader = threading.Thread(target=lambda: received.append(fifo.read_bytes()))
    reader.start()
    write_atomic(fifo, b"hello")
    reader.join(5)
    assert received == [b"hello"]
    assert stat.S_ISFIFO(os.stat(fifo).st_mode)


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="no /dev/full")
def test_device_output_is_written_as_a_stream():
    with pytest.raises(MapError, match="/dev/full: cannot write"):
        write_atomic("/dev/full", b"x" * 10)
    assert stat.S_ISCHR(os.stat("/dev/full").st_mode)


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="no /dev/full")
def test_failing_stream_leaves_the_other_files_as_they_were(tmp_path):
    """`convert scan2cad -o cad.json --scan-output /dev/full`: the CAD map is not replaced."""
    (tmp_path / "cad.json").write_text("old")
    with pytest.raises(MapError, match="/dev/full: cannot write"):
        write_files([(tmp_path / "cad.json", "new"), (Path("/dev/full"), b"x" * 10)])
    assert (tmp_path / "cad.json").read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cad.json"]


def test_huge_but_finite_numbers_round_trip(tmp_path):
    objmap = ObjectMap([SemanticObject("a", "chair", [9.9e5, -9.9e5, 1e-300], size=[1e6, 0, 1])])
    again = load_map(save_map(objmap, tmp_path / "m.json"))
    assert np.allclose(again.positions, objmap.positions)
