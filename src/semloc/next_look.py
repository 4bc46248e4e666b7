""" "Look there next": where an ambiguous robot should look to tell its rival places apart.

When the answer is `ambiguous`, the top hypotheses put the local frame at different places of
the map.  A map object near one of those places lies, under each hypothesis r, at one spot of
the local frame, `where[r]` = T_r⁻¹ p.  Looking at the spot `where[r]`:

* seeing an object of its label there confirms r, and not seeing one rules r out, **unless**
  another top hypothesis also expects an object of that label at that spot (a map object of
  the same label within `look_tolerance` of where it puts the spot): then the look does not tell
  the two apart.  The ranks whose spot is theirs alone and within `look_reach` of the objects seen
  so far (a spot the robot can get to look at) are the ones the suggestion **separates**.
* Its **gain** is the expected reduction of the ambiguity, in bits: the entropy of the
  outcome of looking at every separated spot, with the hypotheses' confidences as their
  probabilities (normalised over the top hypotheses; equal when none has one).  Each
  separated rank is its own outcome and the other ranks together one more, so two equally
  likely places give 1 bit.

Suggestions are map objects within `look_reach` of the local objects under some top hypothesis;
a rank is not separated by a spot already looked at (a local object of the same label lies
within `look_tolerance` of it: what it shows is already in the evidence).  Best first by gain,
then by what one look there may see (how many spots that tell the same rank apart lie within
`look_sight` of it: a look sees an area, not one object), then by how near the spot is to the
objects seen (a nearer look is cheaper); at most `suggestions` of them, one per spot.
Everything comes from the hypotheses' poses and the map: no new sensor is needed.  Pure
computation on numpy arrays.

**Which hypotheses are weighed.**  The top `look_hypotheses` with a pose inside the caller's
position prior; when fewer than two lie inside it, those outside count too: a place outside
the prior that forbids a claim is the rival a look must tell apart.

**When nothing nearby tells them apart.**  In a building of look-alike rooms every other copy
may hold an object of the label near each spot (a row of chairs in every classroom), so no spot
is one place's alone among five.  An ambiguous answer with two or more places still gets a
suggestion, widened step by step as a robot would go: first tell fewer places apart (the best
four, three, then the best two: one look that settles the top two is worth more than none),
then look farther (twice `look_reach`, then `WIDER_REACH` times it, where any gain counts):
nearer first, as a robot pays for every metre.  A suggestion's `where` holds the ranks it
weighed.  Only when even the widest look tells nothing (identical copies in an otherwise empty
map) is the list empty.
"""

from __future__ import annotations

import math
import weakref
from collections.abc import Sequence

import numpy as np
from pydantic import BaseModel, ConfigDict, Field
from scipy.spatial import cKDTree

from semloc.maps import ObjectMap
from semloc.results import Hypothesis, Look

__all__ = ["NextLookConfig", "next_look"]


class NextLookConfig(BaseModel):
    """How many suggestions, over how many hypotheses, how far from what was seen."""

    model_config = ConfigDict(extra="forbid")

    suggestions: int = Field(3, ge=0, description="Suggestions of an ambiguous answer (0: none).")
    look_hypotheses: int = Field(5, ge=2, description="Top hypotheses (with a pose) weighed.")
    look_min_gain: float = Field(
        0.05, ge=0, description="Suggestions expected to tell less than this (bits) are left out."
    )
    look_sight: float = Field(
        2.0, gt=0, description="Objects within this distance (m) of a spot are seen by one look."
    )
    look_reach: float = Field(
        8.0, gt=0, description="A spot to look at lies within this distance (m) of a seen object."
    )
    look_tolerance: float = Field(
        1.0, gt=0, description="Two hypotheses expect the same object at a spot within this (m)."
    )


_TREES: weakref.WeakKeyDictionary[ObjectMap, dict[str, cKDTree]] = weakref.WeakKeyDictionary()


def _label_trees(labels: np.ndarray, positions: np.ndarray) -> dict[str, cKDTree]:
    """KD-trees of all objects ("") and of each label's objects."""
    positions = np.asarray(positions, dtype=float).reshape(-1, 3)
    trees = {"": cKDTree(positions)}
    for label in np.unique(labels):
        trees[str(label)] = cKDTree(positions[labels == label])
    return trees


def _trees(global_map: ObjectMap) -> dict[str, cKDTree]:
    """The map's label trees, built once per map."""
    if global_map not in _TREES:
        _TREES[global_map] = _label_trees(np.asarray(global_map.labels), global_map.positions)
    return _TREES[global_map]


def _counts(points: np.ndarray, labels: np.ndarray, trees: dict, radius: float) -> np.ndarray:
    """How many objects of each point's label (`labels`, per leading index) lie within
    `radius` of it; `points` is (G, ..., 3)."""
    counts = np.zeros(points.shape[:-1], dtype=np.int64)
    for label in np.unique(labels):
        rows = labels == label
        tree = trees.get(str(label))
        if tree is not None:
            counts[rows] = tree.query_ball_point(points[rows], radius, return_length=True)
    return counts


WIDER_REACH = 4.0
"""The widest search for a telling spot, as a multiple of `look_reach` (the last resort)."""


