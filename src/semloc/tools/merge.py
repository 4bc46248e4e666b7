"""One map from two aligned maps: matched objects fused, the others kept, each with provenance.

`semloc align --merged` writes it.  B must already be in A's frame (`ObjectMap.transformed`
with the alignment's pose).  A matched pair becomes one object with A's id and label: its points
are the union of both objects' points, its centre the mean of those points (the two centres'
mean without points), its box A's (B's when A has none).  Every object carries
`"provenance": {"from": "A" | "B" | "both", "ids": [...]}` among its extra keys (written to the
map file; unknown keys survive a round trip); an unmatched object of B whose id is taken in A is
renamed `B:<id>`.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from semloc.maps import ObjectMap, SemanticObject


def merged_map(a: ObjectMap, b_in_a: ObjectMap, pairs: Iterable[tuple[str, str]]) -> ObjectMap:
    """A and B (in A's frame) as one map; `pairs` are the (A id, B id) correspondences."""
    partner = dict(pairs)
    matched_b = set(partner.values())
    objects = [
        _fused(obj, b_in_a.get(partner[obj.id])) if obj.id in partner else _tagged(obj, "A")
        for obj in a
    ]
    taken = {o.id for o in objects}
    for obj in b_in_a:
        if obj.id not in matched_b:
            renamed = obj if obj.id not in taken else obj.replace(id=_free_id(obj.id, taken))
            taken.add(renamed.id)
            objects.append(_tagged(renamed, "B", [obj.id]))
    return ObjectMap(objects, up=a.up, name=f"{a.name}+{b_in_a.name}".strip("+"), extra=a.extra)


def _tagged(obj: SemanticObject, source: str, ids: list[str] | None = None) -> SemanticObject:
    provenance = {"from": source, "ids": ids or [obj.id]}
    return obj.replace(extra={**obj.extra, "provenance": provenance})


def _fused(a: SemanticObject, b: SemanticObject) -> SemanticObject:
    clouds = [p for p in (a.points, b.points) if p is not None and len(p)]
    points = np.vstack(clouds) if clouds else None
    position = points.mean(axis=0) if points is not None else (a.position + b.position) / 2
    size, rotation = (a.size, a.rotation) if a.size is not None else (b.size, b.rotation)
    fused = a.replace(
        position=position, points=points, size=size, rotation=rotation, seen=min(a.seen, b.seen)
    )
    return _tagged(fused, "both", [a.id, b.id])


def _free_id(wanted: str, taken: set[str]) -> str:
    candidate, n = f"B:{wanted}", 2
    while candidate in taken:
        candidate, n = f"B:{wanted}#{n}", n + 1
    return candidate
