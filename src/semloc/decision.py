"""The decision: which candidates are distinct places, how they are ranked, how sure, the status.

Shared by the Localizer and the baselines (only their association step differs).

Confidence.  A hypothesis verified by the Localizer carries `features` (`FEATURES`: inlier
pairs, share of rejected pairs, centre residual, point fitness, supporting and conflicting
local objects outside the set; see `semloc.verification.Evidence`).  The shipped
`ConfidenceModel` (`confidence_model.py` beside this module, fitted on simulated benchmark
attempts by `benchmarks/calibrate_confidence.py`) turns them into a ranking logit, which
orders the hypotheses (`rank_by="evidence"`: which place of this answer is right), an
`evidence` logit and a calibrated `confidence`: the probability that the pose is right
(15 deg / 0.5 m), from the evidence and its gap to the best rival place's evidence.  A rival
is another distinct place that shares less than `rival_overlap` of the hypothesis' pairs
(`is_rival`); one that shares more is a variant of the same answer, not a rival.

    localized   the best hypothesis has >= `min_pairs` pairs, a fitness of at least
                `min_fitness`, and a confidence of at least `min_confidence` (chosen for >= 99 %
                precision on every kind of calibration attempt).  Hypotheses without a confidence (the
                baselines') must instead dominate every *rival* in the terms of the ranking
                (more pairs or a clearly smaller residual; or a score / fitness larger by the
                factor 1 + margin); a rival there has a different pose and shares less
                than `rival_overlap` of the smaller one's pairs with the best one;
    ambiguous   hypotheses exist (>= 2 pairs) but the best is not trusted (or its pose lies
                outside the caller's position prior, `semloc.priors`, or the search had to
                leave out places as well supported as the best, `cut_search`); `reason` says
                why;
    failed      no association set has 2 or more pairs; `reason` says why.

Hypotheses are distinct places: walking down the ranked candidates, one whose pose is within
`distinct_rotation_deg` / `distinct_translation` of a place already listed (or whose pairs are
a subset of one) is skipped (`distinct`), so the top-k are k different answers.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Collection, Iterable, Sequence
from functools import cache
from pathlib import Path
from typing import Literal, NamedTuple

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from semloc._decision_fast import first_same_place
from semloc.confidence_model import SHIPPED
from semloc.coverage import GONE_SHARE
from semloc.priors import OUTSIDE_PRIOR
from semloc.results import Hypothesis, Status
from semloc.transforms import pose_error

RankBy = Literal["evidence", "residual", "score", "fitness"]
Place = tuple[Collection, np.ndarray | None]  # (pairs, pose) of a candidate answer


FEATURES = (
    "n_pairs", "rejected_share", "residual", "fitness", "n_support", "conflict_share",
)  # fmt: skip
SIGNS = {"n_pairs": 1, "rejected_share": -1, "residual": -1, "fitness": 1, "n_support": 0,
         "conflict_share": -1}  # fmt: skip
"""The direction in which each feature may move the evidence (the fit is constrained to it; 0:
free — `n_support` counts pairs that are also in `n_pairs`, found by the pose, not the
clustering)."""
MODEL_MODULE = Path(__file__).with_name("confidence_model.py")
"""Where `benchmarks/calibrate_confidence.py --write` puts a refitted model."""


GAP_CAP = 4.0
"""The evidence gap to the best rival place counts up to this many logits."""
NO_RIVAL = -4.0
"""The evidence of a missing rival place; a weaker rival counts as this (a lone weak
hypothesis is not made sure by having no rival)."""


class ConfidenceModel(BaseModel):
    """Two logistic models: evidence = b + w . features; confidence = sigmoid(c0 + c1 *
    evidence + c2 * rival + c3 * gap), where r = max(evidence of the best other place,
    `NO_RIVAL`) (`NO_RIVAL` if none), rival = sigmoid(r) and gap = min(evidence - r, `GAP_CAP`).
    c1, c3 >= 0 and c2 <= 0: more evidence never lowers the confidence, a stronger rival never
    raises it."""

    model_config = ConfigDict(extra="forbid")

    evidence_bias: float
    evidence_weights: dict[str, float]
    confidence_bias: float
    confidence_evidence: float = Field(ge=0)
    confidence_rival: float = Field(le=0)
    confidence_gap: float = Field(0.0, ge=0)
    ranking_bias: float | None = None
    ranking_weights: dict[str, float] | None = Field(
        None,
        description="The logit that orders the hypotheses (`rank_by='evidence'`); None: the "
        "evidence.  Ranking asks which place of one answer is right, the confidence how often "
        "the best is: fitted apart (`benchmarks/calibrate_confidence.py`).",
    )
    min_confidence: float = Field(ge=0, le=1, description="Operating point for >= 99 % precision.")
    fitted_by: str = ""
    data: str = ""

    def evidence(self, features: dict[str, float]) -> float:
        return self.evidence_bias + sum(self.evidence_weights[k] * features[k] for k in FEATURES)

    def ranking(self, features: dict[str, float]) -> float:
        """The logit by which hypotheses are ranked (the evidence when none is fitted)."""
        if self.ranking_weights is None:
            return self.evidence(features)
        bias = self.ranking_bias or 0.0
        return bias + sum(self.ranking_weights[k] * features[k] for k in FEATURES)

    def confidence(self, evidence: float, rival: float | None) -> float:
        rival = NO_RIVAL if rival is None else max(rival, NO_RIVAL)
        rival_share, gap = _sigmoid(rival), min(evidence - rival, GAP_CAP)
        return _sigmoid(
            self.confidence_bias
            + self.confidence_evidence * evidence
            + self.confidence_rival * rival_share
            + self.confidence_gap * gap
        )


def _sigmoid(x: float) -> float:
    return 1.0 / (1.0 + math.exp(-max(min(x, 50.0), -50.0)))


@cache
def shipped_model() -> ConfidenceModel:
    """The confidence model shipped with the package (`confidence_model.SHIPPED`)."""
    return ConfidenceModel(**SHIPPED)


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
    min_confidence: float = Field(
        default_factory=lambda: shipped_model().min_confidence,
        ge=0,
        le=1,
        description="Confidence the best hypothesis needs to be 'localized' (default: the "
        "shipped model's operating point for >= 99 % precision on simulated attempts).",
    )
    margin: float = Field(
        0.5,
        ge=0,
        description="Dominance factor over every rival: residual (m) more than (1 + margin) x "
        "the best's plus residual_floor, or score / fitness at most 1 / (1 + margin) of it.",
    )
    residual_floor: float = Field(
        0.02, ge=0, description="Residual difference (m) below which two hypotheses tie."
    )
    rival_overlap: float = Field(
        0.5,
        ge=0,
        le=1,
        description="A hypothesis sharing at least this share of another's pairs is a variant "
        "of it, not a rival: in its confidence's evidence gap and when deciding dominance.",
    )
    distinct_rotation_deg: float = Field(
        10.0, gt=0, description="Hypotheses closer than this in rotation are the same place."
    )
    distinct_translation: float = Field(
        0.3, gt=0, description="Hypotheses closer than this (m) in translation are the same place."
    )


def same_place(
    candidate: Place, other: Place, config: DecisionConfig, anchor: np.ndarray | None = None
) -> bool:
    """Whether `candidate` repeats `other`: a subset of its pairs, or a pose close to its pose.

    Translations are compared where the local objects are: at `anchor` (a point of the local
    frame, their centroid), so that the answer does not depend on where the local frame's
    origin lies (far from the objects, a small rotation moves the origin a lot)."""
    pairs, pose = candidate
    if pairs and set(pairs) <= set(other[0]):
        return True
    if pose is None or other[1] is None:
        return False
    rotation, translation = pose_error(pose, other[1])
    if anchor is not None:
        point = np.append(np.asarray(anchor, dtype=float), 1.0)
        translation = float(np.linalg.norm((pose - other[1]) @ point))
    return rotation < config.distinct_rotation_deg and translation < config.distinct_translation


def local_anchor(local_xyz: np.ndarray) -> np.ndarray | None:
    """Where `same_place` compares translations: the centroid of the local objects (None for
    no objects)."""
    local_xyz = np.asarray(local_xyz, dtype=float).reshape(-1, 3)
    return local_xyz.mean(axis=0) if len(local_xyz) else None


def duplicates(
    hypotheses: Sequence[Hypothesis], config: DecisionConfig, anchor: np.ndarray | None
) -> int:
    """How many of `hypotheses` (ranked) have a pose at the same place (`same_place`, by pose
    alone) as a better-ranked one; the Localizer's answers have none."""
    posed = [h for h in hypotheses if h.pose is not None]
    return sum(
        any(same_place(((), h.pose), ((), other.pose), config, anchor) for other in posed[:i])
        for i, h in enumerate(posed)
    )