def next_look(
    hypotheses: Sequence[Hypothesis],
    global_map: ObjectMap,
    local_labels: Sequence[str],
    local_positions: np.ndarray,
    config: NextLookConfig | None = None,
) -> list[Look]:
    """The suggestions for an ambiguous answer's `hypotheses` (best first), given the local
    objects seen so far (labels and positions, local frame) and the global map.  Widened step
    by step until one is found (module docstring, "When nothing nearby tells them apart")."""
    config = config or NextLookConfig()
    posed = [h for h in hypotheses if h.pose is not None]
    inside = [h for h in posed if not h.outside_prior]
    weighed = (inside if len(inside) >= 2 else posed)[: config.look_hypotheses]
    seen = np.asarray(local_positions, dtype=float).reshape(-1, 3)
    if config.suggestions == 0 or len(weighed) < 2 or len(seen) == 0 or len(global_map) == 0:
        return []
    for count, reach, min_gain in _widening(config, len(weighed)):
        step = config.model_copy(update={"look_reach": reach, "look_min_gain": min_gain})
        looks = _looks(weighed[:count], global_map, local_labels, seen, step)
        if looks:
            return looks
    return []


def _widening(config: NextLookConfig, weighed: int) -> list[tuple[int, float, float]]:
    """The searches tried in turn: (hypotheses weighed, reach, least gain)."""
    reach, gain = config.look_reach, config.look_min_gain
    fewer = [(count, reach, gain) for count in range(weighed, 1, -1)]
    return [*fewer, (2, 2 * reach, gain), (2, WIDER_REACH * reach, 0.0)]


def _looks(
    top: list[Hypothesis],
    global_map: ObjectMap,
    local_labels: Sequence[str],
    seen: np.ndarray,
    config: NextLookConfig,
) -> list[Look]:
    """The suggestions that tell the hypotheses `top` apart, within `config`'s reach."""
    poses = np.array([h.pose for h in top])
    inverses = np.linalg.inv(poses)
    weights = np.array([h.confidence or 0.0 for h in top])
    weights = weights / weights.sum() if weights.sum() > 0 else np.full(len(top), 1 / len(top))
    trees = _trees(global_map)
    near: set[int] = set()
    for pose in poses:
        in_global = seen @ pose[:3, :3].T + pose[:3, 3]
        near.update(*trees[""].query_ball_point(in_global, config.look_reach))
    if not near:
        return []
    candidates = np.array(sorted(near))
    labels = np.asarray(global_map.labels)[candidates]
    # spots[g, r]: where candidate g lies in the local frame if hypothesis r is right
    positions = np.asarray(global_map.positions)[candidates]
    spots = np.einsum("rij,gj->gri", inverses[:, :3, :3], positions) + inverses[:, :3, 3]
    local = _label_trees(np.asarray(local_labels), seen)
    distance = local[""].query(spots)[0]
    already = _counts(spots, labels, local, config.look_tolerance) > 0
    # expected[g, r, o]: where hypothesis o puts spot (g, r) in the map
    expected = np.einsum("oij,grj->groi", poses[:, :3, :3], spots) + poses[:, :3, 3]
    others = _counts(expected, labels, trees, config.look_tolerance)
    others[:, np.arange(len(top)), np.arange(len(top))] = 0  # r itself
    separated = (distance <= config.look_reach) & ~already & (others.sum(axis=2) == 0)
    telling = _telling_nearby(spots, separated, config.look_sight)
    looks = []
    for g in np.flatnonzero(separated.any(axis=1)):
        chosen = np.flatnonzero(separated[g])
        outcomes = [*weights[chosen], 1.0 - weights[chosen].sum()]
        gain = -sum(p * math.log2(p) for p in outcomes if p > 1e-12)
        if gain < max(config.look_min_gain, 1e-9):
            continue
        look = Look(
            label=str(labels[g]),
            global_id=str(global_map.ids[candidates[g]]),
            where={h.rank: spots[g, r] for r, h in enumerate(top)},
            separates=sorted(top[r].rank for r in chosen),
            gain=float(gain),
        )
        evidence = int(telling[g, chosen].max())
        looks.append((round(gain, 6), -evidence, float(distance[g, chosen].min()), look))
    looks.sort(key=lambda item: (-item[0], item[1], item[2], item[3].global_id))
    return _one_per_spot(looks, config)


def _telling_nearby(spots: np.ndarray, separated: np.ndarray, sight: float) -> np.ndarray:
    """[g, r]: how many separated spots of rank r lie within `sight` of spot (g, r): what one
    look there may see that tells r from the others."""
    telling = np.zeros(separated.shape, dtype=np.int64)
    for r in range(separated.shape[1]):
        rows = np.flatnonzero(separated[:, r])
        if len(rows):
            points = spots[rows, r]
            close = np.linalg.norm(points[:, None] - points[None], axis=2) <= sight
            telling[rows, r] = close.sum(axis=1)
    return telling


def _one_per_spot(looks: list[tuple], config: NextLookConfig) -> list[Look]:
    """The best suggestions, one per label and spot (the same spot of a separated rank)."""
    chosen: list[Look] = []
    for *_, look in looks:
        rank = look.separates[0]
        if any(
            other.label == look.label
            and rank in other.separates
            and np.linalg.norm(other.where[rank] - look.where[rank]) < config.look_tolerance
            for other in chosen
        ):
            continue
        chosen.append(look)
        if len(chosen) == config.suggestions:
            break
    return chosen
