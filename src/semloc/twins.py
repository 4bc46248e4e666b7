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
from anchors: G's objects of the rarest labels the map holds more than once, each with a
member of G of a rare label a few metres away, matched to every map pair of the same two
labels at the same distance and height difference (rare labels: few pairs to try).  Motions
that move G's centroid by less than `apart` m (a room's size) are the place itself or its own
repeated objects (a row of chairs shifted by one: the search weighs those); twins closer than
that to each other are one twin (the one that places most objects).  Exact labels only: a
twin is the map's own copy, in the map's vocabulary.

While a place is tracked, each of its twins is weighed against it on the objects that tell
the two apart (`copy_holds`, `copy_leads`): the Localizer doubts the claim when a twin leads
and ends it when a twin leads by more.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.spatial import cKDTree

from semloc._twins_fast import Grid, placed

MIN_TWIN_PAIRS = 3
"""A twin places at least this many of the objects (fewer fix no pose)."""
ANCHORS = 3
"""Anchor pairs tried by default: a copy is found through a pair it holds both members of, and
a copy of an old or partial room (one keeping a random 70 % of the objects) holds a given pair
about half the time, so three pairs miss it about once in eight and eight about once in 200
(each pair more costs a match over the map's pairs of two more common labels)."""


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
    anchors: int = ANCHORS,
    apart: float = 4.0,
    most: int = 8,
    index: TwinIndex | None = None,
) -> list[np.ndarray]:
    """The 4x4 motions S (map to map) that put the map objects `members` on copies of
    themselves elsewhere in the map, most objects placed first (see the module docstring).
    `tree` (of `positions`: the look-ups `index`'s grid cannot tell) and `index` (their
    `TwinIndex`) may be given, built once per map."""
    members = np.unique(np.asarray(members, dtype=np.int64))
    if len(members) < MIN_TWIN_PAIRS:
        return []
    index = TwinIndex(positions, codes) if index is None else index
    up = np.asarray(up, dtype=float) / np.linalg.norm(up)
    need = max(MIN_TWIN_PAIRS, int(np.ceil(min_share * len(members))))
    counts, motions = [np.zeros(0, dtype=np.int64)], [np.zeros((0, 4, 4))]
    for a, b in _anchor_pairs(positions, codes, members, up, anchors):
        found = _motions(positions, codes, up, a, b, tolerance, index)
        placed = _placed(found, positions, codes, members, tolerance, index, need, tree, (a, b))
        counts.append(placed[placed >= need])
        motions.append(found.matrices(placed >= need))
    order = np.argsort(-np.concatenate(counts), kind="stable")  # most objects placed first
    S = np.concatenate(motions)[order]
    centroid = positions[members].mean(axis=0)
    moved = S[:, :3, :3] @ centroid + S[:, :3, 3]
    # (closer: the place itself, or its own repeated objects, e.g. a row of chairs)
    away = np.linalg.norm(moved - centroid, axis=1) >= apart
    kept: list[int] = []
    for i in np.flatnonzero(away):
        if len(kept) == most:
            break
        if all(np.linalg.norm(moved[i] - moved[j]) >= apart for j in kept):
            kept.append(int(i))
    return [S[i] for i in kept]


class TwinIndex:
    """Per label code, the map's objects of it and a KD-tree of their positions, each built
    when first asked (the twins' search matches anchor pairs label by label); how many
    objects each label has; all the objects in a grid per reach (`grid`: the count of what a
    motion places looks them up)."""

    def __init__(self, positions: np.ndarray, codes: np.ndarray) -> None:
        self.positions, self.codes = positions, codes
        self.counts = np.bincount(codes)
        self._grids: dict[float, Grid] = {}
        self._of: dict[int, tuple[np.ndarray, cKDTree]] = {}

    def __call__(self, code: int) -> tuple[np.ndarray, cKDTree]:
        if code not in self._of:
            indices = np.flatnonzero(self.codes == code)
            self._of[code] = (indices, cKDTree(self.positions[indices]))
        return self._of[code]

    def grid(self, reach: float) -> Grid:
        """All the map's objects in a grid of cells at least `reach` m wide."""
        if reach not in self._grids:
            self._grids[reach] = Grid(self.positions, reach)
        return self._grids[reach]


