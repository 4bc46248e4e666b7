"""Map-to-map alignment: where a second object map B lies in a first map A.

A second mapping session or a second robot brings a whole object map, every object at once.
The Localizer is sized for a few new objects per update: the candidate pairs of one update grow
with B's size and the compatibility edges among them with its square (see "Many objects at
once" in `clustering.py`).  `align` bounds that work and keeps the paper's algorithm where it
is cheap:

1. **Seeds.**  A small B (at most `whole_below` objects) is one Localizer update with every
   object (the paper's algorithm), its `whole_places` best distinct places the seeds.  A
   larger B is localized in up to `views` seed views: the first `rare_views` are centred on
   B's most distinctive objects (the fewest candidates in A: a fridge anchors a view in the
   kitchen, where a chair fits every classroom), at least 3 m apart, the others spread over
   B by farthest-point sampling (where A overlaps only part of B, views centred on rare
   objects alone may all fall outside it: an object A lacks has one candidate fewer, so it
   looks rarer); each holds the `view_size` objects of B nearest to its centre and is one
   Localizer update against A (clustering, verification, pose recovery): a local map like a
   robot's, the case the Localizer is made for.
2. **Growth by guided matching.**  Every distinct place of the seeds (the `per_view` best of
   each view) places all of B in A's frame; each object of B is paired with the nearest object
   of A it may be (the Localizer's candidates: labels, label map, descriptor gate), mutual
   nearest within a radius, and the pose is refitted on the pairs (closed form, robust:
   `refits` rounds weighted by each pair's distance); one pass per radius of `match_radii`,
   wide to narrow, or the narrowest alone, whichever scores more (step 3): a wide pass
   reaches B's far objects from a seed a few degrees off, and pairs close objects of one
   kind crosswise from a seed that is right.  In maps of repeated rooms a view fits several
   places and the right one is rarely a view's best, but grown over B it fits the most.
3. **Score.**  A grown place scores its agreeing pairs: each pair counts 1 - (d / fit_radius)²
   by the distance d of its centres, nothing beyond.  Not the number of pairs: a place
   shifted into a twin room pairs B's objects with twins a few decimetres off, and it pairs
   more of them than the right place where A's session saw less of B than the twin room holds.
   When B is *precise* (a place pairs `precise_pairs` objects, and a quarter of B's, with a
   median distance below `precise_below`: the same objects measured as precisely as A's), every place is scored at
   `precise_fit_radius`: a similar room's objects a decimetre or two off no longer agree.
4. **Decision.**  A small B that is not precise gets the Localizer's answer as it is (status,
   places, poses, confidence: with noisy centres its point evidence ranks places better than
   their centres do), each place's pairs completed by guided matching under its pose (step
   2's narrowest radius).  Otherwise the grown places are ranked by their score (then centre
   residual) and merged when they are the same place; each keeps the evidence features of
   the view that seeded it with its score as its pairs and its grown residual, the shipped
   confidence model scores them against each other and `decision.decide` gives the status,
   as for a localization; `localized` further needs the best place to score (1 + margin)
   times as much as any other place.  Where two places fit B equally (identical rooms) the
   answer is `ambiguous`.  Views stop early once the best place scores `settled_pairs`,
   (1 + margin)² times as much as any other, and `confirmations` views have found it.

Work: `views` localizations of `view_size` objects, then per seed place one pass over B's
candidate pairs per radius and one more at the narrowest: linear in B's size (and in the
number of same-label objects of A).
`pose_information` estimates the information matrix of the relative pose from the aligned
pairs (a pose-graph edge).  Pure computation on numpy arrays.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterable
from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from semloc._alignment_fast import guided_passes, mutual_nearest
from semloc.association import CandidateIndex, label_report
from semloc.decision import (
    decide,
    distinct,
    local_anchor,
    same_place_index,
    score_confidence,
    shipped_model,
)
from semloc.localizer import Localizer, LocalizerConfig
from semloc.maps import ObjectMap
from semloc.pose import z_up_rotations
from semloc.results import Hypothesis, Result, Step
from semloc.transforms import centre_residual
from semloc.window import WindowConfig


class AlignmentConfig(BaseModel):
    """How a whole second map is aligned (see the module docstring)."""

    model_config = ConfigDict(extra="forbid")

    whole_below: int = Field(
        24, ge=2, description="B with at most this many objects is one Localizer update."
    )
    views: int = Field(8, ge=1, description="Seed views of a larger B.")
    rare_views: int | None = Field(
        2,
        ge=0,
        description="How many views are centred on B's rarest objects; the others spread over "
        "B (farthest points) so that some fall where A overlaps it (None: all on rare ones).",
    )
    view_size: int = Field(10, ge=3, description="Objects of B per seed view.")
    per_view: int = Field(10, ge=1, description="Distinct places of each view that are tried.")
    settled_pairs: int = Field(
        6,
        ge=3,
        description="Views stop once the best grown place scores this many agreeing pairs, (1 + "
        "margin)² times as much as any other place, and `confirmations` views found it.",
    )
    fit_radius: float = Field(
        0.3,
        gt=0,
        description="A grown place's score: each pair counts 1 - (d / fit_radius)² (d: the "
        "distance (m) of its centres under the place's pose), nothing beyond.",
    )
    precise_below: float = Field(
        0.05,
        ge=0,
        description="B counts as precise when one of its places pairs at least "
        "`precise_pairs` objects with a median centre distance (m) below this: the same "
        "objects measured twice (0: never).",
    )
    precise_pairs: int = Field(
        5,
        ge=3,
        description="See `precise_below`; at least a quarter of B's objects too (among many "
        "places of a large noisy B a few pairs can meet closely by chance).",
    )
    precise_fit_radius: float = Field(
        0.1,
        gt=0,
        description="The score's radius (in place of `fit_radius`) when B is precise: a twin "
        "room's similar objects a decimetre or two off no longer count as agreeing.",
    )
    whole_places: int = Field(
        30,
        ge=1,
        description="Distinct places of B whole that are grown (a twin room that pairs more "
        "of a small B can rank the right place below the Localizer's usual ten).",
    )
    confirmations: int = Field(
        2,
        ge=1,
        description="Views stop early only once this many views have found the best place.",
    )
    refits: int = Field(
        3, ge=1, description="Rounds of the robust refit after each guided-matching pass."
    )
    match_radii: tuple[float, ...] = Field(
        (2.0, 1.0, 0.6),
        min_length=1,
        description="Guided matching, one pass each: the farthest (m) a pair's centres may lie "
        "apart (wide first: far from its view a seed's small rotation error moves B's objects "
        "by metres).",
    )


def align(
    a: ObjectMap,
    b: ObjectMap,
    config: LocalizerConfig | None = None,
    alignment: AlignmentConfig | None = None,
    **overrides: Any,
) -> Result:
    """Where B lies in A: a Result whose pose is T_A_B (p_A = R @ p_B + t), its pairs
    (A id, B id) the correspondences, its status / confidence / reason as for `localize`."""
    if not isinstance(a, ObjectMap) or not isinstance(b, ObjectMap):
        raise TypeError("align needs two ObjectMaps")
    aligner = _Aligner(a, b, config, alignment or AlignmentConfig(), overrides)
    result = aligner.run()
    result.read_labels = lambda: label_report(aligner.index, b)  # B's labels read in A's
    return result


class _Aligner:
    """One alignment of B in A: seeds, growth, decision."""

    def __init__(self, a, b, config, alignment: AlignmentConfig, overrides: dict) -> None:
        probe = Localizer(a, config, local_up=b.up, **overrides)
        self.config, self.prior = probe.config, a  # each view's Localizer describes `a` itself
        self.a, self.b, self.alignment = probe.global_map, b, alignment
        index = CandidateIndex(self.a, self.config.association, probe.descriptor_gate)
        self.index = index
        candidates = [index.candidates(obj) for obj in b]
        self.cand_b = np.repeat(np.arange(len(b)), [len(c) for c in candidates])
        self.cand_a = np.concatenate([*candidates, np.zeros(0, dtype=int)]).astype(int)
        self.b_xyz, self.a_xyz = b.positions, self.a.positions
        self.a_row = {str(i): k for k, i in enumerate(self.a.ids)}
        self.b_row = {str(i): k for k, i in enumerate(b.ids)}
        # the guided matching works in the z-up frames (4-DoF: a yaw there), on the centres
        # of every candidate pair gathered once
        self.yaw_only = b.up is not None and self.a.up is not None
        self.z_b, self.z_a = z_up_rotations(b.up, self.a.up) if self.yaw_only else (_I3, _I3)
        self.b_z = np.ascontiguousarray(self.b_xyz @ self.z_b.T)
        self.a_z = np.ascontiguousarray(self.a_xyz @ self.z_a.T)
        self.cand_b_z, self.cand_a_z = self.b_z[self.cand_b], self.a_z[self.cand_a]

    def run(self) -> Result:
        start = time.perf_counter()
        timing = {"association": 0.0, "clustering": 0.0, "pose": 0.0, "growth": 0.0}
        small = len(self.b) <= self.alignment.whole_below
        if small:
            own = self._localized(np.arange(len(self.b)), timing, self.alignment.whole_places)
            seeds: Iterable[list[Hypothesis]] = [self._seeds(own, self.alignment.whole_places)]
        else:
            seeds = (self._seeds_of(view, timing) for view in self._views())
        grown, tried = self._grown_places(seeds, timing)
        precise = self._precise(grown)
        if small and not precise:
            return self._localizers_answer(own)
        hypotheses = self._decided_places(grown, precise)
        status, reason = decide(hypotheses, self.config.decision, "residual")
        if status == "localized":
            status, reason = self._clearly_best(hypotheses)
        if not hypotheses:
            reason = "no view of the second map found a consistent set of 2 or more pairs"
        timing["total"] = (time.perf_counter() - start) * 1e3
        step = Step(step=0, n_local=len(self.b), n_sets=tried, ms=timing["total"],
                    top_scores=[h.score for h in hypotheses][:10], status=status)  # fmt: skip
        return Result.of(status, hypotheses[: self.config.top_k], [step], timing, reason)

    def _grown_places(
        self, seeds: Iterable[list[Hypothesis]], timing: dict[str, float]
    ) -> tuple[list[Hypothesis], int]:
        """The distinct places grown from each view's seeds, view after view until settled,
        and how many seeds were grown."""
        grown: list[Hypothesis] = []
        votes: list[set[int]] = []  # the views that found each grown place
        tried = 0
        for number, view_seeds in enumerate(seeds):
            tick = time.perf_counter()
            for seed in view_seeds:
                known = self._place_of(seed.pose, grown)
                if known is None:
                    tried += 1
                    place = self._grown(seed)
                    known = None if place is None else self._place_of(place.pose, grown)
                    if place is not None and known is None:
                        grown.append(place)
                        votes.append(set())
                        known = len(grown) - 1
                if known is not None:
                    votes[known].add(number)
            timing["growth"] += (time.perf_counter() - tick) * 1e3
            if self._settled(grown, votes):
                break
        return grown, tried

    def _localized(
        self, view: np.ndarray, timing: dict[str, float], places: int | None = None
    ) -> Result:
        """One Localizer update of the objects `view` of B against A (`places`: how many
        distinct places it reports, from four times as many screened sets)."""
        config = self.config.model_copy(update={"window": WindowConfig.unbounded()})
        if places is not None and places > config.top_k:
            screened = max(config.screened_sets, 4 * places)
            config = config.model_copy(update={"top_k": places, "screened_sets": screened})
        localizer = Localizer(self.prior, config, local_up=self.b.up)
        result = localizer.update([self.b[int(i)] for i in view])
        assert result is not None
        for stage in ("association", "clustering", "pose"):
            timing[stage] += result.timing_ms.get(stage, 0.0)
        return result

    def _seeds(self, result: Result, places: int | None = None) -> list[Hypothesis]:
        """The distinct places (with a pose) of one view's localization, best first."""
        places = self.alignment.per_view if places is None else places
        return [h for h in result.hypotheses[:places] if h.pose is not None]

    def _seeds_of(self, view: np.ndarray, timing: dict[str, float]) -> list[Hypothesis]:
        return self._seeds(self._localized(view, timing))

    def _precise(self, places: list[Hypothesis]) -> bool:
        """Whether one of `places` pairs `precise_pairs` objects or more (and a quarter of B's)
        with a median centre distance below `precise_below`: B holds the same objects as A
        measured as precisely, and a place whose pairs are a decimetre or two off is a twin,
        not a match."""
        enough = max(self.alignment.precise_pairs, math.ceil(len(self.b) / 4))
        for h in places:
            if h.pose is None or len(h.pairs) < enough:
                continue
            if (
                np.median(self._distances(h.pose, self._rows(h.pairs)))
                < self.alignment.precise_below
            ):
                return True
        return False

    def _localizers_answer(self, result: Result) -> Result:
        """A small B's answer as one Localizer update of every object (status, its
        `top_k` places, poses, confidence), each place's pairs completed by guided matching
        under its pose."""
        tick = time.perf_counter()
        hypotheses = result.hypotheses[: self.config.top_k]
        for h in hypotheses:
            if h.pose is not None:
                h.pairs = self._completed(h.pairs, h.pose)
        timing = {**result.timing_ms, "growth": (time.perf_counter() - tick) * 1e3}
        return Result.of(result.status, hypotheses, result.steps, timing, result.reason,
                         result.explain)  # fmt: skip

    def _completed(self, pairs: list[tuple[str, str]], pose: np.ndarray) -> list[tuple[str, str]]:
        """`pairs` and the guided matches under `pose` (narrowest radius) of objects they miss."""
        a_done, b_done = {g for g, _ in pairs}, {l for _, l in pairs}
        found = self._matches(pose, self.alignment.match_radii[-1])
        extra = [(str(self.a.ids[g]), str(self.b.ids[l])) for g, l in found]
        return [*pairs, *((g, l) for g, l in extra if g not in a_done and l not in b_done)]

    def _views(self) -> list[np.ndarray]:
        """B's seed views (see the module docstring)."""
        rarity = np.bincount(self.cand_b, minlength=len(self.b))
        rarity = np.where(rarity == 0, np.iinfo(np.int64).max, rarity)  # no candidate: last
        return seed_views(self.b_xyz, self.alignment.views, self.alignment.view_size, rarity,
                          rare=self.alignment.rare_views)  # fmt: skip

    def _place_of(self, pose: np.ndarray, grown: list[Hypothesis]) -> int | None:
        """The index of the first grown place at `pose` (`same_place`'s pose test, at B's
        centroid), or None."""
        poses = np.array([h.pose for h in grown]).reshape(-1, 4, 4)
        return same_place_index(pose, poses, self.config.decision, local_anchor(self.b_xyz))

    def _settled(self, grown: list[Hypothesis], votes: list[set[int]]) -> bool:
        """Whether more views are not needed: the best grown place scores at least
        `settled_pairs`, (1 + margin)² times as much as any other place, and was found by
        `confirmations` views (a view centred where A lacks B's objects finds only the
        twins of a repeated room)."""
        if not grown:
            return False
        order = sorted(range(len(grown)), key=lambda i: -grown[i].score)
        best, factor = grown[order[0]].score, (1.0 + self.config.decision.margin) ** 2
        return (
            best >= self.alignment.settled_pairs
            and len(votes[order[0]]) >= self.alignment.confirmations
            and all(best >= factor * grown[i].score for i in order[1:])
        )

    def _clearly_best(self, hypotheses: list[Hypothesis]) -> tuple[str, str]:
        """`localized` only when no other place scores nearly as many agreeing pairs of B: in
        a building of identical rooms a shifted pose pairs most of B too, and the confidence
        model, fitted on a few objects, has not seen such rivals."""
        best, factor = hypotheses[0], 1.0 + self.config.decision.margin
        for rival in hypotheses[1:]:
            if best.score < factor * rival.score:
                return "ambiguous", (
                    f"a rival place fits nearly as many objects: rank {rival.rank} scores "
                    f"{rival.score:.1f} agreeing pairs ({len(rival.pairs)} pairs) against "
                    f"{best.score:.1f} ({len(best.pairs)})"
                )
        return "localized", ""

    def _grown(self, seed: Hypothesis) -> Hypothesis | None:
        """The seed's place grown over all of B by guided matching; None if it has < 2 pairs.

        Grown twice, by passes at every radius of `match_radii` (wide to narrow) and by the
        narrowest alone, the one that scores more kept: from a seed that is already right, a
        wide pass among close objects of one kind (a row of chairs) pairs them crosswise and
        can turn the pose by tens of degrees; from a seed a few degrees off, only the wide
        passes reach B's far objects."""
        radii = self.alignment.match_radii
        schedules = [radii] if len(radii) == 1 else [radii, radii[-1:]]
        grown = [self._passes(seed.pose, schedule) for schedule in schedules]
        pose, pairs, score = max(grown, key=lambda place: place[2])
        if len(pairs) < 2:
            return None
        residual = centre_residual(pose, self.b_xyz[pairs[:, 1]], self.a_xyz[pairs[:, 0]])
        features = None
        if seed.features is not None:  # the agreeing pairs count as the pairs
            features = {**seed.features, "n_pairs": score, "residual": residual, "n_support": 0.0}
        return Hypothesis(
            rank=0,
            score=score,
            pairs=[(str(self.a.ids[g]), str(self.b.ids[l])) for g, l in pairs],
            pose=pose,
            fitness=None,  # the seed view's point fitness says little about the grown place
            residual=residual,
            method=f"seed view ({seed.method}) + guided matching",
            features=features,
        )

    def _passes(
        self, pose: np.ndarray, radii: tuple[float, ...]
    ) -> tuple[np.ndarray, np.ndarray, float]:
        """Guided matching from `pose`, one pass per radius, each followed by the robust refit
        (`refits` rounds of the closed form, each pair weighted (1 - (d / radius)²)² by its
        distance d under the previous pose: one wrong pair among ten noisy ones turns a plain
        fit by degrees): the pose, its pairs and their score (pairs: < 2 when the first pass
        finds fewer; an under-determined refit keeps the last pose).  Compiled:
        `_alignment_fast.guided_passes`."""
        R, t, pairs, score = guided_passes(
            *self._to_z(pose), np.asarray(radii, dtype=float), self.alignment.refits,
            self.yaw_only, self.alignment.fit_radius, self.cand_a, self.cand_b, self.cand_a_z,
            self.cand_b_z, self.a_z, self.b_z,
        )  # fmt: skip
        return self._from_z(R, t), pairs, float(score)

    def _to_z(self, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """`pose` (B to A) between the z-up frames: (R, t)."""
        R = self.z_a @ pose[:3, :3] @ self.z_b.T
        return np.ascontiguousarray(R), self.z_a @ pose[:3, 3]

    def _from_z(self, R: np.ndarray, t: np.ndarray) -> np.ndarray:
        """The 4x4 pose (B to A) of (R, t) between the z-up frames."""
        pose = np.eye(4)
        pose[:3, :3], pose[:3, 3] = self.z_a.T @ R @ self.z_b, self.z_a.T @ t
        return pose

    def _score(self, pose: np.ndarray, pairs: np.ndarray, radius: float | None = None) -> float:
        """The agreeing pairs: each pair counts 1 - (d / radius)², nothing beyond (d: the
        distance of its centres under `pose`; radius: `fit_radius` unless given).  A place of
        a repeated room pairs B's objects with twins a few decimetres off, the right place
        with the same objects: a count of pairs alone prefers the twin room when it holds
        more of B's objects than A's session saw."""
        radius = self.alignment.fit_radius if radius is None else radius
        distance = self._distances(pose, pairs)
        return float(np.sum(np.clip(1.0 - (distance / radius) ** 2, 0.0, None)))

    def _distances(self, pose: np.ndarray, pairs: np.ndarray) -> np.ndarray:
        """The distance of each pair's centres (rows: A index, B index) under `pose`."""
        moved = self.b_xyz[pairs[:, 1]] @ pose[:3, :3].T + pose[:3, 3]
        return np.linalg.norm(moved - self.a_xyz[pairs[:, 0]], axis=1)

    def _rows(self, pairs: list[tuple[str, str]]) -> np.ndarray:
        """(A index, B index) rows of (A id, B id) pairs."""
        rows = [(self.a_row[g], self.b_row[l]) for g, l in pairs]
        return np.array(rows, dtype=int).reshape(-1, 2)

    def _matches(self, pose: np.ndarray, radius: float) -> np.ndarray:
        """(A index, B index) pairs under `pose`, ascending: each object of B with the nearest
        object of A it may be within `radius`, one to one: a pair is kept when it is the
        closest of both its objects (mutual nearest candidates; compiled)."""
        return mutual_nearest(
            *self._to_z(pose), radius, self.cand_a, self.cand_b, self.cand_a_z, self.cand_b_z,
            len(self.a_z), len(self.b_z),
        )  # fmt: skip

    def _decided_places(self, grown: list[Hypothesis], precise: bool) -> list[Hypothesis]:
        """Distinct places, the highest score first (then the smaller residual), ranked 1, 2,
        ... and scored by the confidence model against each other.  When B is `precise`,
        every place is scored again at `precise_fit_radius`."""
        if precise:
            for h in grown:
                h.score = self._score(
                    h.pose, self._rows(h.pairs), self.alignment.precise_fit_radius
                )
                if h.features is not None:
                    h.features = {**h.features, "n_pairs": h.score}
        ordered = sorted(grown, key=lambda h: (-h.score, h.residual or 0.0))
        anchor = local_anchor(self.b_xyz)
        places = ((h.pairs, h.pose) for h in ordered)
        kept = [ordered[i] for i in distinct(places, len(ordered), self.config.decision, anchor)]
        for position, h in enumerate(kept, 1):
            h.rank = position
        score_confidence(kept, shipped_model(), self.config.decision.rival_overlap)
        return kept


def place_scores(
    a: ObjectMap,
    b: ObjectMap,
    poses: list[np.ndarray],
    config: LocalizerConfig | None = None,
    alignment: AlignmentConfig | None = None,
) -> list[float]:
    """How well B fits A at each pose (T_A_B): B grown from the pose by guided matching as
    `align` grows its seeds, and its agreeing pairs scored at `fit_radius` (0 when it pairs
    fewer than 2 objects).  E.g. whether a wrong place fits B as well as the true one."""
    aligner = _Aligner(a, b, config, alignment or AlignmentConfig(), {})
    scores = []
    for pose in poses:
        seed = Hypothesis(rank=0, score=0.0, pairs=[], pose=np.asarray(pose, float), method="")
        place = aligner._grown(seed)
        scores.append(0.0 if place is None else place.score)
    return scores


_I3 = np.eye(3)
_I3.flags.writeable = False


def seed_views(
    xyz: np.ndarray,
    views: int,
    size: int,
    rarity: np.ndarray | None = None,
    spacing: float = 3.0,
    rare: int | None = None,
) -> list[np.ndarray]:
    """`views` neighbourhoods of the points `xyz` (indices), each the `size` points nearest to
    its centre.  Centres are the rarest points first (`rarity`: e.g. how many map objects each
    may be; a rare object anchors a view in a distinctive place), at least `spacing` apart, at
    most `rare` of them (None: as many as there are), then farthest-point sampling for the
    rest."""
    xyz = np.asarray(xyz, dtype=float).reshape(-1, 3)
    if len(xyz) == 0:
        return []
    rarity = np.zeros(len(xyz)) if rarity is None else np.asarray(rarity, dtype=float)
    centres: list[int] = []
    nearest = np.full(len(xyz), np.inf)
    for i in np.lexsort((np.arange(len(xyz)), rarity)):  # rarest first, stable
        if len(centres) == min(views if rare is None else rare, len(xyz)):
            break
        if nearest[i] >= spacing:
            centres.append(int(i))
            nearest = np.minimum(nearest, np.linalg.norm(xyz - xyz[i], axis=1))
    while len(centres) < min(views, len(xyz)):
        centres.append(int(np.argmax(nearest)))
        nearest = np.minimum(nearest, np.linalg.norm(xyz - xyz[centres[-1]], axis=1))
    size = min(size, len(xyz))
    return [
        np.sort(np.argsort(np.linalg.norm(xyz - xyz[c], axis=1), kind="stable")[:size])
        for c in centres
    ]


def pose_information(
    pose: np.ndarray, local_xyz: np.ndarray, global_xyz: np.ndarray, floor: float = 0.01
) -> np.ndarray:
    """The 6x6 information matrix of `pose` (T_global_local) from its aligned pairs, in the
    order (x, y, z, rotation about x, y, z) of a right perturbation exp(δ) of the pose: the
    Gauss-Newton normal matrix J^T J / σ² of the centre residuals, σ² their mean squared
    residual per axis (at least `floor` m, so that a perfect fit is not infinitely sure)."""
    R, t = pose[:3, :3], pose[:3, 3]
    local_xyz = np.asarray(local_xyz, dtype=float).reshape(-1, 3)
    global_xyz = np.asarray(global_xyz, dtype=float).reshape(-1, 3)
    residual = local_xyz @ R.T + t - global_xyz
    sigma2 = max(float(np.mean(residual**2)), floor**2)
    information = np.zeros((6, 6))
    for p in local_xyz:
        # d(R (p + δt + δθ × p)) = R δt - R [p]x δθ
        J = np.hstack([R, -R @ _skew(p)])
        information += J.T @ J
    return information / sigma2


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
