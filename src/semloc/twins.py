"""Twins: where else the map holds a place's objects in the same arrangement.

A building of look-alike rooms holds each room's layout several times: classrooms, hotel
rooms, the copies of a tiled floor.  The search grows association sets from the local view;
when the map is old or the view is partial, the sets of the right copy can lose to those of
another copy (or be pruned before the answer), and a decision that weighs only the sets it
found cannot know that a copy it did not list would explain the view as well.  So before a
place is claimed, its twins are looked up in the map itself and weighed as hypotheses.

A twin of a set of map objects G is a rigid motion S about the map's up axis (yaw and a
translation: copies of a room stand upright) that puts at least `min_share` of G, and at
least 3 of them, within `tolerance` of map objects of the same label.  Candidate motions come
from anchors: G's objects of the rarest labels the map holds more than once, each with the
member of G farthest from it, matched to every map pair of the same two labels at the same
distance and height difference.  Motions that move G's centroid by less than `same_place` m
are the place itself; twins closer than that to each other are one twin (the one that places
most objects).  Exact labels only: a twin is the map's own copy, in the map's vocabulary.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

MIN_TWIN_PAIRS = 3
"""A twin places at least this many of the objects (fewer fix no pose)."""


def label_codes(labels: np.ndarray) -> np.ndarray:
    """Each label as a small integer (equal labels, equal codes)."""
    _, codes = np.unique(np.asarray(labels, dtype=str), return_inverse=True)
    return codes.astype(np.int64)


def twins(
    positions: np.ndarray,
    codes: np.ndarray,
    up: np.ndarray,
    members: np.ndarray,
    tolerance: float,
    *,
    tree: cKDTree | None = None,
    min_share: float = 0.5,
    anchors: int = 3,
    same_place: float = 1.0,
    most: int = 8,
) -> list[np.ndarray]:
    """The 4x4 motions S (map to map) that put the map objects `members` on copies of
    themselves elsewhere in the map, most objects placed first (see the module docstring)."""
    members = np.unique(np.asarray(members, dtype=np.int64))
    if len(members) < MIN_TWIN_PAIRS:
        return []
    tree = cKDTree(positions) if tree is None else tree
    up = np.asarray(up, dtype=float) / np.linalg.norm(up)
    need = max(MIN_TWIN_PAIRS, int(np.ceil(min_share * len(members))))
    found: list[tuple[int, np.ndarray]] = []
    for a, b in _anchor_pairs(positions, codes, members, up, anchors):
        for S in _motions(positions, codes, up, a, b, tolerance, tree):
            placed = _placed(S, positions, codes, members, tolerance, tree)
            if placed >= need:
                found.append((placed, S))
    centroid = positions[members].mean(axis=0)
    kept: list[tuple[int, np.ndarray]] = []
    for placed, S in sorted(found, key=lambda f: -f[0]):
        moved = S[:3, :3] @ centroid + S[:3, 3]
        if np.linalg.norm(moved - centroid) < same_place:
            continue  # the place itself
        if all(np.linalg.norm(moved - (T[:3, :3] @ centroid + T[:3, 3])) >= same_place
               for _, T in kept):  # fmt: skip
            kept.append((placed, S))
    return [S for _, S in kept[:most]]


def _anchor_pairs(
    positions: np.ndarray, codes: np.ndarray, members: np.ndarray, up: np.ndarray, anchors: int
) -> list[tuple[int, int]]:
    """Up to `anchors` (a, b): members of the rarest labels that the map holds more than once,
    each with the member farthest from it across the up axis (the pair that fixes the yaw
    best)."""
    counts = np.bincount(codes)[codes[members]]
    order = members[np.argsort(counts, kind="stable")][np.sort(counts) > 1]  # (1: no copy)
    pairs = []
    for a in order[:anchors]:
        offsets = positions[members] - positions[a]
        across = np.linalg.norm(offsets - np.outer(offsets @ up, up), axis=1)
        b = members[int(np.argmax(across))]
        if across.max() > 0:
            pairs.append((int(a), int(b)))
    return pairs


def _motions(
    positions: np.ndarray, codes: np.ndarray, up: np.ndarray, a: int, b: int,
    tolerance: float, tree: cKDTree,
) -> list[np.ndarray]:  # fmt: skip
    """Every yaw-and-translation motion taking (a, b) onto a map pair of the same labels at
    the same distance (within `tolerance`) and height difference."""
    offset = positions[b] - positions[a]
    distance, height = np.linalg.norm(offset), offset @ up
    others = np.flatnonzero(codes == codes[a])
    reach = tree.query_ball_point(positions[others], distance + tolerance)
    motions = []
    for a2, near in zip(others.tolist(), reach):
        for b2 in near:
            if codes[b2] != codes[b] or b2 == a2:
                continue
            offset2 = positions[b2] - positions[a2]
            if abs(np.linalg.norm(offset2) - distance) > tolerance:
                continue
            if abs(offset2 @ up - height) > tolerance:
                continue
            motions.append(_yaw_motion(positions[a], offset, positions[a2], offset2, up))
    return motions


def _yaw_motion(
    p: np.ndarray, v: np.ndarray, p2: np.ndarray, v2: np.ndarray, up: np.ndarray
) -> np.ndarray:
    """The rotation about `up` taking v's horizontal part onto v2's, with p onto p2."""
    h, h2 = v - (v @ up) * up, v2 - (v2 @ up) * up
    angle = np.arctan2(np.cross(h, h2) @ up, h @ h2)
    K = np.array([[0, -up[2], up[1]], [up[2], 0, -up[0]], [-up[1], up[0], 0]])
    R = np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * (K @ K)
    S = np.eye(4)
    S[:3, :3], S[:3, 3] = R, p2 - R @ p
    return S


def _placed(
    S: np.ndarray, positions: np.ndarray, codes: np.ndarray, members: np.ndarray,
    tolerance: float, tree: cKDTree,
) -> int:  # fmt: skip
    """How many `members` S puts within `tolerance` of a map object of their label."""
    moved = positions[members] @ S[:3, :3].T + S[:3, 3]
    near = tree.query_ball_point(moved, tolerance)
    return sum(any(codes[j] == codes[m] for j in js) for m, js in zip(members.tolist(), near))


def twin_pairs(
    S: np.ndarray,
    pairs: list[tuple[int, int]],
    positions: np.ndarray,
    codes: np.ndarray,
    tolerance: float,
    tree: cKDTree,
) -> list[tuple[int, int]]:
    """The (global, local) index pairs of a twin: each pair's map object moved by S onto the
    nearest map object of its label within `tolerance` (one-to-one)."""
    out, taken = [], set()
    for g, l in pairs:
        moved = S[:3, :3] @ positions[g] + S[:3, 3]
        near = [j for j in tree.query_ball_point(moved, tolerance) if codes[j] == codes[g]]
        near = [j for j in near if j not in taken]
        if near:
            j = min(near, key=lambda j: np.linalg.norm(positions[j] - moved))
            taken.add(j)
            out.append((int(j), int(l)))
    return out