def distinct(
    places: Iterable[Place],
    top_k: int,
    config: DecisionConfig,
    anchor: np.ndarray | None = None,
) -> list[int]:
    """Indices of the first `top_k` places (in the given order) that repeat no earlier pick
    (`anchor`: see `same_place`).

    `places` is consumed lazily, so a generator computes poses only as far as needed.  Each
    place is tested against all picks at once (`same_place`'s pose test, compiled)."""
    chosen: list[int] = []
    if top_k < 1:
        return chosen
    pair_sets: list[set] = []
    poses = np.empty((min(top_k, 16), 4, 4))  # grown as needed: top_k may be huge
    posed = 0
    for i, (pairs, pose) in enumerate(places):
        if pairs:
            mine = set(pairs)
            if any(mine <= other for other in pair_sets):
                continue
        if pose is not None:
            pose = np.ascontiguousarray(pose, dtype=float)
            if _first_same_place(pose, poses, posed, config, anchor) is not None:
                continue
        chosen.append(i)
        if len(chosen) == top_k:
            break
        pair_sets.append(set(pairs))
        if pose is not None:
            if posed == len(poses):
                poses = np.concatenate([poses, np.empty_like(poses)])
            poses[posed] = pose
            posed += 1
    return chosen


def same_place_index(
    pose: np.ndarray, poses: np.ndarray, config: DecisionConfig, anchor: np.ndarray | None = None
) -> int | None:
    """The index of the first of `poses` (K, 4, 4) at the same place as `pose` by
    `same_place`'s pose test, or None (compiled: `_decision_fast.first_same_place`)."""
    pose = np.ascontiguousarray(pose, dtype=float)
    poses = np.ascontiguousarray(poses, dtype=float).reshape(-1, 4, 4)
    return _first_same_place(pose, poses, len(poses), config, anchor)


