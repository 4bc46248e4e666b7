"""The search: the paper's method on the window's objects, from candidates to a verdict.

A `Search` grows association sets (`semloc.clustering`) from the local objects it is given,
one update at a time, and answers from them: each screened set is verified first
(`verification.consensus`: the pairs that disagree with the pose the others agree on are
rejected); only the chosen hypotheses get a pose recovery (closed form, or a global search
where the centres leave the rotation free), after which their evidence is measured, they are
ranked by it, same-place duplicates are merged and a calibrated confidence is attached.
Robust ICP refines the best and only those of the `refine_top` first whose refinement could
change the verdict (`decision.verdict_refinements`); the others keep their closed-form pose,
marked `refined: false`, and are refined on demand (`Hypothesis.refine`).

Streaming: the poses of the last answer are kept per association set (keyed by its pairs and
whether it was refined).  A set that is unchanged at the next answer reuses its estimate; a set
that grew is recovered warm-started from the pose of its largest kept subset; a re-detected
local object drops the kept poses that used it.

Look-alike rooms: before a best place is claimed, its copies in the map (`semloc.twins`) are
weighed as hypotheses, listed by the sets or not (an old map can make the right copy's sets
lose to another's); a copy the view does not tell apart (`decision.told_apart`) keeps the
answer `ambiguous`.

A position prior gates the candidates of each local object and marks the hypotheses whose pose
lies outside it, which cannot be `localized`.  In a large map, place retrieval
(`semloc.places`) narrows each object's candidates to the places that can hold the window.

A search is grown once per window: when the window changes without it (objects retired, a
tracked claim's updates, a new prior) it is `stale`, and the Localizer starts a `renewed` one
on the whole window.
"""

from __future__ import annotations

import numpy as np

from semloc.clustering import HierarchicalClustering, MergeCriterion, SetPairs
from semloc.decision import (
    Decision,
    as_well_supported,
    cut_search,
    decide,
    distinct,
    local_anchor,
    missing_penalty,
    new_regions,
    prior_first,
    rank_places,
    same_place,
    score_confidence,
    shipped_model,
    verdict_refinements,
)
from semloc.map_context import MapContext
from semloc.maps import SemanticObject
from semloc.pose import PoseEstimate, PoseRecovery, cached_cloud, recover_pose
from semloc.priors import OUTSIDE_PRIOR, Prior
from semloc.results import Hypothesis, Status
from semloc.semantics import pair_weight
from semloc.sightings import Sightings
from semloc.tracking import check, recent_contradiction
from semloc.transforms import centre_residual
from semloc.twins import MIN_TWIN_PAIRS, twin_pairs
from semloc.verification import Evidence, MapSupport, Verified, verify_sets

NEWEST_CONTRADICT = "contradicted by the newest objects"
"""The reason of a search's answer whose best place the latest updates' objects contradict."""
STALE = "stale evidence"
"""The reason (its start) of a search's answer whose best place was not seen of late
(`tracking.stale_m`)."""

_PoseKey = tuple[bool, frozenset[tuple[int, int]]]  # (refined, pairs)


