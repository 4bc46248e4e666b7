"""The decision: which candidates are distinct places, how they are ranked, and the status.

Shared by the Localizer and the baselines (only their association step differs).

    localized   the best hypothesis has ≥ `min_pairs` pairs, a fitness of at least
                `min_fitness` (its points land on the map) and dominates every *rival* in
                the terms of the ranking (more pairs or a clearly smaller residual; or a
                score / fitness larger by the factor 1 + margin); a rival has a different
                pose that shares less than `rival_overlap` of its pairs with the best one
                (one swapped association is a variant of the same answer, not a rival);
    ambiguous   hypotheses exist (≥ 2 pairs) but none dominates;
    failed      no association set has 2 or more pairs.

Hypotheses are distinct places: walking down the ranked candidates, one whose pose is within
`distinct_rotation_deg` / `distinct_translation` of a place already listed (or whose pairs are
a subset of one) is skipped (`distinct`), so the top-k are k different answers.
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Iterable, Sequence
from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from semloc.results import Hypothesis, Status
from semloc.transforms import pose_error

RankBy = Literal["residual", "score", "fitness"]
Place = tuple[Collection, np.ndarray | None]  # (pairs, pose) of a candidate answer


class DecisionConfig(BaseModel):
    """When a hypothesis counts as the answer, and when two hypotheses are the same place."""

    model_config = ConfigDict(extra="forbid")

    min_pairs: int = Field(3, ge=2, description="Pairs the best set needs to be 'localized'.")
    min_fitness: float = Field(
        0.3,
        ge=0,
        le=1,
        description="Fitness the best hypothesis needs to be 'localized': the share of its local "
        "points (without points: of its matched centres) that land on the global map; 0 = off.",
    )
    margin: float = Field(
        0.5,
        ge=0,
        description="Dominance factor over every rival: residual (m) at least (1 + margin) x "
        "the best's plus residual_floor, or score / fitness at most 1 / (1 + margin) of it.",
    )
    residual_floor: float = Field(
        0.02, ge=0, description="Residual difference (m) below which two hypotheses tie."
    )
    rival_overlap: float = Field(
        0.5,
        ge=0,
        le=1,
        description="A hypothesis sharing at least this share of pairs with the best one is a "
        "variant of it, not a rival, when deciding dominance.",
    )
    distinct_rotation_deg: float = Field(
        10.0, gt=0, description="Hypotheses closer than this in rotation are the same place."
    )
    distinct_translation: float = Field(
        0.3, gt=0, description="Hypotheses closer than this (m) in translation are the same place."
    )


def same_place(candidate: Place, other: Place, config: DecisionConfig) -> bool:
    """Whether `candidate` repeats `other`: a subset of its pairs, or a pose close to its pose."""
    pairs, pose = candidate
    if pairs and set(pairs) <= set(other[0]):
        return True
    if pose is None or other[1] is None:
        return False
    rotation, translation = pose_error(pose, other[1])
    return rotation < config.distinct_rotation_deg and translation < config.distinct_translation


def distinct(places: Iterable[Place], top_k: int, config: DecisionConfig) -> list[int]:
    """Indices of the first `top_k` places (in the given order) that repeat no earlier pick.

    `places` is consumed lazily, so a generator computes poses only as far as needed."""
    chosen: list[tuple[int, Place]] = []
    for i, place in enumerate(places):
        if not any(same_place(place, other, config) for _, other in chosen):
            chosen.append((i, place))
            if len(chosen) == top_k:
                break
    return [i for i, _ in chosen]


_INF = float("inf")
RANKINGS: dict[str, Callable[[Hypothesis], tuple | float]] = {
    "score": lambda h: -h.score,
    "residual": lambda h: (-len(h.pairs), _INF if h.residual is None else h.residual, -h.score),
    "fitness": lambda h: (-(h.fitness if h.fitness is not None else -1.0), -h.score),
}


def rank(hypotheses: list[Hypothesis], rank_by: RankBy) -> list[Hypothesis]:
    """The hypotheses in the order of `rank_by`, renumbered 1, 2, ..."""
    ordered = sorted(hypotheses, key=RANKINGS[rank_by])
    for position, h in enumerate(ordered, 1):
        h.rank = position
    return ordered


def decide(hypotheses: Sequence[Hypothesis], config: DecisionConfig, rank_by: RankBy) -> Status:
    """The status of ranked hypotheses (best first); see the module docstring."""
    if not hypotheses:
        return "failed"
    best = hypotheses[0]
    if len(best.pairs) < config.min_pairs or best.pose is None:
        return "ambiguous"
    if best.fitness is not None and best.fitness < config.min_fitness:
        return "ambiguous"  # consistent centres, but the objects' points do not overlap
    rivals = [h for h in hypotheses[1:] if _is_rival(best, h, config.rival_overlap)]
    if all(_dominates(best, rival, rank_by, config) for rival in rivals):
        return "localized"
    return "ambiguous"


def _dominates(best: Hypothesis, rival: Hypothesis, rank_by: RankBy, d: DecisionConfig) -> bool:
    """Whether `best` beats `rival` clearly, in the terms of the chosen ranking."""
    if rank_by == "score":
        return best.score >= (1.0 + d.margin) * rival.score
    if rank_by == "fitness":
        return (best.fitness or 0.0) >= (1.0 + d.margin) * (rival.fitness or 0.0)
    if len(rival.pairs) < len(best.pairs) or rival.residual is None:
        return True
    return rival.residual > (1.0 + d.margin) * (best.residual or 0.0) + d.residual_floor


def _is_rival(best: Hypothesis, other: Hypothesis, max_overlap: float) -> bool:
    """Whether `other` is a different answer: it shares few of its pairs with `best`."""
    shared = len(set(best.pairs) & set(other.pairs))
    return shared < max_overlap * min(len(best.pairs), len(other.pairs))