def _first_same_place(
    pose: np.ndarray, poses: np.ndarray, count: int, config: DecisionConfig, anchor
) -> int | None:
    found = first_same_place(
        pose, poses, count, _NO_ANCHOR if anchor is None else np.asarray(anchor, dtype=float),
        anchor is not None, config.distinct_rotation_deg, config.distinct_translation,
    )  # fmt: skip
    return None if found < 0 else int(found)


_NO_ANCHOR = np.zeros(3)


_INF = float("inf")
RESIDUAL_RANK = 4.0
"""Logit per metre of centre residual subtracted from the ranking logit (not in the
confidence): repeated objects give near-equal fitness, their centres still tell them apart."""
RANKINGS: dict[str, Callable[[Hypothesis], tuple | float]] = {
    "evidence": lambda h: (  # the ranking logit when `rank_places` set it, else the evidence
        _INF if h.evidence is None else -round(h.evidence - RESIDUAL_RANK * (h.residual or 0), 6),
        -h.score,
    ),
    "score": lambda h: -h.score,
    "residual": lambda h: (-len(h.pairs), _INF if h.residual is None else h.residual, -h.score),
    "fitness": lambda h: (-(h.fitness if h.fitness is not None else -1.0), -h.score),
}


MISSING_LOGIT = 1.0
"""Evidence logit taken from a hypothesis per map object that its pose puts well inside the
sensor's recent looks and nothing accounts for, beyond `coverage.GONE_SHARE` of those it
expects there (negative evidence, `semloc.coverage`): a look-alike place that predicts
absent objects loses against one that does not."""


