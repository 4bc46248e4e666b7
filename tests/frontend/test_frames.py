"""RGB-D keyframes: validation and back-projection of keypoints."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from semloc.frontend.frames import KeyframeMap, RGBDFrame

K = np.array([[50.0, 0, 31.5], [0, 50.0, 23.5], [0, 0, 1]])


def _pose(yaw: float, t) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    T = np.eye(4)
    T[:3, :3] = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    T[:3, 3] = t
    return T


@given(
    st.integers(0, 63), st.integers(0, 47), st.floats(0.3, 8.0),
    st.floats(-3.1, 3.1), st.tuples(*[st.floats(-5, 5)] * 3),
)  # fmt: skip
def test_points_back_project_pixels_with_their_depth(u, v, z, yaw, t):
    depth = np.zeros((48, 64), np.float32)
    depth[v, u] = z
    T = _pose(yaw, t)
    frame = RGBDFrame(0, np.zeros((48, 64, 3), np.uint8), depth, K, T)
    xyz, valid = frame.points(np.array([[u, v], [0 if u else 1, 0 if v else 1]]))
    assert valid.tolist() == [True, False]
    camera = np.linalg.inv(T) @ np.append(xyz[0], 1.0)
    assert np.allclose(camera[:3] / camera[2] * [50, 50, 1] + [31.5, 23.5, 0], [u, v, 1],
                       atol=1e-6)  # fmt: skip
    assert np.isclose(camera[2], np.float32(z), rtol=1e-6)


def test_bad_frames_and_empty_maps_are_refused():
    rgb, depth = np.zeros((4, 5, 3), np.uint8), np.zeros((4, 5), np.float32)
    with pytest.raises(ValueError, match="uint8"):
        RGBDFrame(0, rgb.astype(float), depth, K, np.eye(4))
    with pytest.raises(ValueError, match="differ in size"):
        RGBDFrame(0, rgb, depth[:3], K, np.eye(4))
    with pytest.raises(ValueError, match="3x3"):
        RGBDFrame(0, rgb, depth, np.eye(4), np.eye(4))
    with pytest.raises(ValueError, match="at least one"):
        KeyframeMap.of([])
    assert RGBDFrame(0, rgb + 255, depth, K, np.eye(4)).gray.max() == 255
