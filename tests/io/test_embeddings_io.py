"""Per-object semantic embeddings: validation, unit length, JSON and .npz round trips."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import semloc
from semloc import MapError, ObjectMap, SemanticObject


def _write(path, objects, **top):
    document = {"format": "semloc-map", "version": 1, "objects": objects, **top}
    path.write_text(json.dumps(document))
    return path


@given(
    st.lists(st.floats(-1e6, 1e6), min_size=1, max_size=64).filter(
        lambda v: max(map(abs, v)) > 1e-6
    )
)
def test_embeddings_are_unit_length(values):
    obj = SemanticObject("a", "chair", [0, 0, 0], embedding=values)
    assert np.isclose(np.linalg.norm(obj.embedding), 1.0)


@pytest.mark.parametrize(
    ("embedding", "message"),
    [
        ([0.0, 0.0], "zero vector"),
        ([1.0, float("nan")], "finite"),
        ([1.0, float("inf")], "finite"),
        ([], "non-empty"),
        (["a", "b"], "numbers"),
    ],
)
def test_bad_embeddings_name_the_object(embedding, message):
    with pytest.raises(MapError, match=f"object 'x'.*{message}"):
        SemanticObject("x", "chair", [0, 0, 0], embedding=embedding)


def test_embeddings_of_one_map_share_their_dimension():
    a = SemanticObject("a", "chair", [0, 0, 0], embedding=[1, 0])
    b = SemanticObject("b", "chair", [1, 0, 0], embedding=[1, 0, 0])
    with pytest.raises(MapError, match="object 'b': embedding has 3 entries, object 'a'"):
        ObjectMap([a, b])


def test_json_round_trip_and_bad_file(tmp_path):
    objects = [SemanticObject("a", "chair", [0, 0, 0], embedding=[3, 4]),
               SemanticObject("b", "table", [1, 0, 0])]  # fmt: skip
    semloc.save_map(ObjectMap(objects), tmp_path / "m.json")
    loaded = semloc.load_map(tmp_path / "m.json")
    assert np.allclose(loaded[0].embedding, [0.6, 0.8]) and loaded[1].embedding is None
    assert "embedding" not in loaded[0].extra
    bad = _write(tmp_path / "bad.json", [{"id": "q", "label": "x", "position": [0, 0, 0],
                                          "embedding": [0, 0]}])  # fmt: skip
    with pytest.raises(MapError, match="object 'q'.*zero vector"):
        semloc.load_map(bad)


def test_npz_members_hold_embeddings(tmp_path):
    np.savez(tmp_path / "m.npz", **{"embedding:a": np.array([1.0, 1.0]), "b": np.zeros((2, 3))})
    path = _write(tmp_path / "m.json", [{"id": "a", "label": "x", "position": [0, 0, 0]},
                                        {"id": "b", "label": "y", "position": [1, 0, 0]}],
                  points_file="m.npz")  # fmt: skip
    loaded = semloc.load_map(path)
    assert np.allclose(loaded[0].embedding, np.sqrt([0.5, 0.5]))
    assert loaded[1].embedding is None and loaded[1].points.shape == (2, 3)
    np.savez(tmp_path / "m.npz", **{"embedding:a": np.zeros((2, 2))})
    with pytest.raises(MapError, match="object 'a': embedding must be a vector"):
        semloc.load_map(path)
