"""What the comparison methods remember between calls in one process: the last few values by
key (`Recent`), and a map's content fingerprint (`map_fingerprint`) for keys.

A benchmark worker receives copies of the same maps in many chains, so what a method computes
from a map alone (features, descriptors, indexes, renderings) is kept by the map's content, or
by the object's identity when the object itself is kept alive (`owner`).
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict
from collections.abc import Callable, Hashable
from typing import Any, TypeVar

import numpy as np

from semloc.maps import ObjectMap

T = TypeVar("T")


class Recent:
    """The values of the last `size` keys asked for (the least recently used is dropped)."""

    def __init__(self, size: int) -> None:
        self.size = size
        self._items: OrderedDict[Hashable, tuple[Any, Any]] = OrderedDict()

    def get(self, key: Hashable, make: Callable[[], T], owner: Any = None) -> T:
        """The value of `key`, made by `make()` when missing.  With `owner`, a kept value counts
        only for that very object (an `id()` in the key can be reused by a new one)."""
        hit = self._items.pop(key, None)
        value = hit[1] if hit is not None and hit[0] is owner else make()
        self.put(key, value, owner)
        return value

    def clear(self) -> None:
        self._items.clear()

    def put(self, key: Hashable, value: Any, owner: Any = None) -> None:
        self._items[key] = (owner, value)  # most recently used last
        while len(self._items) > self.size:
            self._items.popitem(last=False)


def map_fingerprint(global_map: ObjectMap, *settings: str) -> str:
    """A digest of a map's content (positions, labels, `up`, the first points of each object)
    and of `settings` (e.g. a config's JSON)."""
    digest = hashlib.sha1("/".join(settings).encode())
    digest.update(np.ascontiguousarray(global_map.positions).tobytes())
    digest.update("/".join(global_map.labels).encode())
    digest.update(np.asarray(global_map.up if global_map.up is not None else []).tobytes())
    for obj in global_map:
        if obj.points is not None:
            digest.update(np.ascontiguousarray(obj.points[:50]).tobytes())
    return digest.hexdigest()