def missing_penalty(h: Hypothesis) -> float:
    """The evidence logit a hypothesis loses to the objects it expected and nobody saw."""
    if h.n_missing is None or h.n_expected is None:
        return 0.0
    return MISSING_LOGIT * max(0.0, h.n_missing - GONE_SHARE * h.n_expected)


def rank(hypotheses: list[Hypothesis], rank_by: RankBy) -> list[Hypothesis]:
    """The hypotheses in the order of `rank_by`, renumbered 1, 2, ..."""
    ordered = sorted(hypotheses, key=RANKINGS[rank_by])
    for position, h in enumerate(ordered, 1):
        h.rank = position
    return ordered


def rank_places(
    hypotheses: list[Hypothesis],
    rank_by: RankBy,
    config: DecisionConfig,
    model: ConfidenceModel,
    anchor: np.ndarray | None = None,
) -> list[Hypothesis]:
    """Evidence of every hypothesis with features, the order of `rank_by`, same-place
    duplicates merged into the better-ranked one (poses after refinement), ranks 1, 2, ...
    and confidences against the remaining rivals."""
    for h in hypotheses:  # ranked by the ranking logit; `score_confidence` sets the evidence
        if h.features is not None:
            h.evidence = model.ranking(h.features) - missing_penalty(h)
    ordered = rank(hypotheses, rank_by)
    places = ((h.pairs, h.pose) for h in ordered)
    kept = [ordered[i] for i in distinct(places, len(ordered), config, anchor)]
    for position, h in enumerate(kept, 1):
        h.rank = position
    score_confidence(kept, model, config.rival_overlap)
    return kept


class Decision(NamedTuple):
    """A status and why (empty for `localized`)."""

    status: Status
    reason: str


def score_confidence(
    hypotheses: Sequence[Hypothesis],
    model: ConfidenceModel,
    rival_overlap: float = 0.5,
    twinned: Collection[Hypothesis] = (),
) -> None:
    """Set `evidence` (less the negative evidence, `missing_penalty`) and `confidence` of
    hypotheses that carry `features` (distinct places);
    each one's rival is the best evidence among the others that are real rivals of it
    (`is_rival`: sharing less than `rival_overlap` of the pairs; a variant that keeps most of
    its pairs and swaps one is the same answer, wrong in one object, not another place).
    Among `twinned` hypotheses (a place and its copies in the map, `semloc.twins`), one that
    the view tells apart from another (`told_apart`) is not that one's rival."""
    scored = [h for h in hypotheses if h.features is not None]
    twins = [h for h in scored if any(h is t for t in twinned)]
    for h in scored:
        h.evidence = model.evidence(h.features) - missing_penalty(h)
    for h in scored:
        others = [
            o.evidence for o in scored if o is not h and is_rival(h.pairs, o.pairs, rival_overlap)
            and not (_among(h, twins) and _among(o, twins) and told_apart(h, o))
        ]  # fmt: skip
        h.confidence = model.confidence(h.evidence, max(others) if others else None)


TWIN_APART = 2
"""Local objects a place must hold that its copy lacks to be told apart from it."""


def told_apart(place: Hypothesis, twin: Hypothesis) -> bool:
    """Whether the view tells `place` from its copy `twin`: `place` pairs at least
    `TWIN_APART` local objects that `twin` pairs with nothing, and `twin` none that `place`
    does not.  Where a copy lacks an object of the layout, a detection there is one of the
    place's: today's world adding an object of that label at that very spot of the copy is
    rare, while the generic evidence weighs a missing pair as any pair."""
    mine, theirs = {l for _, l in place.pairs}, {l for _, l in twin.pairs}
    return len(mine - theirs) >= TWIN_APART and not theirs - mine


