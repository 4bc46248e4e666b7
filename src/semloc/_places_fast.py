"""Compiled inner loop of place retrieval (`places.py`; numba, cached on disk).

`cell_support` counts, per local object and cell, the other local objects for which the cell
holds a constellation word of the pair: the words of one pair of labels and a range of
distance bins are one contiguous run of the sorted index, found by binary search.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def cell_support(words, cells, first, second, low, high, starts, codes, n_labels, n_bins,
                 n_local, n_cells):  # fmt: skip
    """support[a, c]: how many local objects b (pairs `first`=a, `second`=b, bins `low` to
    `high`) cell c holds a word (label of a candidate of a, of b, bin) for; the labels of a
    local object's candidates are `codes[starts[i]:starts[i + 1]]`."""
    support = np.zeros((n_local, n_cells), np.int32)
    stamp = np.full(n_cells, -1, np.int64)
    for p in range(len(first)):
        a, b = first[p], second[p]
        for i in range(starts[a], starts[a + 1]):
            for j in range(starts[b], starts[b + 1]):
                base = (codes[i] * n_labels + codes[j]) * n_bins
                begin = np.searchsorted(words, base + low[p])
                end = np.searchsorted(words, base + high[p], side="right")
                for e in range(begin, end):
                    c = cells[e]
                    if stamp[c] != p:
                        stamp[c] = p
                        support[a, c] += 1
    return support
