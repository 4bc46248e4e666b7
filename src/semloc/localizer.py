"""The Localizer: association → clustering → hypotheses → decision, one incremental update at a time.

`Localizer(global_map, config).update(objects)` takes the local objects that are new or were
re-detected (same id = updated), grows the association sets, turns the best of them into
distinct pose hypotheses and decides (`decision.py`).  Each screened set is verified first
(`verification.consensus`: the pairs that disagree with the pose the others agree on are
rejected); only the chosen hypotheses get a pose recovery (closed form, or a global search
where the centres leave the rotation free), after which their evidence is measured, they are
ranked by it, same-place duplicates are merged and a calibrated confidence is attached.
Robust ICP refines the best and only those of the `refine_top` first whose refinement could
change the verdict (`decision.verdict_refinements`); the others keep their closed-form
pose, marked `refined: false`, and are refined on demand (`Hypothesis.refine`).
`update(objects, answer=False)` only grows the association sets, for callers that read the
answer later (a replay reads only its last one).

Streaming: the poses of the last answer are kept per association set (keyed by its pairs and
whether it was refined).  A set that is unchanged at the next answer reuses its estimate; a set
that grew is recovered warm-started from the pose of its largest kept subset; a re-detected
local object drops the kept poses that used it.  Object clouds for pose recovery are prepared
once per object (`pose.cached_cloud`), so all Localizers of one map share them.

Look-alike rooms: before a best place is claimed, its copies in the map (`semloc.twins`) are
weighed as hypotheses, listed by the sets or not (an old map can make the right copy's sets
lose to another's); a copy the view does not tell apart (`decision.told_apart`) keeps the
answer `ambiguous`.  While a place is tracked, objects that it cannot explain but one of its
copies holds where the pose puts them make the answer `ambiguous` while that copy leads over
the latest updates (`TWIN_DOUBT`, the copy listed as the second hypothesis) and end the claim
when it leads by more (`TWIN_KIDNAP`): the robot was carried into the copy.

A position prior (`semloc.priors.Prior`: `Localizer(..., prior=P)`, `set_prior`) gates the
candidates of each local object and marks the hypotheses whose pose lies outside it, which
cannot be `localized`; a tracked place that leaves it ends the claim.

`localize(global_map, local_map)` replays a local map by its `seen` keyframes.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable, Iterable
from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator
from scipy.spatial import cKDTree

from semloc.association import (
    AssociationConfig,
    CandidateIndex,
    Describer,
    LabelResolution,
    label_report,
)
from semloc.changes import Changes, ChangesConfig, RunChanges, answer_changes
from semloc.clustering import ClusteringConfig, HierarchicalClustering, MergeCriterion, SetPairs
from semloc.coverage import (
    GONE_SHARE,
    Accounting,
    Coverage,
    Looks,
    checked_coverage,
    expected_objects,
)
from semloc.decision import (
    PLACE_APART,
    Decision,
    DecisionConfig,
    RankBy,
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
from semloc.maps import MapError, ObjectMap, SemanticObject, unit_vector
from semloc.next_look import NextLookConfig, next_look
from semloc.places import PlaceIndex, RetrievalConfig, place_index
from semloc.pose import (
    PoseConfig,
    PoseEstimate,
    PoseRecovery,
    cached_cloud,
    estimate_pose,
    recover_pose,
)
from semloc.priors import GATE_SLACK, OUTSIDE_PRIOR, Prior, checked_prior
from semloc.results import Hypothesis, Result, Status, Step, Support
from semloc.semantics import pair_weight
from semloc.tracking import (
    CONTRADICTED,
    AgainstRate,
    Track,
    TrackingConfig,
    Verdict,
    allowances,
    check,
    footprints,
    one_to_one,
    recent_contradiction,
)
from semloc.transforms import centre_residual
from semloc.twins import (
    ANCHORS,
    MIN_TWIN_PAIRS,
    copy_holds,
    label_codes,
    twin_lead,
    twin_pairs,
    twins,
)
from semloc.verification import (
    Evidence,
    MapSupport,
    VerificationConfig,
    Verified,
    verify_sets,
)
from semloc.window import LocalWindow, WindowConfig

_COMPONENTS: dict[str, type[BaseModel]] = {
    "association": AssociationConfig,
    "clustering": ClusteringConfig,
    "pose": PoseConfig,
    "verification": VerificationConfig,
    "decision": DecisionConfig,
    "changes": ChangesConfig,
    "window": WindowConfig,
    "tracking": TrackingConfig,
    "retrieval": RetrievalConfig,
    "next_look": NextLookConfig,
}


class LocalizerConfig(BaseModel):
    """All settings, one model per component.  Component fields may also be given flat:
    `LocalizerConfig(gamma=0.7, delta=0.4)` sets `clustering.gamma` and `association.delta`."""

    model_config = ConfigDict(extra="forbid")

    association: AssociationConfig = Field(default_factory=AssociationConfig)
    clustering: ClusteringConfig = Field(default_factory=ClusteringConfig)
    pose: PoseConfig = Field(default_factory=PoseConfig)
    verification: VerificationConfig = Field(default_factory=VerificationConfig)
    decision: DecisionConfig = Field(default_factory=DecisionConfig)
    changes: ChangesConfig = Field(default_factory=ChangesConfig)
    window: WindowConfig = Field(default_factory=WindowConfig)
    tracking: TrackingConfig = Field(default_factory=TrackingConfig)
    retrieval: RetrievalConfig = Field(default_factory=RetrievalConfig)
    next_look: NextLookConfig = Field(default_factory=NextLookConfig)
    top_k: int = Field(10, ge=1, description="How many distinct hypotheses are reported.")
    screened_sets: int = Field(
        60, ge=1, description="Association sets screened by closed-form pose for hypotheses."
    )
    refine_top: int = Field(
        3,
        ge=0,
        description="How many of the best hypotheses may get robust ICP: the best one and "
        "those whose refinement could change the verdict (the rest: closed form or search, "
        "with fitness; `Hypothesis.refine` on demand).",
    )
    rank_by: RankBy = Field(
        "evidence",
        description="Order of the reported hypotheses: 'evidence' (the confidence model's "
        "evidence: agreeing pairs, fitness, residual, supporting and conflicting objects), "
        "'residual' (most pairs, then smallest residual of the aligned object centres), "
        "'score' (the paper's clustering score) or 'fitness' (point-set fitness of the pose).",
    )

    @model_validator(mode="before")
    @classmethod
    def _route_flat_fields(cls, data: Any) -> Any:
        if not isinstance(data, dict):
            return data
        data = dict(data)
        for key in [k for k in data if k not in cls.model_fields]:
            owners = [name for name, model in _COMPONENTS.items() if key in model.model_fields]
            if len(owners) == 1:
                section = data.get(owners[0], {})
                if isinstance(section, BaseModel):
                    section = section.model_dump()
                data[owners[0]] = {**section, key: data.pop(key)}
        return data

    @property
    def gamma(self) -> float:
        return self.clustering.gamma

    @property
    def delta(self) -> float:
        return self.association.delta


class Localizer:
    """Incremental object-level relocalization against one global map.

    `describer` computes shape descriptors for the candidate gate; by default the kind named
    by `config.association.descriptor` from the registry (`semloc.association.DESCRIBERS`).
    """

    def __init__(
        self,
        global_map: ObjectMap,
        config: LocalizerConfig | None = None,
        local_up: Any = None,
        describer: Describer | None = None,
        prior: Prior | None = None,
        **overrides: Any,
    ) -> None:
        if not isinstance(global_map, ObjectMap):
            raise TypeError(
                f"Localizer needs an ObjectMap as global map, got {type(global_map).__name__}"
            )
        if config is not None and not isinstance(config, LocalizerConfig):
            raise TypeError(
                f"config must be a LocalizerConfig, got {type(config).__name__}; give settings "
                "as keywords (Localizer(global_map, gamma=0.7)) or LocalizerConfig(**settings)"
            )
        if config is None:
            config = LocalizerConfig(**overrides)
        elif overrides:
            config = LocalizerConfig(**{**config.model_dump(), **overrides})
        self.config = config
        self._describer = describer or config.association.describer()
        if self._describer is not None:
            global_map = global_map.with_objects(self._describer.describe(global_map))
        self.global_map = global_map
        self.local_up = None if local_up is None else unit_vector(local_up, "local_up")
        self.descriptor_gate = config.association.gate(self._describer)
        self._candidates = CandidateIndex(global_map, config.association, self.descriptor_gate)
        self.window = LocalWindow(config.window)
        self._track: Track | None = None
        self._allowance: np.ndarray | None = None  # per map object, for tracking checks
        self._part_m: np.ndarray | None = None  # per map object, half its footprint
        self._found: dict[str, tuple[SemanticObject, np.ndarray, np.ndarray]] = {}
        self._prior = checked_prior(prior)
        self._prior_slack: np.ndarray | None = None  # per map object, for the prior's gate
        above = config.retrieval.above
        self._places: PlaceIndex | None = (
            place_index(global_map, config.retrieval)
            if above is not None and len(global_map) >= above
            else None
        )
        self._retrieved: dict[str, np.ndarray] = {}  # local id -> candidates in its places
        self._look: Coverage | None = None  # what the sensor covered at this update
        self._looks: deque[tuple[int, Coverage]] = deque(maxlen=LOOKS_KEPT)  # (update, look)
        self._run_changes = RunChanges()  # what changed, over the run's tracked claims
        self._against = AgainstRate()  # how often the run's claims judged objects against
        self._map_tree: cKDTree | None = None  # the map's positions, for looks and twins
        self._unseen_of: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}  # this update's, by pose
        self._label_codes: np.ndarray | None = None  # the map's labels as integers (twins)
        self._twin_motions: dict[tuple[int, ...], list[np.ndarray]] = {}  # (anchors, map
        # objects) -> twins
        self._track_twins: tuple[np.ndarray, list[np.ndarray]] | None = None  # (its pairs'
        # map objects when found, the copies) of the tracked place where the robot is
        self._twin_fits: deque[tuple[int, list[list[str]]]] = deque(maxlen=TWIN_UPDATES)
        # (each latest update's objects that tell the place from each copy; None: not weighed)
        self._diagonal_lengths: np.ndarray | None = None
        self._reset_search()
        self._steps: deque[Step] = deque(maxlen=config.window.steps)
        self._n_steps = 0
        self._timing = {"association": 0.0, "clustering": 0.0, "pose": 0.0, "total": 0.0}

    def _reset_search(self) -> None:
        """An empty search: no association sets, no local objects registered."""
        global_map, config = self.global_map, self.config
        self._poses: dict[_PoseKey, PoseEstimate | None] = {}  # of the last answer's sets
        self._clustering = HierarchicalClustering(
            global_map.positions,
            list(global_map.ids),
            config.clustering,
            encoded_ids=global_map.encoded_ids,
            sweep_order=global_map.sweep_order,
        )
        self._local: dict[str, SemanticObject] = {}
        self._local_index: dict[str, int] = {}
        self._candidates_of: dict[int, np.ndarray] = {}  # local index -> global indices
        self._gated_of: dict[int, int] = {}  # local index -> candidates kept by the prior
        self._similarity_of: dict[int, np.ndarray] = {}  # local index -> their similarity
        self._support = MapSupport(
            [], global_map.positions, config.verification, axis=global_map.sweep_order.axis
        )
        self._search_stale = False  # the window changed without the search seeing it
        self._cut = (False, 0)  # the last search left out places as good as its best; pairs

    @property
    def local_map(self) -> ObjectMap:
        """The local objects of the window (latest version of each, oldest detection first)."""
        return ObjectMap(self.window.objects, up=self.local_up, name="local")

    def state(self) -> dict[str, Any]:
        """What rebuilds this Localizer besides its window's objects (`local_map`), in JSON
        types: the window's bookkeeping, the tracked place, the kept steps and timing.
        `Localizer.restore` takes it back; the restored Localizer answers as this one would
        while it tracks a place, and otherwise clusters its window anew at its next update
        (the same objects in one batch instead of the updates they came in)."""
        track = None if self._track is None else self._track.state(list(self.global_map.ids))
        return {
            "version": STATE_VERSION,
            "window": self.window.state(),
            "track": track,
            "steps": [s.to_dict() for s in self._steps],
            "looks": [[update, look.to_dict()] for update, look in self._looks],
            "changes": self._run_changes.state(list(self.global_map.ids)),
            "against": [self._against.against, self._against.judged],
            "twins": self._twins_state(),
            "n_steps": self._n_steps,
            "timing": dict(self._timing),
        }

    @classmethod
    def restore(
        cls,
        global_map: ObjectMap,
        state: dict[str, Any],
        objects: Iterable[SemanticObject],
        config: LocalizerConfig | None = None,
        local_up: Any = None,
        prior: Prior | None = None,
    ) -> Localizer:
        """A Localizer from `state()` and the window's objects (the latest version of each);
        `ValueError` when they do not fit together.  The prior is not part of the state."""
        if not isinstance(state, dict) or state.get("version") != STATE_VERSION:
            raise ValueError(f"not a Localizer state of version {STATE_VERSION}")
        localizer = cls(global_map, config, local_up=local_up, prior=prior)
        try:
            objects = localizer._described(list(objects))
            localizer.window = LocalWindow.restored(
                localizer.config.window, state["window"], objects
            )
            localizer._register(objects)
            localizer._against = AgainstRate(*map(float, state.get("against", [0.0, 0.0])))
            if state["track"] is not None:
                localizer._track = Track.restored(
                    state["track"], localizer.global_map.index_of, localizer.config.tracking,
                    localizer._against,
                )  # fmt: skip
            localizer._steps.extend(Step(**s) for s in state["steps"])
            localizer._run_changes = RunChanges.restored(
                state.get("changes", {}), localizer.global_map.index_of
            )
            localizer._looks.extend(
                (int(update), Coverage.from_dict(look)) for update, look in state.get("looks", [])
            )
            localizer._restore_twins(state.get("twins"))
            localizer._n_steps = int(state["n_steps"])
            localizer._timing.update({k: float(v) for k, v in state["timing"].items()})
        except (KeyError, TypeError, IndexError) as exc:
            raise ValueError(f"the Localizer state is malformed ({exc!r})") from None
        localizer._search_stale = True
        return localizer

    def _twins_state(self) -> dict[str, list] | None:
        """The tracked place's copies were found from these map objects; the latest updates'
        objects that fit each copy (`_carried_to_twin`)."""
        if self._track_twins is None:
            return None
        ids = self.global_map.ids
        return {
            "members": [str(ids[g]) for g in self._track_twins[0].tolist()],
            "fits": [[update, told] for update, told in self._twin_fits],
        }

    def _restore_twins(self, twins_state: dict[str, list] | None) -> None:
        if twins_state is None:
            return
        members = np.array([self.global_map.index_of(g) for g in twins_state["members"]], int)
        self._track_twins = (members, self._twin_motions_of(members, TRACK_ANCHORS))
        fits = twins_state["fits"]
        for i, fit in enumerate(fits):
            if fit and isinstance(fit[0], int) and len(fit) == 2:
                update, told = fit
            else:  # (a state of every update's objects, consecutive, or of counts: none)
                update, told = self.window.updates - len(fits) + 1 + i, fit
            if told and all(isinstance(keys, list) for keys in told) and any(told):
                self._twin_fits.append((int(update), told))

    @property
    def tracking(self) -> bool:
        """Whether a found place is being tracked (the last answer was `localized`)."""
        return self._track is not None

    @property
    def prior(self) -> Prior | None:
        """The position prior in effect (None: none); `set_prior` changes it."""
        return self._prior

    def set_prior(self, prior: Prior | None) -> None:
        """Use `prior` from the next update on (None removes it): the window's candidates are
        gated anew and the search regrows; a tracked place outside the new prior is let go."""
        self._prior = checked_prior(prior)
        self._search_stale = True  # the search regrows from the window, gated anew
        if self._track is not None and not self._within_prior(self._track.pose):
            self._end_track()

    def _within_prior(self, pose: np.ndarray) -> bool:
        return self._prior is None or self._prior.admits(pose)

    @property
    def n_sets(self) -> int:
        return self._clustering.n_sets

    def prepare(self) -> Localizer:
        """Prepare the point cloud of every map object now (downsampled points, normals,
        KD-tree), instead of when a localization first needs it; returns the Localizer.

        The preparation is kept per map object (`cached_cloud`), so it is done once per
        loaded map whichever Localizer asks: call it after loading a map, before time-critical
        use (about half a millisecond per object of a few hundred points)."""
        for obj in self.global_map:
            cached_cloud(obj, self.config.pose)
        return self

    def update(
        self,
        objects: Iterable[SemanticObject] | ObjectMap,
        answer: bool = True,
        *,
        position: Any = None,
        coverage: Coverage | None = None,
    ) -> Result | None:
        """Add new or re-detected local objects and return the current answer.

        `position`: where the robot is now in the local (odometry) frame, a point or a 4x4
        pose; it measures the travel that bounds the window (`config.window.distance`).
        `coverage`: what the sensor covered at this update (`semloc.Coverage`, or its dict);
        with it, map objects a place puts in view that were not detected count against it.
        With `answer=False` only the association sets grow (no hypotheses, no pose recovery,
        no decision) and None is returned; a later update with an answer sees the same sets.
        """
        start = time.perf_counter()
        if isinstance(objects, ObjectMap) and objects.up is not None and self.local_up is None:
            self.local_up = objects.up
        objects = self._described(_checked_objects(objects))
        self._look = checked_coverage(coverage)
        self._unseen_of = {}
        self.window.advance(_robot_position(position))
        if self._look is not None:
            self._looks.append((self.window.updates, self._look))
        self.window.add(objects)
        retired = self.window.retire()
        for object_id in retired:
            self._found.pop(object_id, None)
        if retired:  # (an update larger than the window loses its oldest objects too)
            self._search_stale = True
            objects = [o for o in objects if o.id in self.window]
        self._register(objects)
        if self._track is not None:
            self._track.keep_only(self._found)
            return self._track_update(objects, answer, start)
        return self._search_update(objects, answer, start)

    def _search_update(
        self, objects: list[SemanticObject], answer: bool, start: float, reason: str = ""
    ) -> Result | None:
        """Grow the association sets of the window and decide (the paper's method).  A given
        `reason` overrides a `localized` decision (the answer that ended a tracked claim)."""
        if self._places is not None:
            self._retrieve()
        if self._search_stale:  # objects retired: the sets are grown again from the window
            self._reset_search()
            objects = self.window.objects
        detections = self._associate(objects)
        tick = time.perf_counter()
        # an update whose objects all wait in place retrieval gives the sets nothing to merge
        # with: it must not age them out (the view's copies would expire but ten)
        waiting = self._places is not None and not any(len(c) for c in detections.values())
        if detections and not waiting:
            self._clustering.update(
                np.array([o.position for o in self._local.values()]).reshape(-1, 3),
                list(self._local),
                detections,
            )
        tock = time.perf_counter()
        status: Status | None = None
        hypotheses: list[Hypothesis] = []
        if answer:
            hypotheses = self._hypotheses()
            status, why = decide(hypotheses, self.config.decision, self.config.rank_by)
            status, why = cut_search(Decision(status, why), *self._cut)
            if not hypotheses:
                why = self._why_no_sets()
            elif why == OUTSIDE_PRIOR and self._prior is not None:  # (the best has a pose)
                why = self._prior.why_outside(np.asarray(hypotheses[0].pose))
            if status == "localized" and self._newest_contradict(hypotheses[0]):
                status, why = "ambiguous", NEWEST_CONTRADICT
            elif status == "localized" and self._stale([l for _, l in hypotheses[0].pairs]):
                status, why = "ambiguous", self._stale_reason()
            if reason:
                status, why = "ambiguous", reason
            reason = why
            scores = [h.score for h in hypotheses]
        else:
            scores = self._clustering.top_scores(self.config.top_k, min_size=2)
        end = time.perf_counter()
        self._add_timing(tick - start, tock - tick, end - tock)
        self._add_step(scores, end - start, status)
        if status is None:
            return None
        hypotheses = hypotheses[: self.config.top_k]  # (twins weighed beyond it: not listed)
        result = self._result(status, hypotheses, reason, self._changes(hypotheses))
        if status == "localized" and self.config.tracking.track:
            self._start_track(hypotheses[0])
        return result

    def _track_update(self, objects: list[SemanticObject], answer: bool, start: float):
        """Check the tracked place on the new objects; follow it, or end the claim."""
        track = self._track
        assert track is not None
        candidates = {o.id: self._found[o.id][1] for o in objects}
        verdict = check(
            track.pose, objects, candidates, self.global_map.positions, self._allowances(),
            self.config.tracking.move_m, track.pairs, self._parts(),
        )  # fmt: skip
        looked, looked_unseen = None, np.zeros(0, dtype=int)
        if self._look is not None:
            expected, looked_unseen = self._unseen(track.pose)
            looked = (len(looked_unseen), len(expected))
            excess = max(0.0, len(looked_unseen) - GONE_SHARE * len(expected))
            verdict = Verdict(verdict.supported, verdict.contradicting, verdict.changed,
                              verdict.repeated, excess)  # fmt: skip
        against, doubt = track.contradicted(verdict), None
        if not against:
            lead, updates, doubt = self._carried_to_twin(
                track, verdict, objects, candidates, looked_unseen
            )
            against = updates if lead >= TWIN_KIDNAP else 0
        if against:  # a fresh window of the contradicting updates' objects
            return self._contradicted(against, objects, answer, start)
        report = self._report_verdict(track, objects, candidates, verdict)
        track.accept(verdict)
        self._observe_changes(track, report, objects, candidates, looked_unseen)
        self._search_stale = True  # the search did not see these objects
        lapsed = len(track.pairs) < self._min_track_pairs() or self._stale(list(track.pairs))
        followed = None if lapsed else self._follow(track)
        if followed is None or not self._within_prior(track.pose):
            # too little or too old evidence left in the window, the pose no longer fits its
            # newest pairs, or the place left the prior: search again
            self._end_track()
            return self._search_update(objects, answer, start)
        end = time.perf_counter()
        self._add_timing(0.0, 0.0, end - start)
        hypothesis = followed
        hypothesis.confidence = track.current_confidence()
        if looked is not None:
            hypothesis.n_missing, hypothesis.n_expected = looked
        doubted = doubt is not None or track.doubted()
        self._add_step([hypothesis.score], end - start,
                       None if not answer else "ambiguous" if doubted else "localized")  # fmt: skip
        if not answer:
            return None
        if not doubted:
            return self._result("localized", [hypothesis], "", self._changes([hypothesis]))
        # (no more likely than not; the claim is kept and weighed on)
        hypothesis.confidence = min(hypothesis.confidence, 0.5)
        if doubt is None:
            return self._result("ambiguous", [hypothesis], DOUBTED, self._changes([hypothesis]))
        hypotheses = [hypothesis, self._copy_hypothesis(hypothesis, doubt)]
        return self._result("ambiguous", hypotheses, TWIN_DOUBTED, self._changes(hypotheses))

    def _contradicted(
        self, updates: int, objects: list[SemanticObject], answer: bool, start: float
    ):
        """End the claim: search again on the objects of the latest `updates` updates only (the
        older ones may show the place the robot has left), and answer `ambiguous`."""
        self._end_track()
        self.window.keep_only(self.window.since(self.window.updates - updates + 1))
        self._found = {i: f for i, f in self._found.items() if i in self.window}
        self._unseen_of = {}
        return self._search_update(objects, answer, start, reason=CONTRADICTED)

    def _unseen(
        self, pose: np.ndarray, looks: list[tuple[int, Coverage]] | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """The map objects `looks` (default: this update's) expect under `pose`, and those of
        them that no object detected since that look accounts for (`semloc.coverage`: a
        look's update holds every detection in it)."""
        if looks is None:
            assert self._look is not None
            looks = [(self.window.updates, self._look)]
        key = (pose.tobytes(), tuple(update for update, _ in looks))
        if key not in self._unseen_of:  # (the answer's support asks again for its best pose)
            self._unseen_of[key] = self._unseen_now(pose, looks)
        return self._unseen_of[key]

    def _unseen_now(
        self, pose: np.ndarray, looks: list[tuple[int, Coverage]]
    ) -> tuple[np.ndarray, np.ndarray]:
        """`_unseen`, computed: each window object's distances to its candidates are measured
        once for all the looks (`semloc.coverage.Accounting`)."""
        tree = self._tree()
        settings = Looks(move_m=self.config.tracking.move_m)
        positions = self.global_map.positions
        accounting = Accounting(pose, positions, self._allowances(), settings.move_m)
        expected: set[int] = set()
        unseen: set[int] = set()
        for update, look in looks:
            origin = pose[:3, :3] @ look.origin + pose[:3, 3]
            near = np.array(tree.query_ball_point(origin, look.range_m + 0.5), dtype=int)
            seen = expected_objects(pose, [look], positions, self._diagonals(), settings, near)
            expected.update(seen.tolist())
            if len(seen):
                local = [(i, (self._found[i][0].position, self._found[i][1]))
                         for i in self.window.since(update)]  # fmt: skip
                unseen.update(seen[~accounting.accounted(local)[seen]].tolist())
        return np.array(sorted(expected), dtype=int), np.array(sorted(unseen), dtype=int)

    def _tree(self) -> cKDTree:
        """A KD-tree of the map's positions (looks, twins), built when first needed."""
        if self._map_tree is None:
            self._map_tree = cKDTree(self.global_map.positions)
        return self._map_tree

    def _diagonals(self) -> np.ndarray:
        """Each map object's box diagonal (NaN without a box)."""
        if self._diagonal_lengths is None:
            self._diagonal_lengths = np.linalg.norm(self.global_map.sizes, axis=1)
        return self._diagonal_lengths

    def _report_verdict(
        self, track: Track, objects: list[SemanticObject], candidates: dict[str, np.ndarray],
        verdict: Verdict,
    ) -> Verdict:  # fmt: skip
        """This update's objects judged for the run's change report (`tracking.one_to_one`):
        against the claim's pairs of other local objects (before this update's replace them)
        and the map objects the run saw at their place; its contradicting objects are
        tracking's."""
        R, t = track.pose[:3, :3], track.pose[:3, 3]
        now = {o.id for o in objects}
        held = {g: R @ self._found[l][0].position + t
                for l, g in track.pairs.items() if l not in now and l in self._found}  # fmt: skip
        judged = one_to_one(track.pose, objects, candidates, self.global_map.positions,
                            self._allowances(), self.config.tracking.move_m, held,
                            self._run_changes.matched, self._parts())  # fmt: skip
        return Verdict(judged.supported, verdict.contradicting, judged.changed,
                       sources=judged.sources)  # fmt: skip

    def _observe_changes(
        self, track: Track, verdict: Verdict, objects: list[SemanticObject],
        candidates: dict[str, np.ndarray], unseen: np.ndarray,
    ) -> None:  # fmt: skip
        """The run's change report learns what this update's objects said of the claim."""
        run, by_id = self._run_changes, {o.id: o for o in objects}
        R, t = track.pose[:3, :3], track.pose[:3, 3]
        for g, object_id in verdict.supported:
            run.observe_matched(g, object_id)
        for g, object_id in verdict.changed:
            obj = by_id[object_id]
            sources = verdict.sources.get(object_id, [g])
            gaps = np.linalg.norm(
                self.global_map.positions[sources] - (R @ obj.position + t), axis=1
            )
            run.observe_undecided(object_id, dict(zip(sources, gaps.tolist())), obj.seen)
        for obj in objects:
            if not len(candidates[obj.id]):
                run.observe_new(obj.id, obj.seen, unknown_label=True)
            elif obj.id in verdict.contradicting:
                run.observe_new(obj.id, obj.seen)
        run.observe_missing(unseen.tolist())

    def _newest_contradict(self, best: Hypothesis) -> bool:
        """Whether the objects of the latest updates contradict the best place by tracking's
        rule (`semloc.tracking`): a claim is about where the robot is now, and a window that
        spans a kidnap holds a place the robot has left."""
        assert best.pose is not None
        tracking = self.config.tracking
        verdicts = []
        for update in range(self.window.updates - 2, self.window.updates + 1):
            objects = [self._found[i][0] for i in self.window.since(update)
                       if self.window.arrival(i).update == update]  # fmt: skip
            candidates = {o.id: self._found[o.id][1] for o in objects}
            verdicts.append(check(best.pose, objects, candidates, self.global_map.positions,
                                  self._allowances(), tracking.move_m,
                                  part_m=self._parts()))  # fmt: skip
        return recent_contradiction(verdicts, tracking.contradiction)

    def _parts(self) -> np.ndarray:
        """How near (m) to a detection of a map object another one is a part of it (a
        detector's split): half the object's footprint (`tracking.footprints`)."""
        if self._part_m is None:
            self._part_m = 0.5 * footprints(self.global_map)
        return self._part_m

    def _allowances(self) -> np.ndarray:
        if self._allowance is None:
            self._allowance = allowances(self.global_map, self.config.tracking.track_tolerance)
        return self._allowance

    def _stale(self, local_ids: list[str]) -> bool:
        """Whether none of these local objects was detected within `tracking.stale_m` metres of
        travel (a claim is about where the robot is now)."""
        stale_m, window = self.config.tracking.stale_m, self.window
        found = [window.arrival(l).travel for l in local_ids if l in window]
        return stale_m is not None and (not found or window.travel - max(found) > stale_m)

    def _stale_reason(self) -> str:
        return f"{STALE}: none of its objects was detected in the last {self.config.tracking.stale_m:g} m"

    def _min_track_pairs(self) -> int:
        return max(self.config.tracking.track_min_pairs, self.config.decision.min_pairs)

    def _follow(self, track: Track) -> Hypothesis | None:
        """The tracked place refitted to its newest supporting pairs, as the answer's one
        hypothesis (None: the pose no longer fits them)."""
        pairs = track.newest(self.config.tracking.track_pairs)
        locals_ = [self._found[l][0] for _, l in pairs]
        globals_ = [self.global_map[g] for g, _ in pairs]
        l_xyz = np.array([o.position for o in locals_])
        g_xyz = np.array([o.position for o in globals_])
        cfg = self.config.pose
        estimate = estimate_pose(
            l_xyz, g_xyz, [cached_cloud(o, cfg) for o in locals_],
            [cached_cloud(o, cfg) for o in globals_], self.local_up, self.global_map.up, cfg,
            init=track.pose,
        )  # fmt: skip
        if estimate is None:
            return None
        residual = centre_residual(estimate.T, l_xyz, g_xyz)
        if residual > self.config.tracking.track_tolerance:
            return None
        track.pose = estimate.T
        return Hypothesis(
            rank=1,
            score=track.score,
            pairs=[(g.id, l.id) for g, l in zip(globals_, locals_)],
            pose=estimate.T,
            fitness=estimate.fitness,
            rmse=estimate.rmse,
            residual=residual,
            method=f"tracked/{estimate.method}",
            confidence=track.confidence,
            outside_prior=None if self._prior is None else False,
        )

    def _start_track(self, best: Hypothesis) -> None:
        """Track the place found; the search's sets are let go (grown again from the window
        if the claim ends)."""
        assert best.pose is not None
        pairs = [(self.global_map.index_of(g), l) for g, l in best.pairs]
        self._track = Track(best.pose, pairs, best.confidence, best.score, self.config.tracking,
                            self._against)  # fmt: skip
        self._reset_search()
        self._search_stale = True

    def _end_track(self) -> None:
        self._track = None
        self._search_stale = True
        self._track_twins = None  # (found again from the next claim's pairs)
        self._twin_fits.clear()

    def _result(self, status: Status, hypotheses: list[Hypothesis], reason: str, explain) -> Result:
        result = Result.of(status, hypotheses, self._steps, self._timing, reason, explain)
        result.support = self._support_of(hypotheses[0] if hypotheses else None)
        result.prior = self._prior
        index, labelled = self._candidates, self.window.objects  # (read when first asked)
        result.read_labels = lambda: label_report(index, labelled)
        if status == "ambiguous":  # where to look next, computed when first read
            seen = self.window.objects
            labels = [self._map_label(o) for o in seen]
            positions = np.array([o.position for o in seen]).reshape(-1, 3)
            result.suggest = lambda: next_look(
                hypotheses, self.global_map, labels, positions, self.config.next_look
            )
        return result

    def _map_label(self, obj: SemanticObject) -> str:
        """The map's label `obj` is read as (its most similar candidate's; its own without)."""
        _, found, similarity = self._found[obj.id]
        if len(found) == 0:
            return obj.label
        return str(self.global_map.labels[found[int(np.argmax(similarity))]])

    def _support_of(self, best: Hypothesis | None) -> Support | None:
        """How recent the evidence of the best hypothesis is (its local objects' detections)."""
        if best is None or best.pose is None:
            return None
        ids = [l for _, l in best.pairs if l in self.window]
        if not ids:
            return None
        arrivals = [self.window.arrival(l) for l in ids]
        keyframes = [self._found[l][0].seen for l in ids]
        window = self.window
        counts = {} if self._track is None else self._track.counts()
        missing_ids = None
        if self._looks:
            # the looks the count was made on: while tracked, this update's (when it has one)
            newest = (
                self._track is not None and self._look is not None and best.n_missing is not None
            )
            shown, unseen = self._unseen(best.pose, None if newest else list(self._looks))
            if best.n_missing is None:  # (weighed for the refined ones only)
                best.n_missing, best.n_expected = len(unseen), len(shown)
            map_ids = self.global_map.ids
            missing_ids = tuple(str(map_ids[i]) for i in unseen[: Support.MISSING_IDS_KEPT])
        return Support(
            n_pairs=len(ids),
            seen=(min(keyframes), max(keyframes)),
            updates_ago=window.updates - min(a.update for a in arrivals),
            metres=window.travel - min(a.travel for a in arrivals),
            tracked=self._track is not None,
            n_changed=counts.get("changed", 0),
            n_contradicting=counts.get("contradicting", 0),
            n_missing=best.n_missing,
            n_expected=best.n_expected,
            missing_ids=missing_ids,
        )

    def _add_step(self, scores: list[float], seconds: float, status: Status | None) -> None:
        self._steps.append(
            Step(
                step=self._n_steps,
                n_local=len(self.window),
                n_sets=self._clustering.n_sets,
                top_scores=sorted(scores, reverse=True),
                ms=seconds * 1e3,
                status=status,
            )
        )
        self._n_steps += 1

    def _described(self, objects: list[SemanticObject]) -> list[SemanticObject]:
        return objects if self._describer is None else list(self._describer.describe(objects))

    def _register(self, objects: list[SemanticObject]) -> None:
        """The candidates of each new object version (kept while it is in the window)."""
        for obj in objects:
            found, similarity = self._candidates.weighted(obj)
            self._found[obj.id] = (obj, found, similarity)

    def _retrieve(self) -> None:
        """Narrow each window object's candidates to the places that can hold the window
        (`semloc.places`); when an object the search holds gets other candidates than it was
        clustered with, the search regrows from the window."""
        assert self._places is not None
        objects = self.window.objects
        found = [self._prior_gated(o, self._found[o.id][1]) for o in objects]
        positions = np.array([o.position for o in objects]).reshape(-1, 3)
        cfg = self.config.clustering
        support = self._places.support(positions, found, MergeCriterion.of(cfg))
        kept = self._places.kept(support, found)
        retrieved = {o.id: k for o, k in zip(objects, kept)}
        held = {i: self._retrieved[i] for i in self._local if i in self._retrieved}
        if any(not np.isin(retrieved[i], c, assume_unique=True).all() for i, c in held.items()):
            self._search_stale = True  # wider than the search holds: it regrows
        elif held:  # narrower: the held objects keep theirs (their other sets stay apart)
            retrieved.update(held)
        self._retrieved = retrieved

    def _gated(self, obj: SemanticObject, found: np.ndarray) -> np.ndarray:
        """The candidates the clustering gets: those the prior lets `obj` be, in the places
        retrieved for the window (large maps); all without either.  Evidence, verification
        and tracking see all candidates."""
        if self._places is not None and obj.id in self._retrieved:
            return self._retrieved[obj.id]  # (retrieved among the prior's candidates)
        return self._prior_gated(obj, found)

    def _prior_gated(self, obj: SemanticObject, found: np.ndarray) -> np.ndarray:
        """The candidates of `obj` the prior allows (all without a prior)."""
        if self._prior is None:
            return found
        slack = self._gate_slack()[found]
        return found[self._prior.gate(obj.position, self.global_map.positions[found], slack)]

    def _gate_slack(self) -> np.ndarray:
        """Per map object, how far its centre may lie from a detection's (the prior's gate)."""
        if self._prior_slack is None:
            self._prior_slack = allowances(self.global_map, GATE_SLACK)
        return self._prior_slack

    def _changes(self, hypotheses: list[Hypothesis]) -> Callable[[], Changes] | None:
        """What the best hypothesis says changed (`semloc.changes`), computed when first read:
        the window's objects and their candidates are taken now (later updates replace them).
        A tracked place is judged on the objects detected since its oldest pair used, as the
        older ones drifted with the odometry."""
        if self._run_changes and self._track is not None:  # (made when first read)
            run, ids = self._run_changes.copy(), self.global_map.ids
            return lambda: run.report(list(ids))
        if not hypotheses or hypotheses[0].pose is None:
            return None
        local = self.window.objects
        best, config = hypotheses[0], self.config.changes
        if self._track is not None:
            used = {l for _, l in best.pairs}
            oldest = min(self.window.arrival(l).update for l in used)
            local = [o for o in local if self.window.arrival(o.id).update >= oldest]
        candidates = {o.id: self._found[o.id][1] for o in local}
        return lambda: answer_changes(
            self.global_map, local, best.pose, best.pairs, config=config, candidates=candidates
        )

    def _why_no_sets(self) -> str:
        """Why no association set has 2 pairs: too few objects, or too few with candidates."""
        matched = sum(len(c) > 0 for c in self._candidates_of.values())
        if len(self.global_map) == 0:
            return "the global map has no objects"
        if len(self._local) < 2:
            return f"too few local objects: {len(self._local)} seen, 2 needed"
        waiting = [  # retrieval left them nothing, though the prior (if any) left some
            i
            for i, k in self._retrieved.items()
            if len(k) == 0 and len(self._prior_gated(*self._found[i][:2]))
        ]
        if waiting and matched >= 2 and sum(len(k) > 0 for k in self._retrieved.values()) < 2:
            return (
                f"the view so far fits too many places of the map: {len(waiting)} local "
                "object(s) wait for more objects to narrow their places (place retrieval)"
            )
        if self._prior is not None and sum(n > 0 for n in self._gated_of.values()) < 2 <= matched:
            return "too few candidates within the prior: fewer than 2 local objects have one"
        if matched == 0:
            return "no candidates for these labels: no local object has a map object it could be"
        if matched == 1:
            return "only one local object has candidates in the map (2 needed)"
        return "no two local objects have consistent candidates (no set of 2 or more pairs)"

    def _add_timing(self, association: float, clustering: float, pose: float) -> None:
        for key, seconds in (
            ("association", association),
            ("clustering", clustering),
            ("pose", pose),
            ("total", association + clustering + pose),
        ):
            self._timing[key] += seconds * 1e3

    def _associate(self, objects: list[SemanticObject]) -> dict[int, np.ndarray]:
        """Register objects with the search; return candidate global indices per local index."""
        detections: dict[int, np.ndarray] = {}
        for obj in objects:
            index = self._local_index.setdefault(obj.id, len(self._local_index))
            if obj.id in self._local:  # re-detected: poses that used the old version are stale
                self._poses = {
                    k: v for k, v in self._poses.items() if all(l != index for _, l in k[1])
                }
            self._local[obj.id] = obj
            _, found, self._similarity_of[index] = self._found[obj.id]
            self._candidates_of[index] = found
            self._support.assign(index, found)
            detections[index] = self._gated(obj, found)
            self._gated_of[index] = len(detections[index])
        return detections

    # Hypotheses -------------------------------------------------------------------------
    def _hypotheses(self) -> list[Hypothesis]:
        """Distinct places, best first: verify many sets by closed-form consensus, recover the
        poses of the top-k, measure their evidence, rank, merge duplicates, attach confidence."""
        cfg = self.config
        by_size = cfg.rank_by in ("residual", "evidence")
        sets, cut = self._screened_sets(by_size)
        local_xyz = np.array([o.position for o in self._local.values()]).reshape(-1, 3)
        screened = [c for c in self._verified_all(sets, local_xyz) if len(c.pairs) >= 2]
        if by_size:  # pairs include the guided matches
            screened.sort(key=lambda c: (-len(c.pairs), round(c.residual, 9), -c.score))
        places = [(c.pairs, c.pose) for c in screened]
        anchor = local_anchor(local_xyz)
        picked = distinct(places, cfg.top_k + 1, cfg.decision, anchor)
        best = (len(screened[0].pairs), screened[0].residual) if screened else (0, 0.0)
        if by_size and len(picked) > cfg.top_k:  # a place left out: as good as the best?
            left = screened[picked[-1]]
            cut |= as_well_supported(len(left.pairs), left.residual, best, cfg.decision)
        self._cut = (cut, best[0])
        chosen = [screened[i] for i in picked[: cfg.top_k]]
        previous, self._poses = self._poses, {}
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
        if self._prior is not None:  # conditioned on the prior: rivals outside it do not count
            for h in ranked:
                h.outside_prior = h.pose is not None and not self._prior.admits(h.pose)
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
        up = self.global_map.up
        if best is None or best.pose is None or best.confidence is None or up is None:
            return [], []
        if best.confidence < self.config.decision.min_confidence:
            return [], []
        positions, codes, tree = self.global_map.positions, self._codes(), self._tree()
        tolerance = self.config.verification.inlier_tolerance
        pairs = [(self.global_map.index_of(g), self._local_index[l]) for g, l in best.pairs]
        members = np.array([g for g, _ in pairs])
        sets, listed = [], []
        for S in self._twin_motions_of(members):
            place: tuple[list, np.ndarray] = ([], S @ best.pose)
            if any(same_place(place, (h.pairs, h.pose), self.config.decision, anchor)
                   for h in ranked[1:]):  # fmt: skip
                listed.append(place)  # (weighed already)
                continue
            moved = twin_pairs(S, pairs, positions, codes, tolerance, tree)
            moved = [(g, l) for g, l in moved if g in self._candidates_of[l]]
            if len(moved) >= MIN_TWIN_PAIRS:
                sets.append(moved)
        if not sets:
            return [], listed
        rows = np.array([p for pairs_ in sets for p in pairs_], dtype=np.int64)
        sizes = np.array([len(p) for p in sets], dtype=np.int64)
        verified = verify_sets(
            rows, sizes, np.full(len(sets), best.score), local_xyz, positions,
            (self.local_up, up), self.config.verification, self._support,
        )  # fmt: skip
        found = [self._hypothesis(1, v, local_xyz, previous)  # (refined as the best is)
                 for v in verified if len(v.pairs) >= 2]  # fmt: skip
        return found, listed

    def _codes(self) -> np.ndarray:
        if self._label_codes is None:
            self._label_codes = label_codes(self.global_map.labels)
        return self._label_codes

    def _twin_motions_of(self, members: np.ndarray, anchors: int = ANCHORS) -> list[np.ndarray]:
        """The twins of the map objects `members` (`semloc.twins`, through `anchors` anchor
        pairs), kept for the latest `TWINS_KEPT` sets of members: a set that shares most of
        its members with a kept one is the same place (grown by an object or two) and has its
        copies."""
        found = tuple(sorted(members.tolist()))
        key = (anchors, *found)
        for kept in reversed(self._twin_motions):
            same = kept[0] == anchors and len(set(kept[1:]) & set(found))
            if same and same >= 0.75 * max(len(found), len(kept) - 1):
                return self._twin_motions[kept]
        if key not in self._twin_motions:
            if len(self._twin_motions) >= TWINS_KEPT:
                self._twin_motions.pop(next(iter(self._twin_motions)))
            up = self.global_map.up
            self._twin_motions[key] = [] if up is None else twins(
                self.global_map.positions, self._codes(), up, members,
                self.config.verification.inlier_tolerance, tree=self._tree(), apart=PLACE_APART,
                most=TWINS_WEIGHED, anchors=anchors,
            )  # fmt: skip
        return self._twin_motions[key]

    def _carried_to_twin(
        self,
        track: Track,
        verdict: Verdict,
        objects: list[SemanticObject],
        candidates: dict,
        unseen: np.ndarray,
    ) -> tuple[int, int, np.ndarray | None]:
        """By how many objects the latest updates show the robot in a copy of the tracked
        place rather than in it, over how many updates, and that copy (a map motion; (0, 0,
        None): no copy leads).  A look-alike room differs from the tracked one where one of them lacks
        an object, so per copy (`semloc.twins` of the claim's newest pairs: the copies of where
        the robot is) each update weighs the objects that tell the two apart.  For the copy: a
        detection the place does not explain (changed or contradicting) that lies where the
        copy holds a map object it may be, and, with the sensor's coverage, a map object the
        look expects of the place (`unseen`: none accounts for it) where the copy holds none
        of its label.  For the place: a supporting detection where the copy holds no map
        object it may be (`semloc.twins.copy_leads`).  Only the updates with such objects
        are kept (`TWIN_UPDATES` of them): a robot carried off may see nothing that tells
        the rooms apart for a while, and nothing seen is no news.  The copies are looked up
        again when the robot walked on (the claim's newest pairs changed) and an update has
        objects against the place or missing from its look, or a copy leads."""
        against = {l for _, l in verdict.changed} | set(verdict.contradicting)
        members = np.array([g for g, _ in track.newest(self.config.tracking.track_pairs)])
        held = self._track_twins[0] if self._track_twins else np.zeros(0, dtype=int)
        if np.isin(members, held).sum() < 0.5 * len(members):  # the robot walked on
            leading = bool(self._twin_fits) and self._copy_lead()[0] > 0
            if not against and not len(unseen) and not leading:
                return 0, 0, None
            old = self._track_twins[1] if self._track_twins else []
            self._track_twins = (members, self._twin_motions_of(members, TRACK_ANCHORS))
            self._carry_fits(old, self._track_twins[1], track.pose[:3, 3])
        motions = self._track_twins[1]
        if not motions:
            return 0, 0, None
        R, t, ids, codes = track.pose[:3, :3], track.pose[:3, 3], self.global_map.ids, self._codes()
        by_id = {o.id: o for o in objects}
        # (where, the kinds it may be, key, whether it is evidence when the copy holds it)
        placed = [(R @ by_id[l].position + t, codes[candidates[l]], f"+local {l}", True)
                  for l in against]  # fmt: skip
        placed += [(R @ by_id[l].position + t, codes[candidates[l]], f"-map {ids[g]}", False)
                   for g, l in verdict.supported]  # fmt: skip
        placed += [(self.global_map.positions[u], codes[[u]], f"+map {ids[u]}", False)
                   for u in unseen]  # fmt: skip
        where = (self.global_map.positions, codes, self._allowances(), self._tree())
        told = [[key for at, kinds, key, if_held in placed
                 if copy_holds(S, at, kinds, *where) == if_held] for S in motions]  # fmt: skip
        if any(told):
            self._twin_fits.append((self.window.updates, told))
        lead, updates, best = self._copy_lead()
        return (lead, updates, motions[best]) if lead > 0 else (0, 0, None)

    def _copy_lead(self) -> tuple[int, int, int]:
        """The kept evidence's lead of the best copy over the tracked place, how many of the
        latest updates it spans, and that copy's index (`semloc.twins.twin_lead`)."""
        lead, kept, best = twin_lead([told for _, told in self._twin_fits])
        if lead <= 0:
            return 0, 0, 0
        return lead, self.window.updates - self._twin_fits[-kept][0] + 1, best

    def _carry_fits(self, old: list[np.ndarray], new: list[np.ndarray], at: np.ndarray) -> None:
        """The kept evidence of the copies `old`, for the copies `new` of the place the robot
        walked on to: a copy is the same when it puts the robot (`at`) within `PLACE_APART`
        of where the other does; a new copy has none."""
        moved = [S[:3, :3] @ at + S[:3, 3] for S in old]
        same = [next((i for i, m in enumerate(moved)
                      if np.linalg.norm(S[:3, :3] @ at + S[:3, 3] - m) < PLACE_APART), None)
                for S in new]  # fmt: skip
        kept = [(update, [[] if i is None else told[i] for i in same])
                for update, told in self._twin_fits]  # fmt: skip
        self._twin_fits.clear()
        self._twin_fits.extend((u, told) for u, told in kept if any(told))

    def _copy_hypothesis(self, place: Hypothesis, S: np.ndarray) -> Hypothesis:
        """The copy `S` (a map motion) of a tracked place, as its rival: the place's pairs
        moved onto the copy's objects, the place's pose moved by `S`."""
        assert place.pose is not None
        index, ids = self.global_map.index_of, self.global_map.ids
        moved = twin_pairs(
            S, [(index(g), i) for i, (g, _) in enumerate(place.pairs)], self.global_map.positions,
            self._codes(), self.config.verification.inlier_tolerance, self._tree(),
        )  # fmt: skip
        pairs = [(str(ids[g]), place.pairs[i][1]) for g, i in moved]
        return Hypothesis(rank=2, score=float(len(pairs)), pairs=pairs, pose=S @ place.pose,
                          method="copy")  # fmt: skip

    def _screened_sets(self, by_size: bool) -> tuple[SetPairs, bool]:
        """The sets screened for hypotheses, and whether the screening was cut.  Ranked by
        size: the `screened_sets` best; in a building (a map place retrieval narrows), then
        each further set as large as the largest whose map objects lie in a region no
        screened set covers (`new_regions`), up to `screened_sets` more: variants of one place
        (chairs swapped) must not crowd its copies elsewhere out.  More new regions than that:
        cut.  Smaller maps screen as they always did (their confidence is calibrated so)."""
        cfg = self.config
        limit = cfg.screened_sets
        if not by_size or self._places is None:
            return self._clustering.top_pairs(limit, min_size=2, largest_first=by_size), False
        sets = self._clustering.top_pairs(self._clustering.n_sets, 2, largest_first=True)
        if len(sets.sizes) <= limit:
            return sets, False
        largest = int(np.searchsorted(-sets.sizes, -sets.sizes[0], side="right"))
        ends = np.cumsum(sets.sizes[:largest])
        centroids = np.add.reduceat(self.global_map.positions[sets.pairs[: ends[-1], 0]],
                                    ends - sets.sizes[:largest]) / sets.sizes[:largest, None]  # fmt: skip
        extra = new_regions(centroids, limit, most=limit + 1)
        rows = np.concatenate([np.arange(limit), extra[:limit]])
        return _rows_of(sets, rows), len(extra) > limit

    def _verified_all(self, sets: SetPairs, local_xyz: np.ndarray) -> list[Verified]:
        """Each set verified against the map (`semloc.verification.verify_sets`)."""
        return verify_sets(
            sets.pairs, sets.sizes, sets.scores, local_xyz, self.global_map.positions,
            (self.local_up, self.global_map.up), self.config.verification, self._support,
        )  # fmt: skip

    def _hypothesis(
        self, rank: int, verified: Verified, local_xyz: np.ndarray, previous: dict,
        lazy: bool = False,
    ) -> Hypothesis:  # fmt: skip
        """A verified set's inlier pairs with their pose and evidence: refined (robust ICP)
        when among the `refine_top` first, unless `lazy` (then when `Hypothesis.refine` asks);
        the others keep the closed form's (or search's) pose unless asked."""
        local_objects = list(self._local.values())
        globals_ = [self.global_map[g] for g, _ in verified.pairs]
        locals_ = [local_objects[l] for _, l in verified.pairs]
        l_xyz = np.array([o.position for o in locals_])
        g_xyz = np.array([o.position for o in globals_])
        ids = self.global_map.ids
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
        if pose is not None and self._looks and refine:  # (the places that decide)
            seen, unseen = self._unseen(pose, list(self._looks))
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
            if self._prior is None and cfg.rank_by == "evidence":
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
        if best.pose is None or best.confidence is None or self.global_map.up is None:
            return False
        if best.confidence < self.config.decision.min_confidence:
            return False
        members = np.array([self.global_map.index_of(g) for g, _ in best.pairs])
        return bool(self._twin_motions_of(members))

    def _semantic_weight(self, pairs: list[tuple[int, int]]) -> float:
        """The summed evidence weight (`semantics.pair_weight`) of (global, local) index pairs."""
        total = 0.0
        for g, l in pairs:
            candidates = self._candidates_of.get(l, np.zeros(0, dtype=int))
            at = int(np.searchsorted(candidates, g))
            found = at < len(candidates) and candidates[at] == g
            total += float(pair_weight(self._similarity_of[l][at])) if found else 1.0
        return total

    def label_report(self) -> dict[str, LabelResolution]:
        """How each label of the local objects so far was read against the map's labels."""
        return label_report(self._candidates, self.window.objects)


_PoseKey = tuple[bool, frozenset[tuple[int, int]]]  # (refined, pairs)


class _Recovery:
    """The pose of one set's pairs, refined or not, for the Localizer's current answer:
    reused when the previous answer recovered it for the same pairs (same object versions),
    else recovered once (`semloc.pose.recover_pose`), warm-started from the pose of the
    largest subset of its pairs that the previous answer recovered (refined ones first),
    and refined (robust ICP) only when asked.  Each estimate given is kept for the next
    answer (`Localizer._poses` of this answer: a re-detection since drops them)."""

    def __init__(
        self, localizer: Localizer, pairs: list[tuple[int, int]], previous: dict, matched: tuple
    ) -> None:
        self.localizer, self.previous, self.matched = localizer, previous, matched
        self.kept = localizer._poses  # this answer's (a refinement asked later lands there)
        self.pairs = frozenset(pairs)
        self._recovery: PoseRecovery | None = None
        self._recovered = False

    def estimate(self, refine: bool) -> PoseEstimate | None:
        key: _PoseKey = (refine, self.pairs)
        if key in self.previous:
            estimate = self.previous[key]
        else:
            recovery = self._recover()
            cfg = self.localizer.config.pose
            estimate = None if recovery is None else recovery.estimate(refine and cfg.refine)
        self.kept[key] = estimate
        return estimate

    def _recover(self) -> PoseRecovery | None:
        if not self._recovered:
            l_xyz, g_xyz, locals_, globals_ = self.matched
            localizer = self.localizer
            cfg = localizer.config.pose
            self._recovery = recover_pose(
                l_xyz, g_xyz, [cached_cloud(o, cfg) for o in locals_],
                [cached_cloud(o, cfg) for o in globals_], localizer.local_up,
                localizer.global_map.up, cfg, init=_warm_start(self.pairs, self.previous),
            )  # fmt: skip
            self._recovered = True
        return self._recovery


def _checked_objects(objects: Any) -> list[SemanticObject]:
    """The objects of an update: SemanticObjects, each id once (else MapError / TypeError)."""
    if isinstance(objects, (str, bytes)) or not isinstance(objects, Iterable):
        raise TypeError(f"update() takes SemanticObjects, got {type(objects).__name__}")
    objects = list(objects)
    ids: set[str] = set()
    for obj in objects:
        if not isinstance(obj, SemanticObject):
            raise MapError(f"update() takes SemanticObject items, got {type(obj).__name__}")
        if obj.id in ids:
            raise MapError(f"update(): object '{obj.id}' occurs more than once")
        ids.add(obj.id)
    return objects


def _robot_position(position: Any) -> np.ndarray | None:
    """The robot's position from a point (3,) or a pose (4, 4); None stays None."""
    if position is None:
        return None
    array = np.asarray(position, dtype=float)
    if array.shape == (4, 4):
        array = array[:3, 3]
    if array.shape != (3,) or not np.all(np.isfinite(array)):
        raise ValueError(f"position must be a finite point (3,) or pose (4, 4), got {array.shape}")
    return array


def _warm_start(pairs: frozenset, previous: dict[_PoseKey, PoseEstimate | None]):
    """The pose of the largest recovered subset of `pairs` (refined first), or None."""
    subsets = [
        (len(k[1]), k[0], estimate.T)
        for k, estimate in previous.items()
        if estimate is not None and k[1] <= pairs
    ]
    return max(subsets, key=lambda s: s[:2])[2] if subsets else None


EMPTY_LOCAL_MAP = "the local map has no objects"
LOOKS_KEPT = 6
"""The search weighs the sensor's looks of this many latest updates (negative evidence)."""
TWIN_KIDNAP = 2
"""By how many objects of the latest updates a copy of the tracked place must explain them
better than the place (`Localizer._carried_to_twin`) to end the claim; leading by less, the
copy makes the answer `ambiguous` (`TWIN_DOUBTED`) and the claim is weighed on: an old map's
change or a detector's error is as likely to speak for the copy as against it, and the robot
carried into a copy must not be claimed where it was while the evidence says otherwise."""
TWIN_DOUBTED = "a copy of the tracked place explains the latest objects better"
DOUBTED = "the newest objects speak against the tracked place"
"""The reason of a tracked place's answer doubted by its newest objects (`Track.doubted`)."""
TWIN_UPDATES = 12
"""The latest updates with objects that tell the tracked place from a copy weighed for it
(`TWIN_KIDNAP`): a view shows what tells look-alike rooms apart one object at a time, often
several updates apart."""
TRACK_ANCHORS = 8
"""Anchor pairs tried for the copies of a tracked place (`semloc.twins.ANCHORS` before a
claim): the copy the robot may be carried into must be among them, and a tracked place looks
its copies up only when its objects change; a copy keeping a random 70 % of the objects is
missed about once in 200 (three pairs: once in eight)."""
TWINS_WEIGHED = 4
"""The copies of a place weighed: those that hold most of its objects."""
TWINS_KEPT = 64
"""The twins (`semloc.twins`) of this many latest claimable places are kept, not looked up
again."""
NEWEST_CONTRADICT = "contradicted by the newest objects"
STALE = "stale evidence"
"""The reason (its start) of a search's answer whose best place was not seen of late
(`tracking.stale_m`)."""
"""The reason of a search's answer whose best place the latest updates' objects contradict."""
STATE_VERSION = 1
"""The layout of `Localizer.state()`."""


def _rows_of(sets: SetPairs, rows: np.ndarray) -> SetPairs:
    """The sets at `rows` (ascending) of `sets`."""
    starts = np.concatenate([[0], np.cumsum(sets.sizes)[:-1]])
    pairs = [sets.pairs[starts[r] : starts[r] + sets.sizes[r]] for r in rows]
    return SetPairs(np.concatenate(pairs), sets.sizes[rows], sets.scores[rows])


def localize(
    global_map: ObjectMap,
    local_map: ObjectMap,
    config: LocalizerConfig | None = None,
    *,
    progress: Callable[[int, int], None] | None = None,
    prior: Prior | None = None,
    **overrides: Any,
) -> Result:
    """Replay `local_map` by its `seen` keyframes (one update per keyframe); the last Result.
    `prior`: where the local frame's origin lies in the global map (`semloc.Prior`).

    Only the last update builds hypotheses and recovers poses: the answers in between would
    not be read.  `progress(done, total)` is called after each update.
    """
    if not isinstance(local_map, ObjectMap):
        raise TypeError(f"localize needs an ObjectMap as local map, got {type(local_map).__name__}")
    localizer = Localizer(global_map, config, local_up=local_map.up, prior=prior, **overrides)
    keyframes = sorted(set(local_map.seen.tolist()))
    if not keyframes:
        return Result("failed", None, [], reason=EMPTY_LOCAL_MAP, prior=prior)
    by_keyframe: dict[int, list[SemanticObject]] = {k: [] for k in keyframes}
    for obj in local_map:  # grouped once: a long replay must not rescan the map per keyframe
        by_keyframe[obj.seen].append(obj)
    for done, keyframe in enumerate(keyframes[:-1], start=1):
        localizer.update(by_keyframe[keyframe], answer=False)
        if progress is not None:
            progress(done, len(keyframes))
    result = localizer.update(by_keyframe[keyframes[-1]])
    assert result is not None  # an update with an answer returns one
    if progress is not None:
        progress(len(keyframes), len(keyframes))
    return result
