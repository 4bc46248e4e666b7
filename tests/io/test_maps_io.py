"""ObjectMap validation and the native file format: round trips and every kind of bad input."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import semloc
from semloc import MapError, ObjectMap, SemanticObject


def write(tmp_path, document, name="map.json") -> str:
    path = tmp_path / name
    path.write_text(document if isinstance(document, str) else json.dumps(document))
    return str(path)


def doc(*objects, **top):
    return {"format": "semloc-map", "version": 1, "objects": list(objects), **top}


CHAIR = {"id": "1", "label": "chair", "position": [1.0, 2.0, 0.5]}


def test_minimal_map_loads(tmp_path):
    m = semloc.load_map(
        write(tmp_path, doc(CHAIR, {"id": 7, "label": "table", "position": [0, 0, 0]}))
    )
    assert list(m.ids) == ["1", "7"]  # integer ids become strings
    assert list(m.labels) == ["chair", "table"]
    np.testing.assert_allclose(m.positions, [[1, 2, 0.5], [0, 0, 0]])
    assert m.up is None and m[0].points is None and list(m.seen) == [0, 0]


def test_full_round_trip_keeps_everything_including_unknown_keys(tmp_path):
    rotation = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]
    original = doc(
        {**CHAIR, "size": [0.5, 0.5, 0.9], "rotation": rotation, "points": [[1, 2, 0.2], [1.1, 2, 0.7]],
         "descriptor": [0.1, 0.3], "seen": 4, "score": 0.9, "colour": "red", "meta": {"a": [1, 2]}},
        name="scene", up=[0, 0, 1], producer="test-suite",
    )  # fmt: skip
    m = semloc.load_map(write(tmp_path, original))
    out = tmp_path / "out.json"
    semloc.save_map(m, out, points="inline")
    again = json.loads(out.read_text())
    assert again["producer"] == "test-suite" and again["name"] == "scene"
    obj = again["objects"][0]
    assert obj["colour"] == "red" and obj["meta"] == {"a": [1, 2]}
    assert obj["seen"] == 4 and obj["score"] == 0.9 and obj["descriptor"] == [0.1, 0.3]
    assert obj["rotation"] == rotation and obj["points"] == [[1, 2, 0.2], [1.1, 2, 0.7]]


def test_points_file_round_trip(tmp_path):
    points = np.random.default_rng(0).normal(size=(50, 3))
    m = ObjectMap([SemanticObject("a", "chair", [0, 0, 0], points=points)], name="x")
    path = semloc.save_map(m, tmp_path / "x.json", points="file")
    document = json.loads(path.read_text())
    assert document["points_file"] == "x.points.npz" and "points" not in document["objects"][0]
    again = semloc.load_map(path)
    np.testing.assert_allclose(again[0].points, points, atol=1e-6)


def test_save_is_atomic_and_leaves_no_temporary_files(tmp_path):
    m = ObjectMap([SemanticObject("a", "chair", [0, 0, 0])])
    semloc.save_map(m, tmp_path / "m.json")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.json"]
    mask = os.umask(0)
    os.umask(mask)
    assert (tmp_path / "m.json").stat().st_mode & 0o777 == 0o666 & ~mask  # not mkstemp's 0600


@pytest.mark.parametrize(
    "document, message",
    [
        ("{not json", "not valid JSON"),
        ("[]", "top level must be a JSON object"),
        (doc(CHAIR, format="other"), "format must be 'semloc-map'"),
        ({"format": "semloc-map", "objects": []}, "missing key 'version'"),
        ({"format": "semloc-map", "version": 1}, "missing key 'objects'"),
        (doc(CHAIR, version=2), "unsupported version"),
        (doc({"id": "1", "position": [0, 0, 0]}), "object '1': missing key 'label'"),
        (doc({"label": "chair", "position": [0, 0, 0]}), "object #0: missing key 'id'"),
        (doc({"id": "1", "label": "chair"}), "object '1': missing key 'position'"),
        (doc(CHAIR, CHAIR), "object '1': duplicate id"),
        (doc({**CHAIR, "position": [0, 0]}), "object '1': position must have shape (3,)"),
        (doc({**CHAIR, "position": [0, "a", 0]}), "object '1': position must be numbers"),
        ('{"format": "semloc-map", "version": 1, "objects": [{"id": "1", "label": "c", '
         '"position": [NaN, 0, 0]}]}', "non-finite number NaN"),
        (doc({**CHAIR, "label": ""}), "object '1': label must be a non-empty string"),
        (doc({**CHAIR, "label": 3}), "object '1': label must be a non-empty string"),
        (doc({**CHAIR, "points": [[0, 0], [1, 1]]}), "object '1': points must have shape (N, 3)"),
        (doc({**CHAIR, "rotation": [[1, 0, 0], [0, 1, 0], [0, 0, 2]]}), "not a proper rotation"),
        (doc({**CHAIR, "size": [1, -1, 1]}), "size has negative entries"),
        (doc({**CHAIR, "seen": 1.5}), "seen must be an integer"),
        (doc({**CHAIR, "descriptor": []}), "descriptor must be a non-empty vector"),
        (doc(CHAIR, up=[0, 0, 0]), "up must be a non-zero vector"),
        (doc(CHAIR, points_file="missing.npz"), "points_file"),
        (doc({**CHAIR, "id": True}), "id must be a string or an integer"),
    ],
)  # fmt: skip
def test_bad_files_raise_map_error_naming_file_and_problem(tmp_path, document, message):
    path = write(tmp_path, document)
    with pytest.raises(MapError) as info:
        semloc.load_map(path)
    assert str(path) in str(info.value)
    assert message in str(info.value)


def test_missing_file_and_corrupt_npz(tmp_path):
    with pytest.raises(MapError, match="file not found"):
        semloc.load_map(tmp_path / "nope.json")
    (tmp_path / "bad.npz").write_bytes(b"not a zip")
    with pytest.raises(MapError, match="not a readable .npz"):
        semloc.load_map(write(tmp_path, doc(CHAIR, points_file="bad.npz")))


def test_npz_with_pickled_objects_is_refused(tmp_path):
    np.savez(tmp_path / "p.npz", **{"1": np.array([object()], dtype=object)})
    with pytest.raises(MapError):
        semloc.load_map(write(tmp_path, doc(CHAIR, points_file="p.npz")))


def test_empty_map_is_valid(tmp_path):
    assert len(semloc.load_map(write(tmp_path, doc()))) == 0


def test_from_arrays_and_transform():
    m = ObjectMap.from_arrays(["a", "b"], ["chair", "desk"], [[1, 0, 0], [0, 2, 0]], up=[0, 0, 3])
    T = np.eye(4)
    T[:3, :3] = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]
    T[:3, 3] = [5, 0, 0]
    moved = m.transformed(T)
    np.testing.assert_allclose(moved.positions, [[5, 1, 0], [3, 0, 0]])
    np.testing.assert_allclose(moved.up, [0, 0, 1])
    with pytest.raises(MapError, match="do not match"):
        ObjectMap.from_arrays(["a"], ["chair", "desk"], [[0, 0, 0]])


# property: any valid map survives a save/load round trip -------------------------------------
finite = st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False)
vec3 = st.lists(finite, min_size=3, max_size=3)
objects = st.lists(
    st.tuples(
        st.text(
            st.characters(codec="utf-8", exclude_categories=["Cs", "Cc"]), min_size=1, max_size=8
        ),
        st.sampled_from(["chair", "table", "Sofa", "lamp post"]),
        vec3,
        st.none() | st.lists(vec3, min_size=0, max_size=5),
        st.integers(0, 100),
    ),
    max_size=6,
    unique_by=lambda t: t[0],
)


@settings(max_examples=40)
@given(objects=objects, inline=st.booleans())
def test_round_trip_property(tmp_path_factory, objects, inline):
    folder = tmp_path_factory.mktemp("rt")
    m = ObjectMap(
        [SemanticObject(i, lab, p, points=pts, seen=s) for i, lab, p, pts, s in objects],
        up=[0, 0, 1],
    )
    path = semloc.save_map(m, folder / "m.json", points="inline" if inline else "file")
    again = semloc.load_map(path)
    assert list(again.ids) == list(m.ids) and list(again.labels) == list(m.labels)
    np.testing.assert_allclose(again.positions, m.positions, atol=1e-6)
    assert list(again.seen) == list(m.seen)
    for a, b in zip(again, m):
        if b.points is None or len(b.points) == 0:
            assert a.points is None or len(a.points) == 0
        else:
            np.testing.assert_allclose(a.points, b.points, rtol=1e-6, atol=1e-5)


@settings(max_examples=60)
@given(st.recursive(st.none() | st.booleans() | finite | st.text(max_size=5),
                    lambda c: st.lists(c, max_size=3) | st.dictionaries(st.text(max_size=5), c, max_size=3),
                    max_leaves=10))  # fmt: skip
def test_arbitrary_json_never_crashes_the_reader(tmp_path_factory, document):
    path = tmp_path_factory.mktemp("fz") / "m.json"
    path.write_text(json.dumps(document))
    try:
        semloc.load_map(path)
    except MapError as exc:
        assert str(path) in str(exc)