def _anchor_pairs(
    positions: np.ndarray, codes: np.ndarray, members: np.ndarray, up: np.ndarray, anchors: int
) -> list[tuple[int, int]]:
    """Up to `anchors` (a, b): members of the rarest labels that the map holds more than once,
    each with the member of the rarest label at least `SPAN` m from it across the up axis
    (the farthest of those; the farthest of all when none is that far): few map pairs to
    match, a yaw fixed well."""
    counts = np.bincount(codes)[codes[members]]
    order = members[np.argsort(counts, kind="stable")][np.sort(counts) > 1]  # (1: no copy)
    pairs: list[tuple[int, int]] = []
    for a in order[:anchors]:
        offsets = positions[members] - positions[a]
        across = np.linalg.norm(offsets - np.outer(offsets @ up, up), axis=1)
        used = np.isin(members, np.array(pairs, dtype=np.int64).ravel())  # (other pairs)
        across = np.where((counts > 1) & ~used, across, 0.0)
        if across.max() <= 0:
            continue
        far = across >= min(SPAN, across.max())
        pick = np.lexsort((-across, counts))  # rarest label first, then farthest
        pairs.append((int(a), int(members[pick[far[pick]][0]])))
    return pairs


SPAN = 2.0
"""An anchor pair's members lie at least this far apart (m) when the place allows."""
LOOSE = 1 + 1e-9
"""A quick test's bound over the exact one's: it may pass what the exact test then refuses,
and never refuses what the exact test passes, whatever the rounding of the two distances."""


def _motions(
    positions: np.ndarray, codes: np.ndarray, up: np.ndarray, a: int, b: int,
    tolerance: float, index: TwinIndex,
) -> YawMotions:  # fmt: skip
    """Every yaw-and-translation motion taking (a, b) onto a map pair of the same labels at
    the same distance (within `tolerance`) and height difference."""
    offset = positions[b] - positions[a]
    distance, height = np.linalg.norm(offset), offset @ up
    (labelled_a, tree_a), (labelled_b, tree_b) = index(int(codes[a])), index(int(codes[b]))
    # the map pairs about `distance` apart, loosely: the tests below decide
    near = tree_a.sparse_distance_matrix(
        tree_b, (distance + tolerance) * LOOSE, output_type="ndarray"
    )
    near = near[np.abs(near["v"] - distance) <= tolerance * LOOSE]
    a2, b2 = labelled_a[near["i"]], labelled_b[near["j"]]
    offsets = positions[b2] - positions[a2]
    keep = np.flatnonzero(
        (b2 != a2)
        & (np.abs(np.linalg.norm(offsets, axis=1) - distance) <= tolerance)
        & (np.abs(offsets @ up - height) <= tolerance)
    )
    keep = keep[np.lexsort((b2[keep], a2[keep]))]  # (the motions' order: by a2, then b2)
    return YawMotions(positions[a], offset, positions[a2[keep]], offsets[keep], up)


class YawMotions:
    """Rotations about `up` taking v's horizontal part onto each v2's (M), with p onto each
    p2: their sines, cosines, `K` (the cross-product matrix of `up`) and `KK` (K²)."""

    def __init__(
        self, p: np.ndarray, v: np.ndarray, p2: np.ndarray, v2: np.ndarray, up: np.ndarray
    ) -> None:
        h = v - (v @ up) * up
        h2 = v2 - np.outer(v2 @ up, up)
        angles = np.arctan2(np.cross(h, h2) @ up, h2 @ h)
        self.p, self.p2, self.sin, self.cos = p, p2, np.sin(angles), np.cos(angles)
        self.K = np.array([[0, -up[2], up[1]], [up[2], 0, -up[0]], [-up[1], up[0], 0]])
        self.KK = self.K @ self.K

    def __len__(self) -> int:
        return len(self.p2)

    def matrices(self, which: np.ndarray | slice = slice(None)) -> np.ndarray:
        """The motions `which` (an index of them) as 4x4 matrices (m, 4, 4)."""
        sin, cos = self.sin[which][:, None, None], self.cos[which][:, None, None]
        R = np.eye(3) + sin * self.K + (1 - cos) * self.KK
        S = np.tile(np.eye(4), (len(R), 1, 1))
        S[:, :3, :3], S[:, :3, 3] = R, self.p2[which] - R @ self.p
        return S


NEAREST = 4
"""How many nearest map objects of a moved member are looked at for one of its label."""