class Search:
    """The association sets of the objects given so far, and the answer they give."""

    def __init__(
        self,
        context: MapContext,
        sightings: Sightings,
        prior: Prior | None,
        local_up: np.ndarray | None,
        retrieved: dict[str, np.ndarray] | None = None,
    ) -> None:
        self.context, self.sightings, self.config = context, sightings, context.config
        self.prior, self.local_up = prior, local_up
        global_map, config = context.map, context.config
        self.stale = False  # the window changed without the search seeing it
        self.cut = (False, 0)  # the last answer left out places as good as its best; pairs
        self.retrieved = retrieved if retrieved is not None else {}  # local id -> candidates
        self.clustering = HierarchicalClustering(
            global_map.positions,
            list(global_map.ids),
            config.clustering,
            encoded_ids=global_map.encoded_ids,
            sweep_order=global_map.sweep_order,
        )
        self.local: dict[str, SemanticObject] = {}  # in the order of their local indices
        self.local_index: dict[str, int] = {}
        self.gated_of: dict[int, int] = {}  # local index -> candidates kept by the prior
        self.support = MapSupport(
            [], global_map.positions, config.verification, axis=global_map.sweep_order.axis
        )
        self.poses: dict[_PoseKey, PoseEstimate | None] = {}  # of the last answer's sets

    def renewed(self) -> Search:
        """An empty search of the same map, prior and retrieval."""
        return Search(self.context, self.sightings, self.prior, self.local_up, self.retrieved)

    @property
    def n_sets(self) -> int:
        return self.clustering.n_sets

    # Growing --------------------------------------------------------------------------
    def retrieve(self) -> None:
        """Narrow each window object's candidates to the places that can hold the window
        (`semloc.places`); when an object the search holds gets other candidates than it was
        clustered with, the search is stale."""
        places, found_of = self.context.places, self.sightings.found
        assert places is not None
        objects = self.sightings.window.objects
        found = [self.prior_gated(o, found_of[o.id][1]) for o in objects]
        positions = np.array([o.position for o in objects]).reshape(-1, 3)
        support = places.support(positions, found, MergeCriterion.of(self.config.clustering))
        kept = places.kept(support, found)
        retrieved = {o.id: k for o, k in zip(objects, kept)}
        held = {i: self.retrieved[i] for i in self.local if i in self.retrieved}
        if any(not np.isin(retrieved[i], c, assume_unique=True).all() for i, c in held.items()):
            self.stale = True  # wider than the search holds: it regrows
        elif held:  # narrower: the held objects keep theirs (their other sets stay apart)
            retrieved.update(held)
        self.retrieved = retrieved

    def associate(self, objects: list[SemanticObject]) -> dict[int, np.ndarray]:
        """Register objects with the search; return candidate global indices per local index."""
        detections: dict[int, np.ndarray] = {}
        for obj in objects:
            index = self.local_index.setdefault(obj.id, len(self.local_index))
            if obj.id in self.local:  # re-detected: poses that used the old version are stale
                kept = self.poses.items()
                self.poses = {k: v for k, v in kept if all(l != index for _, l in k[1])}
            self.local[obj.id] = obj
            found = self.sightings.found[obj.id][1]
            self.support.assign(index, found)
            detections[index] = self.gated(obj, found)
            self.gated_of[index] = len(detections[index])
        return detections

    def cluster(self, detections: dict[int, np.ndarray]) -> None:
        """Grow the association sets by the associated objects (the paper's clustering)."""
        # an update whose objects all wait in place retrieval gives the sets nothing to merge
        # with: it must not age them out (the view's copies would expire but ten)
        waiting = self.context.places is not None and not any(len(c) for c in detections.values())
        if detections and not waiting:
            self.clustering.update(
                np.array([o.position for o in self.local.values()]).reshape(-1, 3),
                list(self.local),
                detections,
            )

    def candidates(self, local_index: int) -> np.ndarray:
        """The map objects (ascending) the local object of `local_index` may be."""
        return self.sightings.found[list(self.local)[local_index]][1]

    def gated(self, obj: SemanticObject, found: np.ndarray) -> np.ndarray:
        """The candidates the clustering gets: those the prior lets `obj` be, in the places
        retrieved for the window (large maps); all without either.  Evidence, verification
        and tracking see all candidates."""
        if self.context.places is not None and obj.id in self.retrieved:
            return self.retrieved[obj.id]  # (retrieved among the prior's candidates)
        return self.prior_gated(obj, found)

    def prior_gated(self, obj: SemanticObject, found: np.ndarray) -> np.ndarray:
        """The candidates of `obj` the prior allows (all without a prior)."""
        if self.prior is None:
            return found
        slack = self.context.gate_slack[found]
        return found[self.prior.gate(obj.position, self.context.map.positions[found], slack)]

    # Answering -------------------------------------------------------------------------
    def decide(self, hypotheses: list[Hypothesis]) -> tuple[Status, str]:
        """The verdict on the hypotheses (`decision.decide`), cut short when the search left
        out places as good as its best, and never a claim the newest objects contradict or
        that none of its objects was seen of late backs."""
        config = self.config
        status, why = decide(hypotheses, config.decision, config.rank_by)
        status, why = cut_search(Decision(status, why), *self.cut)
        if not hypotheses:
            why = self.why_no_sets()
        elif why == OUTSIDE_PRIOR and self.prior is not None:  # (the best has a pose)
            why = self.prior.why_outside(np.asarray(hypotheses[0].pose))
        if status == "localized" and self.newest_contradict(hypotheses[0]):
            status, why = "ambiguous", NEWEST_CONTRADICT
        elif status == "localized" and self.sightings.stale([l for _, l in hypotheses[0].pairs],
                                                             config.tracking.stale_m):  # fmt: skip
            status, why = "ambiguous", _stale_reason(config.tracking.stale_m)
        return status, why

    def newest_contradict(self, best: Hypothesis) -> bool:
        """Whether the objects of the latest updates contradict the best place by tracking's
        rule (`semloc.tracking`): a claim is about where the robot is now, and a window that
        spans a kidnap holds a place the robot has left."""
        assert best.pose is not None
        tracking, context, sightings = self.config.tracking, self.context, self.sightings
        verdicts = []
        updates = sightings.window.updates
        for update in range(updates - 2, updates + 1):
            objects = sightings.arrived_at(update)
            verdicts.append(check(best.pose, objects, sightings.candidates(objects),
                                  context.map.positions, context.allowances, tracking.move_m,
                                  part_m=context.parts))  # fmt: skip
        return recent_contradiction(verdicts, tracking.contradiction)

    def why_no_sets(self) -> str:
        """Why no association set has 2 pairs: too few objects, or too few with candidates."""
        found = self.sightings.found
        matched = sum(len(found[i][1]) > 0 for i in self.local)
        if len(self.context.map) == 0:
            return "the global map has no objects"
        if len(self.local) < 2:
            return f"too few local objects: {len(self.local)} seen, 2 needed"
        waiting = [  # retrieval left them nothing, though the prior (if any) left some
            i for i, k in self.retrieved.items()
            if len(k) == 0 and len(self.prior_gated(*found[i][:2]))
        ]  # fmt: skip
        if waiting and matched >= 2 and sum(len(k) > 0 for k in self.retrieved.values()) < 2:
            return (
                f"the view so far fits too many places of the map: {len(waiting)} local "
                "object(s) wait for more objects to narrow their places (place retrieval)"
            )
        if self.prior is not None and sum(n > 0 for n in self.gated_of.values()) < 2 <= matched:
            return "too few candidates within the prior: fewer than 2 local objects have one"
        if matched == 0:
            return "no candidates for these labels: no local object has a map object it could be"
        if matched == 1:
            return "only one local object has candidates in the map (2 needed)"
        return "no two local objects have consistent candidates (no set of 2 or more pairs)"

    # Hypotheses -------------------------------------------------------------------------
    def hypotheses(self) -> list[Hypothesis]:
        """Distinct places, best first: verify many sets by closed-form consensus, recover the
        poses of the top-k, measure their evidence, rank, merge duplicates, attach confidence."""
        cfg = self.config
        by_size = cfg.rank_by in ("residual", "evidence")
        sets, cut = self._screened_sets(by_size)
        local_xyz = np.array([o.position for o in self.local.values()]).reshape(-1, 3)
        screened = [c for c in self.verified_all(sets, local_xyz) if len(c.pairs) >= 2]
        if by_size:  # pairs include the guided matches
            screened.sort(key=lambda c: (-len(c.pairs), round(c.residual, 9), -c.score))
        places = [(c.pairs, c.pose) for c in screened]
        anchor = local_anchor(local_xyz)
        picked = distinct(places, cfg.top_k + 1, cfg.decision, anchor)
        best = (len(screened[0].pairs), screened[0].residual) if screened else (0, 0.0)
        if by_size and len(picked) > cfg.top_k:  # a place left out: as good as the best?
            left = screened[picked[-1]]
            cut |= as_well_supported(len(left.pairs), left.residual, best, cfg.decision)
        self.cut = (cut, best[0])
        chosen = [screened[i] for i in picked[: cfg.top_k]]
        previous, self.poses = self.poses, {}
        hypotheses = [
            self._hypothesis(rank, c, local_xyz, previous, lazy=True)
            for rank, c in enumerate(chosen, 1)
        ]
        ranked = self._lazily_ranked(hypotheses, anchor)
        twins_, listed = self._twins(ranked, local_xyz, previous, anchor)
        twinned: list[Hypothesis] = []
        if twins_ or listed:  # copies of the best place, listed by the sets or not, weighed
            places = [(h.pairs, h.pose) for h in (ranked[0], *twins_)] + listed
            ranked = rank_places(ranked + twins_, cfg.rank_by, cfg.decision, shipped_model(),
                                 anchor)  # fmt: skip
            twinned = [h for h in ranked if any(same_place((h.pairs, h.pose), p, cfg.decision,
                                                           anchor) for p in places)]  # fmt: skip
            score_confidence(ranked, shipped_model(), cfg.decision.rival_overlap, twinned)
        if self.prior is not None:  # conditioned on the prior: rivals outside it do not count
            for h in ranked:
                h.outside_prior = h.pose is not None and not self.prior.admits(h.pose)
            ranked = prior_first(ranked)
            inside = [h for h in ranked if not h.outside_prior]
            score_confidence(inside, shipped_model(), cfg.decision.rival_overlap, twinned)
        return ranked

    def _twins(
        self, ranked: list[Hypothesis], local_xyz: np.ndarray, previous: dict, anchor
    ) -> tuple[list[Hypothesis], list[tuple[list, np.ndarray]]]:
        """The map's copies of a best place that could be claimed (`semloc.twins`): those
        the search did not list, as hypotheses of the window's objects, and the places
        (no pairs, the pose) of those it listed; none when it could not be claimed anyway."""
        best = ranked[0] if ranked else None
        context = self.context
        up = context.map.up
        if best is None or best.pose is None or best.confidence is None or up is None:
            return [], []
        if best.confidence < self.config.decision.min_confidence:
            return [], []
        positions, tolerance = context.map.positions, self.config.verification.inlier_tolerance
        pairs = [(context.map.index_of(g), self.local_index[l]) for g, l in best.pairs]
        members = np.array([g for g, _ in pairs])
        sets, listed = [], []
        candidates = [self.sightings.found[i][1] for i in self.local]  # by local index
        for S in context.copies_of(members):
            place: tuple[list, np.ndarray] = ([], S @ best.pose)
            if any(same_place(place, (h.pairs, h.pose), self.config.decision, anchor)
                   for h in ranked[1:]):  # fmt: skip
                listed.append(place)  # (weighed already)
                continue
            moved = twin_pairs(S, pairs, positions, context.codes, tolerance, context.tree)
            moved = [(g, l) for g, l in moved if g in candidates[l]]
            if len(moved) >= MIN_TWIN_PAIRS:
                sets.append(moved)
        if not sets:
            return [], listed
        rows = np.array([p for pairs_ in sets for p in pairs_], dtype=np.int64)
        sizes = np.array([len(p) for p in sets], dtype=np.int64)
        verified = verify_sets(
            rows, sizes, np.full(len(sets), best.score), local_xyz, positions,
            (self.local_up, up), self.config.verification, self.support,
        )  # fmt: skip
        found = [self._hypothesis(1, v, local_xyz, previous)  # (refined as the best is)
                 for v in verified if len(v.pairs) >= 2]  # fmt: skip
        return found, listed

    def _screened_sets(self, by_size: bool) -> tuple[SetPairs, bool]:
        """The sets screened for hypotheses, and whether the screening was cut.  Ranked by
        size: the `screened_sets` best; in a building (a map place retrieval narrows), then
        each further set as large as the largest whose map objects lie in a region no
        screened set covers (`new_regions`), up to `screened_sets` more: variants of one place
        (chairs swapped) must not crowd its copies elsewhere out.  More new regions than that:
        cut.  Smaller maps screen as they always did (their confidence is calibrated so)."""
        limit, clustering = self.config.screened_sets, self.clustering
        if not by_size or self.context.places is None:
            return clustering.top_pairs(limit, min_size=2, largest_first=by_size), False
        sets = clustering.top_pairs(clustering.n_sets, 2, largest_first=True)
        if len(sets.sizes) <= limit:
            return sets, False
        largest = int(np.searchsorted(-sets.sizes, -sets.sizes[0], side="right"))
        ends = np.cumsum(sets.sizes[:largest])
        centroids = np.add.reduceat(self.context.map.positions[sets.pairs[: ends[-1], 0]],
                                    ends - sets.sizes[:largest]) / sets.sizes[:largest, None]  # fmt: skip
        extra = new_regions(centroids, limit, most=limit + 1)
        rows = np.concatenate([np.arange(limit), extra[:limit]])
        return _rows_of(sets, rows), len(extra) > limit

    def verified_all(self, sets: SetPairs, local_xyz: np.ndarray) -> list[Verified]:
        """Each set verified against the map (`semloc.verification.verify_sets`)."""
        return verify_sets(
            sets.pairs, sets.sizes, sets.scores, local_xyz, self.context.map.positions,
            (self.local_up, self.context.map.up), self.config.verification, self.support,
        )  # fmt: skip

    def _hypothesis(
        self, rank: int, verified: Verified, local_xyz: np.ndarray, previous: dict,
        lazy: bool = False,
    ) -> Hypothesis:  # fmt: skip
        """A verified set's inlier pairs with their pose and evidence: refined (robust ICP)
        when among the `refine_top` first, unless `lazy` (then when `Hypothesis.refine` asks);
        the others keep the closed form's (or search's) pose unless asked."""
        local_objects, global_map = list(self.local.values()), self.context.map
        globals_ = [global_map[g] for g, _ in verified.pairs]
        locals_ = [local_objects[l] for _, l in verified.pairs]
        l_xyz = np.array([o.position for o in locals_])
        g_xyz = np.array([o.position for o in globals_])
        ids = global_map.ids
        hypothesis = Hypothesis(
            rank=rank,
            score=verified.score,
            pairs=[(g.id, l.id) for g, l in zip(globals_, locals_)],
            pose=None,
            rejected=[(str(ids[g]), local_objects[l].id) for g, l in verified.rejected],
        )
        recovery = _Recovery(self, verified.pairs, previous, (l_xyz, g_xyz, locals_, globals_))

        def refine(h: Hypothesis) -> None:
            self._posed(h, verified, recovery, local_xyz, True)
            if h.features is not None:
                h.evidence = shipped_model().evidence(h.features) - missing_penalty(h)

        self._posed(hypothesis, verified, recovery, local_xyz, rank <= self.config.refine_top
                    and not lazy)  # fmt: skip
        if not hypothesis.refined:
            hypothesis._refiner = refine
        return hypothesis

    def _posed(
        self, h: Hypothesis, verified: Verified, recovery: _Recovery, local_xyz: np.ndarray,
        refine: bool,
    ) -> None:  # fmt: skip
        """`h` given the recovered pose of its pairs (refined or not) and its evidence."""
        l_xyz, g_xyz = recovery.matched[:2]
        estimate = recovery.estimate(refine)
        residual, features = verified.residual, None
        tolerance = self.config.verification.inlier_tolerance
        if estimate is not None:
            residual = centre_residual(estimate.T, l_xyz, g_xyz)
            if refine and residual > tolerance >= verified.residual:
                # ICP on points that do not fit dragged the pose off the agreeing centres
                estimate = recovery.estimate(False)
                assert estimate is not None  # the closed form was determined before
                residual = centre_residual(estimate.T, l_xyz, g_xyz)
        pose = None if estimate is None else estimate.T
        if estimate is not None:
            features = Evidence(
                len(verified.pairs), len(verified.rejected), residual, estimate.fitness,
                verified.support, verified.conflicts, len(local_xyz),
                self._semantic_weight(verified.pairs),
            ).features()  # fmt: skip
        missing = expected = None
        looks = self.sightings.looks
        if pose is not None and looks and refine:  # (the places that decide)
            seen, unseen = self.sightings.unseen(pose, list(looks))
            missing, expected = len(unseen), len(seen)
        h.pose, h.residual, h.features = pose, None if pose is None else residual, features
        h.fitness = None if estimate is None else estimate.fitness
        h.rmse = None if estimate is None else estimate.rmse
        h.method = "" if estimate is None else estimate.method
        h.n_missing, h.n_expected, h.refined = missing, expected, refine or pose is None

    def _lazily_ranked(
        self, hypotheses: list[Hypothesis], anchor: np.ndarray | None
    ) -> list[Hypothesis]:
        """`rank_places` of the hypotheses, the first `refine_top` refined (robust ICP) only
        as far as the verdict needs: the best place and the rivals that could change which
        place is best or the status (`decision.verdict_refinements`); the others keep their
        closed-form pose (`refined: false`, `Hypothesis.refine` on demand).  Without the
        bounds that proof needs (a prior, a ranking other than the evidence's), all of them."""
        cfg = self.config
        pending = [h for h in hypotheses[: cfg.refine_top] if not h.refined]
        model = shipped_model()
        while pending:
            todo = pending
            if self.prior is None and cfg.rank_by == "evidence":
                todo = verdict_refinements(hypotheses, pending, cfg.decision, model)
            if not todo:
                break
            for h in todo:
                h.refine()
            pending = [h for h in pending if not h.refined]
        ranked = rank_places(hypotheses, cfg.rank_by, cfg.decision, model, anchor)
        if pending and self._has_copies(ranked[0]):  # a copy may outrank the best: its
            for h in pending:  # rivals and which places are listed are the pending ones too
                h.refine()
            ranked = rank_places(hypotheses, cfg.rank_by, cfg.decision, model, anchor)
        return ranked

    def _has_copies(self, best: Hypothesis) -> bool:
        """Whether `_twins` weighs copies of `best` (a claimable place with copies)."""
        global_map = self.context.map
        if best.pose is None or best.confidence is None or global_map.up is None:
            return False
        if best.confidence < self.config.decision.min_confidence:
            return False
        members = np.array([global_map.index_of(g) for g, _ in best.pairs])
        return bool(self.context.copies_of(members))

    def _semantic_weight(self, pairs: list[tuple[int, int]]) -> float:
        """The summed evidence weight (`semantics.pair_weight`) of (global, local) index pairs."""
        total, ids = 0.0, list(self.local)
        for g, l in pairs:
            _, candidates, similarity = self.sightings.found[ids[l]]
            at = int(np.searchsorted(candidates, g))
            found = at < len(candidates) and candidates[at] == g
            total += float(pair_weight(similarity[at])) if found else 1.0
        return total


