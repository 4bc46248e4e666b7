"""The g2o `EDGE_SE3:QUAT` line: g2o's conventions (unit quaternion with qw >= 0, the upper
triangle of the information in the order of g2o's error: translation, then the imaginary part of
the error quaternion), checked against g2o's own error definition by finite differences; and
the parser, which answers a tuple or ValueError for any text."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from semloc.alignment import pose_information
from semloc.io.g2o import TAG, edge_line, parse_edge

finite = st.floats(-1e3, 1e3, allow_nan=False)
quaternions = st.lists(st.floats(-1, 1), min_size=4, max_size=4).filter(
    lambda q: np.linalg.norm(q) > 0.1
)


def _pose(quaternion: list[float], translation: list[float]) -> np.ndarray:
    pose = np.eye(4)
    pose[:3, :3] = Rotation.from_quat(quaternion).as_matrix()
    pose[:3, 3] = translation
    return pose


def _g2o_information(pose: np.ndarray, local: np.ndarray, other: np.ndarray) -> np.ndarray:
    """J^T J / σ² of the centre residuals, J by finite differences over g2o's error vector
    e = (t, qx, qy, qz) of delta = Z^-1 X, i.e. X = Z delta with delta built from e (qw > 0)."""
    sigma2 = max(float(np.mean((local @ pose[:3, :3].T + pose[:3, 3] - other) ** 2)), 1e-4)

    def residual(e: np.ndarray) -> np.ndarray:
        delta = np.eye(4)
        delta[:3, :3] = Rotation.from_quat([*e[3:], np.sqrt(1 - e[3:] @ e[3:])]).as_matrix()
        delta[:3, 3] = e[:3]
        moved = pose @ delta
        return (local @ moved[:3, :3].T + moved[:3, 3] - other).ravel()

    h = 1e-6
    jacobian = np.stack(
        [(residual(h * np.eye(6)[k]) - residual(-h * np.eye(6)[k])) / (2 * h) for k in range(6)],
        axis=1,
    )
    return jacobian.T @ jacobian / sigma2


@settings(max_examples=60)
@given(
    quaternion=quaternions,
    translation=st.lists(finite, min_size=3, max_size=3),
    n=st.integers(3, 12),
    seed=st.integers(0, 2**16),
)
def test_the_edge_is_in_g2os_convention(quaternion, translation, n, seed):
    pose = _pose(quaternion, translation)
    rng = np.random.default_rng(seed)
    local = rng.uniform(-5, 5, (n, 3))
    other = local @ pose[:3, :3].T + pose[:3, 3] + rng.normal(0, 0.05, (n, 3))
    information = pose_information(pose, local, other)
    line = edge_line(pose, information)
    fields = line.split()
    assert fields[0] == TAG and len(fields) == 31 and line.endswith("\n")
    q = np.array(fields[6:10], dtype=float)
    assert q[3] >= 0 and abs(np.linalg.norm(q) - 1) < 1e-8
    _, _, parsed, parsed_information = parse_edge(line)
    np.testing.assert_allclose(parsed, pose, atol=1e-6 * (1 + np.abs(translation).max()))
    expected = _g2o_information(pose, local, other)
    np.testing.assert_allclose(parsed_information, expected, rtol=1e-5, atol=1e-5 * expected.max())
    # row by row over the upper triangle: I11 I12 ... I16 I22 ...; the 7th number is I22
    assert float(fields[16]) == pytest.approx(parsed_information[1, 1])


@settings(max_examples=200)
@given(st.text(max_size=300) | st.lists(st.sampled_from([TAG, "0", "1", "nan", "inf", "-2.5",
                                                          "1e400", "x", "0.0"]),
                                         max_size=32).map(" ".join))  # fmt: skip
def test_any_text_parses_to_an_edge_or_a_value_error(text):
    try:
        id_a, id_b, pose, information = parse_edge(text)
    except ValueError:
        return
    assert np.all(np.isfinite(pose)) and np.all(np.isfinite(information))
    np.testing.assert_allclose(pose[:3, :3] @ pose[:3, :3].T, np.eye(3), atol=1e-9)
    np.testing.assert_array_equal(information, information.T)


def test_a_non_finite_number_is_refused():
    good = edge_line(np.eye(4), np.eye(6))
    fields = good.split()
    for index in (3, 8, 12):
        bad = " ".join([*fields[:index], "nan", *fields[index + 1 :]])
        with pytest.raises(ValueError, match="non-finite"):
            parse_edge(bad)
