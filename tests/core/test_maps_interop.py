"""SemanticObject from point clouds (array-likes, open3d or any `.points` holder), the default
centre, and `ObjectMap.cloud` / `to_open3d`."""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from semloc.maps import MapError, ObjectMap, SemanticObject

finite = st.floats(-100, 100, allow_nan=False)


class Cloud:
    """A point-cloud object as other libraries have them: points behind an attribute."""

    def __init__(self, points):
        self.points = points


@given(arrays(float, st.tuples(st.integers(1, 30), st.just(3)), elements=finite))
def test_position_defaults_to_the_centre_of_the_points(points):
    for given_points in (points, points.tolist(), Cloud(points), Cloud(points.tolist())):
        obj = SemanticObject("a", "chair", points=given_points)
        np.testing.assert_allclose(obj.position, points.mean(axis=0))
        np.testing.assert_array_equal(obj.points, points)


def test_positional_api_is_unchanged():
    obj = SemanticObject("a", "chair", [1.0, 2.0, 3.0], [1, 1, 1])
    assert obj.position.tolist() == [1.0, 2.0, 3.0] and obj.size.tolist() == [1, 1, 1]
    explicit = SemanticObject("b", "chair", [0, 0, 0], points=[[1, 1, 1], [3, 3, 3]])
    assert explicit.position.tolist() == [0, 0, 0]  # a given position wins


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({}, "position is missing"),
        ({"points": np.zeros((0, 3))}, "position is missing"),
        ({"points": Cloud([[1, 2], [3, 4]])}, "points must have shape (N, 3)"),
        ({"points": Cloud("xyz")}, "points must be an N x 3 array"),
    ],
)
def test_bad_clouds_name_the_object(kwargs, message):
    with pytest.raises(MapError, match=r"object 'a': ") as error:
        SemanticObject("a", "chair", **kwargs)
    assert message in str(error.value)


def test_cloud_colours_each_point_by_its_label():
    gmap = ObjectMap([
        SemanticObject("a", "chair", points=[[0, 0, 0], [1, 0, 0]]),
        SemanticObject("b", "table", [5, 5, 0]),  # no points: its centre
    ])  # fmt: skip
    points, rgb = gmap.cloud({"chair": "#ff0000", "table": (0.0, 0.5, 1.0)})
    assert points.tolist() == [[0, 0, 0], [1, 0, 0], [5, 5, 0]]
    assert rgb.tolist() == [[1, 0, 0], [1, 0, 0], [0, 0.5, 1]]
    assert gmap.cloud()[1] is None
    with pytest.raises(MapError, match="no colour for the labels \\['table'\\]"):
        gmap.cloud({"chair": "#ff0000"})


@pytest.mark.skipif(importlib.util.find_spec("open3d") is None, reason="open3d not installed")
def test_open3d_round_trip():
    import open3d as o3d

    rng = np.random.default_rng(0)
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(rng.normal(size=(50, 3))))
    obj = SemanticObject("a", "chair", points=pcd)
    np.testing.assert_allclose(obj.points, np.asarray(pcd.points))
    np.testing.assert_allclose(obj.position, np.asarray(pcd.points).mean(axis=0))
    gmap = ObjectMap([obj, SemanticObject("b", "lamp", points=rng.normal(size=(5, 3)) + 4)])
    cloud = gmap.to_open3d({"chair": "#2ca02c", "lamp": "#bcbd22"})
    assert isinstance(cloud, o3d.geometry.PointCloud)
    np.testing.assert_allclose(np.asarray(cloud.points), gmap.cloud()[0])
    np.testing.assert_allclose(np.asarray(cloud.colors)[0], [0x2C / 255, 0xA0 / 255, 0x2C / 255])
    assert not gmap.to_open3d().has_colors()