def _among(h: Hypothesis, hypotheses: Sequence[Hypothesis]) -> bool:
    return any(h is o for o in hypotheses)


def decide(hypotheses: Sequence[Hypothesis], config: DecisionConfig, rank_by: RankBy) -> Decision:
    """The status of ranked hypotheses (best first) and its reason; see the module docstring."""
    if not any(len(h.pairs) >= 2 for h in hypotheses):  # (a baseline's pose may have fewer)
        return Decision("failed", "no association set with 2 or more pairs")
    best = hypotheses[0]
    if best.pose is None:
        return Decision("ambiguous", "the best hypothesis's pose is under-determined")
    if best.outside_prior:
        return Decision("ambiguous", OUTSIDE_PRIOR)
    if len(best.pairs) < config.min_pairs:
        return Decision(
            "ambiguous",
            f"too few pairs: the best hypothesis has {len(best.pairs)} agreeing pairs, "
            f"{config.min_pairs} needed",
        )
    if best.fitness is not None and best.fitness < config.min_fitness:
        return Decision(
            "ambiguous",
            f"low fitness: {best.fitness:.2f} of the local points land on the map, "
            f"{config.min_fitness:.2f} needed",
        )
    others = [h for h in hypotheses[1:] if not h.outside_prior]  # (a prior rules those out)
    if best.confidence is not None:
        return _by_confidence(best, others, config)
    rivals = [h for h in others if _different(best, h, config.rival_overlap)]
    for rival in rivals:
        if not _dominates(best, rival, rank_by, config):
            return Decision(
                "ambiguous", f"a rival place within the margin (rank {rival.rank}, {rank_by})"
            )
    return Decision("localized", "")


def _by_confidence(best: Hypothesis, others: Sequence[Hypothesis], d: DecisionConfig) -> Decision:
    assert best.confidence is not None
    if best.confidence >= d.min_confidence:
        # the confidence model is fitted on few attempts; a rival place whose centres fit
        # nearly as well (same pairs, residual within the margin) still makes it ambiguous
        rivals = [h for h in others if _different(best, h, d.rival_overlap)]
        close = [h for h in rivals if not _dominates(best, h, "residual", d)]
        if not close:
            return Decision("localized", "")
        return Decision(
            "ambiguous",
            f"a rival place within the margin: rank {close[0].rank} fits the centres nearly "
            f"as well ({len(close[0].pairs)} pairs, residual {close[0].residual or 0:.2f} m)",
        )
    rivals = [h for h in others if h.evidence is not None and best.evidence is not None
              and is_rival(best.pairs, h.pairs, d.rival_overlap)]  # fmt: skip
    close = [h for h in rivals if h.evidence >= best.evidence - RIVAL_LOGIT_GAP]
    if close:
        return Decision(
            "ambiguous",
            f"a rival place within the margin: rank {close[0].rank} has nearly the same evidence "
            f"(confidence {best.confidence:.2f} < {d.min_confidence:.2f})",
        )
    return Decision("ambiguous", f"low confidence: {best.confidence:.2f} < {d.min_confidence:.2f}")


PLACE_APART = 4.0
"""Sets whose map objects' centroids lie farther apart than this (m, a room's size) are in
different regions: perhaps copies of one place (the Localizer screens one set per
region beyond its best sets in a building)."""


