"""The compiled pair digests are hashlib's BLAKE2b-64, for any ids."""

from __future__ import annotations

import hashlib

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from semloc.digests import encode_ids, pair_digests
from semloc.maps import ObjectMap, SemanticObject


def blake2b_64(global_id: str, local_id: str) -> int:
    text = f"{global_id}\x00{local_id}".encode()
    return int.from_bytes(hashlib.blake2b(text, digest_size=8).digest(), "little")


def digests(global_ids: list[str], local_ids: list[str], pairs: list[tuple[int, int]]):
    g = np.array([p[0] for p in pairs], dtype=np.int64)
    l = np.array([p[1] for p in pairs], dtype=np.int64)
    return pair_digests(encode_ids(global_ids), g, encode_ids(local_ids), l).tolist()


def test_block_boundaries_and_multi_byte_characters():
    """Messages of 0 to 3 blocks, ending just before, at and after a block boundary (128
    bytes), and ids whose characters take 2 to 4 bytes."""
    global_ids = ["", "a", "x" * 126, "x" * 127, "x" * 128, "x" * 255, "y" * 300, "é€😀"]
    local_ids = ["", "b", "ü" * 70, "q" * 129]
    pairs = [(g, l) for g in range(len(global_ids)) for l in range(len(local_ids))]
    expected = [blake2b_64(global_ids[g], local_ids[l]) for g, l in pairs]
    assert digests(global_ids, local_ids, pairs) == expected


def test_no_pairs():
    assert digests(["a"], ["b"], []) == []


@settings(max_examples=200)
@given(
    st.lists(st.text(max_size=150), min_size=1, max_size=6),
    st.lists(st.text(max_size=150), min_size=1, max_size=6),
    st.data(),
)
def test_equal_to_hashlib(global_ids, local_ids, data):
    pairs = data.draw(
        st.lists(
            st.tuples(st.integers(0, len(global_ids) - 1), st.integers(0, len(local_ids) - 1)),
            max_size=10,
        )
    )
    expected = [blake2b_64(global_ids[g], local_ids[l]) for g, l in pairs]
    assert digests(global_ids, local_ids, pairs) == expected


def test_a_maps_encoded_ids_are_its_ids():
    """`ObjectMap.encoded_ids` (what the clustering digests) spells the map's ids in order,
    and digests read from it are hashlib's."""
    ids = ["chair_1", "tisch-ü", "😀"]
    objects = [SemanticObject(i, "chair", [float(k), 0.0, 0.0]) for k, i in enumerate(ids)]
    encoded = ObjectMap(objects).encoded_ids
    data = encoded.data.tobytes()
    spelled = [data[a:b].decode() for a, b in zip(encoded.starts[:-1], encoded.starts[1:])]
    assert spelled == ids
    got = pair_digests(encoded, np.array([2, 0]), encode_ids(["l"]), np.array([0, 0]))
    assert got.tolist() == [blake2b_64("😀", "l"), blake2b_64("chair_1", "l")]