def _placed(
    S: YawMotions, positions: np.ndarray, codes: np.ndarray, members: np.ndarray,
    tolerance: float, index: TwinIndex, need: int = 0, tree: cKDTree | None = None,
    anchors: tuple[int, ...] = (),
) -> np.ndarray:  # fmt: skip
    """For each motion of S: how many `members` it puts within `tolerance` of a map object of
    their label (among their `NEAREST` nearest); a count under `need` may be short (the
    motion is given up once the members left cannot bring it to `need`).  The map is
    looked up in `index`'s grid; where the grid cannot tell (`_twins_fast`), in `tree` (of
    `positions`; built when needed and not given).  `anchors`: the members of the pair the
    motions were found from."""
    if not len(S):
        return np.zeros(0, dtype=np.int64)
    grid = index.grid(tolerance)
    # rarest labels first (a motion that is no copy misses those soonest), the anchor pair's
    # members last (each motion puts them on its own pair: they seldom miss)
    order = np.lexsort((index.counts[codes[members]], np.isin(members, anchors)))
    counts, unsure = placed(
        S.p, S.p2, S.sin, S.cos, S.K, S.KK, positions[members], codes[members], order, need,
        tolerance, NEAREST, positions, codes, grid.origin, grid.size, grid.dims, grid.starts,
        grid.objects,
    )  # fmt: skip
    if not unsure.any():
        return counts
    m, k = np.nonzero(unsure)  # (counted as placed: looked up exactly here)
    S = S.matrices()
    moved = np.einsum("mij,kj->mki", S[:, :3, :3], positions[members]) + S[:, None, :3, 3]
    tree = cKDTree(positions) if tree is None else tree
    gaps, near = tree.query(moved[m, k], k=NEAREST, distance_upper_bound=tolerance)
    labels = np.where(np.isfinite(gaps), codes[np.minimum(near, len(codes) - 1)], -1)
    np.subtract.at(counts, m, ~(labels == codes[members][k, None]).any(axis=1))
    return counts


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


def copy_holds(
    S: np.ndarray, at: np.ndarray, kinds: np.ndarray, positions: np.ndarray,
    codes: np.ndarray, allowance: np.ndarray, tree: cKDTree,
) -> bool:  # fmt: skip
    """Whether the copy `S` (a map motion) holds a map object of one of `kinds` (label codes)
    within its `allowance` of where `S` puts the map point `at`: any of the map's objects, not
    only a detection's candidates (a prior or the retrieval leave out where the copy lies)."""
    point = S[:3, :3] @ at + S[:3, 3]
    near = np.asarray(tree.query_ball_point(point, allowance.max()), dtype=np.int64)
    near = near[np.isin(codes[near], kinds)]
    gaps = np.linalg.norm(positions[near] - point, axis=1)
    return bool((gaps <= allowance[near]).any())


def twin_lead(updates: Sequence[list[list[str]] | None]) -> tuple[int, int, int]:
    """By how many objects the latest updates tell the best copy rather than the place, over
    how many updates (the fewest among equal leads), and that copy's index (`copy_leads`;
    (0, 0, 0) when none leads)."""
    leads = copy_leads(updates)
    best = max(range(len(leads)), key=lambda i: (leads[i][0], -leads[i][1]), default=0)
    return (*leads[best], best) if leads and leads[best][0] > 0 else (0, 0, 0)


def copy_leads(updates: Sequence[list[list[str]] | None]) -> list[tuple[int, int]]:
    """Per copy, by how many objects the latest updates (oldest first; per update, per copy,
    the keys of the objects that tell the copy from the place: "+..." for the copy, "-..."
    for the place; None: not weighed) tell the copy rather than the place, over the newest
    `n` updates for the `n` that gives most (the fewest of those), and that `n` (0, 0: no
    suffix leads).  An object (a key without its sign) counts once, by its newest evidence.
    The updates before the robot was carried off speak for the place; they do not outweigh
    what it sees since."""
    copies = len(updates[-1]) if updates and updates[-1] is not None else 0
    leads = []
    for i in range(copies):
        newest: set[str] = set()
        lead, best = 0, (0, 0)  # (lead, -n)
        for n, told in enumerate(reversed(updates), start=1):
            for key in told[i] if told else ():
                if key[1:] not in newest:
                    newest.add(key[1:])
                    lead += 1 if key[0] == "+" else -1
            best = max(best, (lead, -n))
        leads.append((best[0], -best[1]))
    return leads