def new_regions(
    centroids: np.ndarray, first: int, apart: float = PLACE_APART, most: int | None = None
) -> np.ndarray:
    """The rows after the `first` whose centroid lies farther than `apart` from those of the
    first rows and of every earlier row taken (in order): one set per region not covered; at
    most `most` of them (None: all)."""
    centroids = np.asarray(centroids, dtype=float).reshape(-1, 3)
    taken = np.empty_like(centroids)
    count = min(first, len(centroids))
    taken[:count] = centroids[:count]
    rows: list[int] = []
    for row in range(first, len(centroids)):
        if most is not None and len(rows) >= most:
            break
        if np.min(np.linalg.norm(taken[:count] - centroids[row], axis=1)) > apart:
            taken[count] = centroids[row]
            count += 1
            rows.append(row)
    return np.array(rows, dtype=np.int64)


SEARCH_CUT = "the search was cut"
"""The reason's start when places as well supported as the best were left out of the search."""


def as_well_supported(
    pairs: int, residual: float, best: tuple[int, float], d: DecisionConfig
) -> bool:
    """Whether a place of `pairs` pairs and centre `residual` is as well supported as the best
    (`best`: its pairs and residual), in the terms of the verdict's residual rule: as many
    pairs, and a residual the best does not beat by the margin (`_dominates`)."""
    best_pairs, best_residual = best
    return pairs >= best_pairs and residual <= (1.0 + d.margin) * best_residual + d.residual_floor


def cut_search(decision: Decision, cut: bool, pairs: int) -> Decision:
    """A search that had to leave out places as well supported as its best (`cut`: more sets
    or distinct places of `pairs` pairs than it keeps) cannot claim: the right place may be
    among those left out, and a decision that weighs only what was found cannot know it.  The
    answer is `ambiguous` and says so first (a `failed` answer stays as it is)."""
    if not cut or decision.status == "failed":
        return decision
    why = (
        f"{SEARCH_CUT}: places as well supported as the best ({pairs} pairs) were left out of "
        "the hypotheses, and the right one may be among them"
    )
    return Decision("ambiguous", why if not decision.reason else f"{why}; {decision.reason}")


RIVAL_LOGIT_GAP = 2.0
"""A rival whose evidence logit is within this of the best's is named as the reason; the
verdict's margin: a place outside the prior beats the best inside only beyond it."""


def prior_first(ranked: list[Hypothesis]) -> list[Hypothesis]:
    """With a prior, among places whose evidence cannot be told apart the prior decides: when
    the best place lies outside the prior but the best inside has evidence within
    `RIVAL_LOGIT_GAP` of it, the places inside come first (ranks renumbered).  An outside place
    better beyond that margin stays first, and forbids a claim."""
    inside = [h for h in ranked if not h.outside_prior]
    if not ranked or not ranked[0].outside_prior or not inside:
        return ranked
    best, candidate = ranked[0].evidence, inside[0].evidence
    if best is None or candidate is None or best - candidate > RIVAL_LOGIT_GAP:
        return ranked
    ordered = inside + [h for h in ranked if h.outside_prior]
    for position, h in enumerate(ordered, 1):
        h.rank = position
    return ordered


def _dominates(best: Hypothesis, rival: Hypothesis, rank_by: RankBy, d: DecisionConfig) -> bool:
    """Whether `best` beats `rival` clearly, in the terms of the chosen ranking."""
    if rank_by == "score":
        return best.score >= (1.0 + d.margin) * rival.score
    if rank_by == "fitness":
        return (best.fitness or 0.0) >= (1.0 + d.margin) * (rival.fitness or 0.0)
    if len(rival.pairs) < len(best.pairs) or rival.residual is None:
        return True
    return rival.residual > (1.0 + d.margin) * (best.residual or 0.0) + d.residual_floor


def is_rival(pairs: Collection, other: Collection, max_overlap: float) -> bool:
    """Whether the hypothesis with pairs `other` is a rival of the one with `pairs`: it shares
    less than `max_overlap` of `pairs`.  One that shares more is a variant of the same answer
    (most of its evidence, one object matched differently), not another place."""
    return len(set(pairs) & set(other)) < max_overlap * len(pairs)