class _Recovery:
    """The pose of one set's pairs, refined or not, for the search's current answer: reused
    when the previous answer recovered it for the same pairs (same object versions), else
    recovered once (`semloc.pose.recover_pose`), warm-started from the pose of the largest
    subset of its pairs that the previous answer recovered (refined ones first), and refined
    (robust ICP) only when asked.  Each estimate given is kept for the next answer
    (`Search.poses` of this answer: a re-detection since drops them).  Object clouds are
    prepared once per object (`pose.cached_cloud`), so all searches of one map share them."""

    def __init__(
        self, search: Search, pairs: list[tuple[int, int]], previous: dict, matched: tuple
    ) -> None:
        self.search, self.previous, self.matched = search, previous, matched
        self.kept = search.poses  # this answer's (a refinement asked later lands there)
        self.pairs = frozenset(pairs)
        self._recovery: PoseRecovery | None = None
        self._recovered = False

    def estimate(self, refine: bool) -> PoseEstimate | None:
        key: _PoseKey = (refine, self.pairs)
        if key in self.previous:
            estimate = self.previous[key]
        else:
            recovery = self._recover()
            cfg = self.search.config.pose
            estimate = None if recovery is None else recovery.estimate(refine and cfg.refine)
        self.kept[key] = estimate
        return estimate

    def _recover(self) -> PoseRecovery | None:
        if not self._recovered:
            l_xyz, g_xyz, locals_, globals_ = self.matched
            search = self.search
            cfg = search.config.pose
            self._recovery = recover_pose(
                l_xyz, g_xyz, [cached_cloud(o, cfg) for o in locals_],
                [cached_cloud(o, cfg) for o in globals_], search.local_up,
                search.context.map.up, cfg, init=_warm_start(self.pairs, self.previous),
            )  # fmt: skip
            self._recovered = True
        return self._recovery


def _stale_reason(stale_m: float | None) -> str:
    return f"{STALE}: none of its objects was detected in the last {stale_m:g} m"


def _warm_start(pairs: frozenset, previous: dict[_PoseKey, PoseEstimate | None]):
    """The pose of the largest recovered subset of `pairs` (refined first), or None."""
    subsets = [
        (len(k[1]), k[0], estimate.T)
        for k, estimate in previous.items()
        if estimate is not None and k[1] <= pairs
    ]
    return max(subsets, key=lambda s: s[:2])[2] if subsets else None


def _rows_of(sets: SetPairs, rows: np.ndarray) -> SetPairs:
    """The sets at `rows` (ascending) of `sets`."""
    starts = np.concatenate([[0], np.cumsum(sets.sizes)[:-1]])
    pairs = [sets.pairs[starts[r] : starts[r] + sets.sizes[r]] for r in rows]
    return SetPairs(np.concatenate(pairs), sets.sizes[rows], sets.scores[rows])
