"""`SemanticObject.replace(position=...)` moves the points with the centre; a map file whose
object points lie far from their centre loads with one warning line naming the object."""

from __future__ import annotations

import logging

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

import semloc
from semloc.cli import main
from semloc.maps import FAR_FROM_POINTS_M, ObjectMap, SemanticObject, far_from_points

finite = st.floats(-50, 50, allow_nan=False)
vectors = st.tuples(finite, finite, finite).map(np.array)


def chair(points: np.ndarray | None = None) -> SemanticObject:
    cloud = np.array([[0.0, 0, 0], [0.5, 0, 0], [0, 0.5, 0.9]]) if points is None else points
    return SemanticObject("c1", "chair", cloud.mean(axis=0), size=[0.5, 0.5, 0.9], points=cloud)


@settings(max_examples=60)
@given(
    points=st.lists(st.tuples(finite, finite, finite), min_size=1, max_size=8).map(np.array),
    target=vectors,
)
def test_a_new_position_moves_the_points_by_the_same_offset(points, target):
    obj = SemanticObject("o", "lamp", points.mean(axis=0), points=points)
    moved = obj.replace(position=target)
    np.testing.assert_allclose(moved.position, target)
    np.testing.assert_allclose(moved.points - moved.position, obj.points - obj.position, atol=1e-9)
    assert far_from_points([moved]) == far_from_points([obj])  # what was close stays close


@settings(max_examples=30)
@given(offset=vectors)
def test_replace_and_transformed_agree_on_a_shift(offset):
    obj = chair()
    T = np.eye(4)
    T[:3, 3] = offset
    by_replace, by_transform = obj.replace(position=obj.position + offset), obj.transformed(T)
    np.testing.assert_allclose(by_replace.points, by_transform.points, atol=1e-9)
    np.testing.assert_allclose(by_replace.position, by_transform.position, atol=1e-9)


def test_points_given_with_the_position_are_taken_as_given():
    obj = chair()
    cloud = np.array([[9.0, 9, 9], [9.5, 9, 9]])
    both = obj.replace(position=[9.2, 9, 9], points=cloud)
    np.testing.assert_array_equal(both.points, cloud)
    assert chair().replace(label="stool").points is not None  # other fields leave points alone
    bare = SemanticObject("b", "box", [0, 0, 0]).replace(position=[1, 2, 3])
    assert bare.points is None and list(bare.position) == [1, 2, 3]


def test_a_map_with_points_far_from_their_centre_warns_once_naming_the_object(tmp_path, caplog):
    good = chair()
    broken = SemanticObject("far-away", "table", [40.0, 0, 0.4],
                            points=np.array([[0.0, 0, 0], [1.0, 0, 0.8]]))  # fmt: skip
    assert far_from_points([good]) == []
    [(name, metres)] = far_from_points([good, broken])
    assert name == "far-away" and metres > FAR_FROM_POINTS_M
    semloc.save_map(ObjectMap([good]), tmp_path / "good.json")
    semloc.save_map(ObjectMap([good, broken]), tmp_path / "bad.json")
    with caplog.at_level(logging.WARNING, logger="semloc"):
        semloc.load_map(tmp_path / "good.json")
        assert caplog.records == []
        semloc.load_map(tmp_path / "bad.json")
    [record] = caplog.records
    message = record.getMessage()
    assert "\n" not in message and "object 'far-away'" in message and "bad.json" in message
    assert "39.0 m from its position" in message and "transformed" in message


def test_the_command_line_warns_and_still_runs(tmp_path, capsys, caplog):
    broken = SemanticObject("t9", "table", [40.0, 0, 0.4],
                            points=np.array([[0.0, 0, 0], [1.0, 0, 0.8]]))  # fmt: skip
    semloc.save_map(ObjectMap([chair(), broken]), tmp_path / "bad.json")
    with caplog.at_level(logging.WARNING, logger="semloc"):
        assert main(["localize", str(tmp_path / "bad.json"), str(tmp_path / "bad.json")]) == 0
    assert any("object 't9'" in r.getMessage() for r in caplog.records)
    assert "status: " in capsys.readouterr().out