def _different(best: Hypothesis, other: Hypothesis, max_overlap: float) -> bool:
    """Whether `other` is a rival of `best` in the dominance rules: each is a rival of the
    other (they share less than `max_overlap` of the smaller one's pairs)."""
    return is_rival(best.pairs, other.pairs, max_overlap) and is_rival(
        other.pairs, best.pairs, max_overlap
    )


def verdict_refinements(
    hypotheses: Sequence[Hypothesis],
    pending: Sequence[Hypothesis],
    config: DecisionConfig,
    model: ConfidenceModel,
) -> list[Hypothesis]:
    """Those of the `pending` hypotheses (not yet refined: their features are bounds) whose
    refinement could change the verdict that `rank_places(hypotheses, "evidence", ...)` and
    `decide` reach: which place is best and the status.  The best place first, alone.

    Robust ICP only raises the fitness (to at most 1) and adds negative evidence (`missing`);
    the centre residual may fall to 0.  So a pending hypothesis cannot change the verdict
    when (1) even so it ranks below the best; (2) the best's confidence stays on the same
    side of `min_confidence` whether its rivals (each pending one at its bound) are as strong
    as they can be or absent; (3) when the best could be claimed, no hypothesis could stop
    the claim by the dominance rule (a rival of the best with as many pairs whose residual is
    not clearly larger, or pending): otherwise each pending rival of the best is refined, as
    its residual counts there and its pose decides which same-place duplicates are listed.
    (Copies of the best, `semloc.twins`, are weighed against refined rivals: the Localizer
    refines all pending hypotheses before it weighs them.)"""
    if not hypotheses:
        return []
    keys = [_ranking_key(h, model) for h in hypotheses]
    best = hypotheses[keys.index(min(keys))]  # (`rank_places`'s first: a stable sort's)
    if _among(best, pending):
        return [best]
    if best.features is None:
        return []
    key = model.ranking(best.features) - missing_penalty(best)
    key -= RESIDUAL_RANK * (best.residual or 0.0) + _KEY_EPS
    evidence, overlap = model.evidence(best.features) - missing_penalty(best), config.rival_overlap
    strongest = max(
        (_evidence_bound(o, pending, model) for o in hypotheses
         if o is not best and o.features is not None and is_rival(best.pairs, o.pairs, overlap)),
        default=None,
    )  # fmt: skip
    claimable = model.confidence(evidence, None) >= config.min_confidence
    unsure = claimable != (model.confidence(evidence, strongest) >= config.min_confidence)
    contested = claimable and any(
        o is not best and _different(best, o, overlap) and len(o.pairs) >= len(best.pairs)
        and (_among(o, pending) or not _dominates(best, o, "residual", config))
        for o in hypotheses
    )  # fmt: skip
    return [
        h for h in pending
        if h.features is not None and (
            model.ranking(_optimistic(h.features)) >= key
            or (unsure and is_rival(best.pairs, h.pairs, overlap))
            or (contested and _different(best, h, overlap))
        )
    ]  # fmt: skip


def _ranking_key(h: Hypothesis, model: ConfidenceModel) -> tuple[float, float]:
    """`RANKINGS["evidence"]` of `h` as `rank_places` sets its evidence (the ranking logit)."""
    if h.features is None:
        return _INF, -h.score
    logit = model.ranking(h.features) - missing_penalty(h)
    return -round(logit - RESIDUAL_RANK * (h.residual or 0), 6), -h.score


def _evidence_bound(h: Hypothesis, pending: Sequence[Hypothesis], model: ConfidenceModel) -> float:
    """The evidence of `h`, or the most it can have after refinement when it is pending."""
    assert h.features is not None
    if _among(h, pending):
        return model.evidence(_optimistic(h.features))
    return model.evidence(h.features) - missing_penalty(h)


_KEY_EPS = 1e-6
"""Ranking keys are compared rounded (`RANKINGS`): a bound this close counts as a tie."""


def _optimistic(features: dict[str, float]) -> dict[str, float]:
    """The features at their best after refinement: every point fits, the centres exactly."""
    return {**features, "fitness": 1.0, "residual": 0.0}
