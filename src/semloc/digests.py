"""64-bit digests of (global id, local id) pairs: BLAKE2b (RFC 7693) compiled for many pairs.

The clustering breaks ties between equally scored association sets by the digests of their
pairs, which depend on the object ids only, never on the order in which objects arrived.  The
digest of a pair is the 8-byte BLAKE2b of the UTF-8 text "global id\\x00local id", read as a
little-endian unsigned 64-bit integer: the number `hashlib.blake2b(text, digest_size=8)` gives,
computed for thousands of pairs in one compiled pass instead of one Python call per pair.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
from numba import njit

__all__ = ["EncodedIds", "encode_ids", "pair_digests"]

_IV = np.array(
    [
        0x6A09E667F3BCC908, 0xBB67AE8584CAA73B, 0x3C6EF372FE94F82B, 0xA54FF53A5F1D36F1,
        0x510E527FADE682D1, 0x9B05688C2B3E6C1F, 0x1F83D9ABFB41BD6B, 0x5BE0CD19137E2179,
    ],
    dtype=np.uint64,
)  # fmt: skip
_SIGMA = np.array(
    [
        [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15],
        [14, 10, 4, 8, 9, 15, 13, 6, 1, 12, 0, 2, 11, 7, 5, 3],
        [11, 8, 12, 0, 5, 2, 15, 13, 10, 14, 3, 6, 7, 1, 9, 4],
        [7, 9, 3, 1, 13, 12, 11, 14, 2, 6, 5, 10, 4, 0, 15, 8],
        [9, 0, 5, 7, 2, 4, 10, 15, 14, 1, 11, 12, 6, 8, 3, 13],
        [2, 12, 6, 10, 0, 11, 8, 3, 4, 13, 7, 5, 15, 14, 1, 9],
        [12, 5, 1, 15, 14, 13, 4, 10, 0, 7, 6, 3, 9, 2, 8, 11],
        [13, 11, 7, 14, 12, 1, 3, 9, 5, 0, 15, 4, 8, 6, 2, 10],
        [6, 15, 14, 9, 11, 3, 0, 8, 12, 2, 13, 7, 1, 4, 10, 5],
        [10, 2, 8, 4, 7, 6, 1, 5, 15, 11, 9, 14, 3, 12, 13, 0],
    ],
    dtype=np.int64,
)
_BLOCK = 128  # bytes per compression
_DIGEST_BYTES = 8
_SEPARATOR = 0  # the byte between the two ids


class EncodedIds(NamedTuple):
    """Object ids as UTF-8 bytes: id i is `data[starts[i]:starts[i + 1]]`."""

    data: np.ndarray  # uint8
    starts: np.ndarray  # int64, one more than the ids


def encode_ids(ids: Sequence[str]) -> EncodedIds:
    """The UTF-8 bytes of each id, concatenated."""
    text = "".join(ids)
    if text.isascii():  # one character, one byte: no per-id encoding
        data = text.encode("ascii")
        lengths = np.fromiter(map(len, ids), dtype=np.int64, count=len(ids))
    else:
        encoded = [i.encode() for i in ids]
        data = b"".join(encoded)
        lengths = np.fromiter(map(len, encoded), dtype=np.int64, count=len(ids))
    starts = np.zeros(len(ids) + 1, dtype=np.int64)
    np.cumsum(lengths, out=starts[1:])
    return EncodedIds(np.frombuffer(data, dtype=np.uint8), starts)


def pair_digests(
    global_ids: EncodedIds, global_rows: np.ndarray, local_ids: EncodedIds, local_rows: np.ndarray
) -> np.ndarray:
    """The digest of each pair (global id `global_rows[i]`, local id `local_rows[i]`), uint64."""
    return _pair_digests(
        global_ids.data, global_ids.starts, np.asarray(global_rows, dtype=np.int64),
        local_ids.data, local_ids.starts, np.asarray(local_rows, dtype=np.int64), _IV, _SIGMA,
    )  # fmt: skip


@njit(cache=True, nogil=True)
def _pair_digests(g_data, g_starts, g_rows, l_data, l_starts, l_rows, iv, sigma):
    """`pair_digests` on the arrays: each message is built in one scratch buffer."""
    longest = 1
    for i in range(len(g_rows)):
        n = g_starts[g_rows[i] + 1] - g_starts[g_rows[i]] + 1
        n += l_starts[l_rows[i] + 1] - l_starts[l_rows[i]]
        longest = max(longest, n)
    message = np.empty(longest, dtype=np.uint8)
    out = np.empty(len(g_rows), dtype=np.uint64)
    h, m = np.empty(8, dtype=np.uint64), np.empty(16, dtype=np.uint64)
    for i in range(len(g_rows)):
        g0, g1 = g_starts[g_rows[i]], g_starts[g_rows[i] + 1]
        l0, l1 = l_starts[l_rows[i]], l_starts[l_rows[i] + 1]
        n = g1 - g0
        message[:n] = g_data[g0:g1]
        message[n] = _SEPARATOR
        message[n + 1 : n + 1 + l1 - l0] = l_data[l0:l1]
        out[i] = _blake2b_64(message[: n + 1 + l1 - l0], iv, sigma, h, m)
    return out


@njit(cache=True, nogil=True)
def _blake2b_64(message, iv, sigma, h, m):
    """BLAKE2b of `message` with an 8-byte digest, unkeyed, as the number its bytes spell
    (little-endian); h and m are scratch arrays of 8 and 16 words."""
    h[:] = iv
    h[0] ^= np.uint64(0x01010000 ^ _DIGEST_BYTES)
    size = len(message)
    blocks = max(1, (size + _BLOCK - 1) // _BLOCK)
    for b in range(blocks):
        begin = b * _BLOCK
        end = min(size, begin + _BLOCK)
        m[:] = 0
        for k in range(end - begin):
            m[k >> 3] |= np.uint64(message[begin + k]) << np.uint64(8 * (k & 7))
        last = b == blocks - 1
        _compress(h, m, np.uint64(end if last else begin + _BLOCK), last, iv, sigma)
    return h[0]


@njit(cache=True, nogil=True, inline="always")
def _rotr(x, n):
    return (x >> np.uint64(n)) | (x << np.uint64(64 - n))


@njit(cache=True, nogil=True, inline="always")
def _mix(a, b, c, d, x, y):
    """The G function: four state words mixed with the message words x and y."""
    a = a + b + x
    d = _rotr(d ^ a, 32)
    c = c + d
    b = _rotr(b ^ c, 24)
    a = a + b + y
    d = _rotr(d ^ a, 16)
    c = c + d
    b = _rotr(b ^ c, 63)
    return a, b, c, d


@njit(cache=True, nogil=True)
def _compress(h, m, counter, last, iv, sigma):
    """The compression function F on the state h with the block m (words), counter bytes;
    the working vector v0..v15 stays in registers."""
    v0, v1, v2, v3, v4, v5, v6, v7 = h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7]
    v8, v9, v10, v11, v12, v13, v14, v15 = iv[0], iv[1], iv[2], iv[3], iv[4], iv[5], iv[6], iv[7]
    v12 ^= counter  # the counter's high word is 0 below 2**64 bytes
    if last:
        v14 = ~v14
    for r in range(12):
        i = r % 10
        v0, v4, v8, v12 = _mix(v0, v4, v8, v12, m[sigma[i, 0]], m[sigma[i, 1]])
        v1, v5, v9, v13 = _mix(v1, v5, v9, v13, m[sigma[i, 2]], m[sigma[i, 3]])
        v2, v6, v10, v14 = _mix(v2, v6, v10, v14, m[sigma[i, 4]], m[sigma[i, 5]])
        v3, v7, v11, v15 = _mix(v3, v7, v11, v15, m[sigma[i, 6]], m[sigma[i, 7]])
        v0, v5, v10, v15 = _mix(v0, v5, v10, v15, m[sigma[i, 8]], m[sigma[i, 9]])
        v1, v6, v11, v12 = _mix(v1, v6, v11, v12, m[sigma[i, 10]], m[sigma[i, 11]])
        v2, v7, v8, v13 = _mix(v2, v7, v8, v13, m[sigma[i, 12]], m[sigma[i, 13]])
        v3, v4, v9, v14 = _mix(v3, v4, v9, v14, m[sigma[i, 14]], m[sigma[i, 15]])
    h[0] ^= v0 ^ v8
    h[1] ^= v1 ^ v9
    h[2] ^= v2 ^ v10
    h[3] ^= v3 ^ v11
    h[4] ^= v4 ^ v12
    h[5] ^= v5 ^ v13
    h[6] ^= v6 ^ v14
    h[7] ^= v7 ^ v15
