"""The Localizer: a run's object-level relocalization, one update of local objects at a time.

`Localizer(global_map, config)` composes the parts that each own their state:

* what the robot has seen (`semloc.sightings.Sightings`): the window of local objects
  (`semloc.window`), each with its map candidates, and the sensor's latest looks;
* the search (`semloc.search.Search`): the paper's association sets grown over the window, the
  hypotheses and the verdict, with the map's look-alike copies and a position prior weighed;
* the tracked place once a place is `localized` (`semloc.tracking.Track`): checked on every
  new object, followed through odometry drift, doubted or ended when the evidence turns
  against it, with its look-alike copies watched (`semloc.copy_watch.CopyWatch`) and the
  run's change report fed (`semloc.changes.RunChanges`).

`add(objects)` feeds new or re-detected local objects (same id = updated) without answering;
`update(objects)` feeds them and answers (`Result`).  While a place is tracked the search is
idle; when the claim ends or lapses it regrows from the window.  What is read off the map
alone is computed once (`semloc.map_context.MapContext`), so a Localizer's updates cost what
the new objects ask.

A position prior (`semloc.priors.Prior`: `Localizer(..., prior=P)`, `set_prior`) gates the
candidates of each local object and marks the hypotheses whose pose lies outside it, which
cannot be `localized`; a tracked place that leaves it ends the claim.

`localize(global_map, local_map)` replays a local map by its `seen` keyframes.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable, Iterable
from typing import Any, Literal, overload

import numpy as np

from semloc.association import Describer, LabelResolution, label_report
from semloc.changes import Changes, RunChanges
from semloc.copy_watch import TWIN_DOUBTED, TWIN_KIDNAP, CopyWatch
from semloc.coverage import Coverage
from semloc.map_context import MapContext
from semloc.maps import ObjectMap, SemanticObject, unit_vector
from semloc.priors import Prior, checked_prior
from semloc.results import Hypothesis, Result, Status, UpdateLog
from semloc.search import Search
from semloc.settings import LocalizerConfig
from semloc.sightings import Sightings, checked_objects, robot_position
from semloc.tracking import CONTRADICTED, DOUBTED, AgainstRate, Track
from semloc.window import LocalWindow

EMPTY_LOCAL_MAP = "the local map has no objects"
STATE_VERSION = 1
"""The layout of `Localizer.state()`."""


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
        self.config = config = LocalizerConfig.of(config, overrides)
        self._context = MapContext(global_map, config, describer or config.association.describer())
        self.global_map = self._context.map
        self.descriptor_gate = self._context.descriptor_gate
        self.local_up = None if local_up is None else unit_vector(local_up, "local_up")
        self._sightings = Sightings(self._context, config.window)
        self._prior = checked_prior(prior)
        self._search = Search(self._context, self._sightings, self._prior, self.local_up)
        self._track: Track | None = None
        self._copies: CopyWatch | None = None  # the tracked place's look-alike copies
        self._run_changes = RunChanges()  # what changed, over the run's tracked claims
        self._against = AgainstRate()  # how often the run's claims judged objects against
        self._log = UpdateLog(config.window.steps)  # the latest steps, the time spent

    @property
    def window(self) -> LocalWindow:
        """The local objects the Localizer works on (`semloc.window`)."""
        return self._sightings.window

    @property
    def local_map(self) -> ObjectMap:
        """The local objects of the window (latest version of each, oldest detection first)."""
        return ObjectMap(self.window.objects, up=self.local_up, name="local")

    @property
    def tracking(self) -> bool:
        """Whether a found place is being tracked (the last answer was `localized`)."""
        return self._track is not None

    @property
    def prior(self) -> Prior | None:
        """The position prior in effect (None: none); `set_prior` changes it."""
        return self._prior

    @property
    def n_sets(self) -> int:
        """How many association sets the search holds."""
        return self._search.n_sets

    def set_prior(self, prior: Prior | None) -> None:
        """Use `prior` from the next update on (None removes it): the window's candidates are
        gated anew and the search regrows; a tracked place outside the new prior is let go."""
        self._prior = checked_prior(prior)
        self._search.prior, self._search.stale = self._prior, True  # regrows, gated anew
        if self._track is not None and not self._within_prior(self._track.pose):
            self._end_track()

    def _within_prior(self, pose: np.ndarray) -> bool:
        return self._prior is None or self._prior.admits(pose)

    def prepare(self) -> Localizer:
        """Prepare every map object's point cloud now, not when a localization first needs it
        (once per loaded map, for all its Localizers: before time-critical use); returns self."""
        self._context.prepare()
        return self

    # State ------------------------------------------------------------------------------
    def state(self) -> dict[str, Any]:
        """What rebuilds this Localizer besides its window's objects (`local_map`), in JSON
        types: the window's bookkeeping, the tracked place, the kept steps and timing.
        `Localizer.restore` takes it back; the restored Localizer answers as this one would
        while it tracks a place, and otherwise clusters its window anew at its next update
        (the same objects in one batch instead of the updates they came in)."""
        ids = list(self.global_map.ids)
        return {
            "version": STATE_VERSION,
            **self._sightings.state(),  # window, looks
            "track": None if self._track is None else self._track.state(ids),
            "changes": self._run_changes.state(ids),
            "against": [self._against.against, self._against.judged],
            "twins": None if self._copies is None else self._copies.state(),
            **self._log.state(),  # steps, n_steps, timing
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
            localizer._restore(state, localizer._context.described(list(objects)))
        except (KeyError, TypeError, IndexError) as exc:
            raise ValueError(f"the Localizer state is malformed ({exc!r})") from None
        localizer._search.stale = True
        return localizer

    def _restore(self, state: dict[str, Any], objects: list[SemanticObject]) -> None:
        index_of = self.global_map.index_of
        self._sightings.restore(state, objects)
        self._against = AgainstRate(*map(float, state.get("against", [0.0, 0.0])))
        if state["track"] is not None:
            self._track = Track.restored(state["track"], index_of, self.config.tracking,
                                         self._against)  # fmt: skip
            self._copies = CopyWatch(self._context, self.config.tracking.track_pairs)
            self._copies.restore(state.get("twins"), self.window.updates)
        self._run_changes = RunChanges.restored(state.get("changes", {}), index_of)
        self._log.restore(state)

    # Updates ----------------------------------------------------------------------------
    def add(
        self,
        objects: Iterable[SemanticObject] | ObjectMap,
        *,
        position: Any = None,
        coverage: Coverage | None = None,
    ) -> None:
        """Add new or re-detected local objects without an answer: the association sets grow
        (no hypotheses, no pose recovery, no decision), a tracked place is checked; a later
        `update` answers on the same sets.  For callers that read only some answers (a replay
        reads its last one)."""
        self._update(objects, False, position, coverage)

    @overload
    def update(
        self, objects: Iterable[SemanticObject] | ObjectMap, answer: Literal[True] = True, *,
        position: Any = None, coverage: Coverage | None = None,
    ) -> Result: ...  # fmt: skip

    @overload
    def update(
        self, objects: Iterable[SemanticObject] | ObjectMap, answer: Literal[False], *,
        position: Any = None, coverage: Coverage | None = None,
    ) -> None: ...  # fmt: skip

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
        `answer=False` is deprecated: use `add`, which it calls.
        """
        if not answer:
            warnings.warn("Localizer.update(..., answer=False) is deprecated: use "
                          "Localizer.add(...)", DeprecationWarning, stacklevel=2)  # fmt: skip
        return self._update(objects, answer, position, coverage)

    def _update(self, objects: Any, answer: bool, position: Any, coverage: Any) -> Result | None:
        start = time.perf_counter()
        if isinstance(objects, ObjectMap) and objects.up is not None and self.local_up is None:
            self.local_up = self._search.local_up = objects.up
        objects = self._context.described(checked_objects(objects))
        objects, retired = self._sightings.add(objects, robot_position(position), coverage)
        if retired:
            self._search.stale = True
        if self._track is not None:
            self._track.keep_only(self._sightings.found)
            return self._track_update(objects, answer, start)
        return self._search_update(objects, answer, start)

    def _search_update(
        self, objects: list[SemanticObject], answer: bool, start: float, reason: str = ""
    ) -> Result | None:
        """Grow the association sets of the window and decide (the paper's method).  A given
        `reason` overrides a `localized` decision (the answer that ended a tracked claim)."""
        search = self._search
        if self._context.places is not None:
            search.retrieve()
        if search.stale:  # the window changed without it: grown again from the window
            search = self._search = search.renewed()
            objects = self.window.objects
        detections = search.associate(objects)
        tick = time.perf_counter()
        search.cluster(detections)
        tock = time.perf_counter()
        status: Status | None = None
        hypotheses: list[Hypothesis] = []
        if answer:
            hypotheses = search.hypotheses()
            status, why = search.decide(hypotheses)
            status, reason = ("ambiguous", reason) if reason else (status, why)
            scores = [h.score for h in hypotheses]
        else:
            scores = search.clustering.top_scores(self.config.top_k, min_size=2)
        end = time.perf_counter()
        self._log.spent(tick - start, tock - tick, end - tock)
        self._add_step(scores, end - start, status)
        if status is None:
            return None
        hypotheses = hypotheses[: self.config.top_k]  # (twins weighed beyond it: not listed)
        result = self._result(status, hypotheses, reason)
        if status == "localized" and self.config.tracking.track:
            self._start_track(hypotheses[0])
        return result

    def _track_update(self, objects: list[SemanticObject], answer: bool, start: float):
        """Check the tracked place on the new objects; follow it, doubt it, or end the claim."""
        track, sightings, context = self._track, self._sightings, self._context
        assert track is not None and self._copies is not None
        candidates = sightings.candidates(objects)
        verdict, unseen, expected = track.check(sightings, objects)
        against, copy = track.contradicted(verdict), None
        if not against:
            lead, updates, copy = self._copies.weigh(
                self.window.updates, track, verdict, objects, candidates, unseen
            )
            against = updates if lead >= TWIN_KIDNAP else 0
        if against:  # a fresh window of the contradicting updates' objects, searched
            self._end_track()
            sightings.keep_latest(against)
            return self._search_update(objects, answer, start, reason=CONTRADICTED)
        report = track.judged_one_to_one(sightings, objects, verdict, self._run_changes.matched)
        track.accept(verdict)
        self._run_changes.observe_update(report, objects, candidates, unseen, track.pose,
                                         context.map.positions)  # fmt: skip
        self._search.stale = True  # the search did not see these objects
        min_pairs = max(self.config.tracking.track_min_pairs, self.config.decision.min_pairs)
        followed = track.follow(sightings, min_pairs, self.local_up, self._prior is not None)
        if followed is None or not self._within_prior(track.pose):
            # too little or too old evidence left in the window, the pose no longer fits its
            # newest pairs, or the place left the prior: search again
            self._end_track()
            return self._search_update(objects, answer, start)
        end = time.perf_counter()
        self._log.spent(0.0, 0.0, end - start)
        followed.confidence = track.current_confidence()
        if expected is not None:
            followed.n_missing, followed.n_expected = len(unseen), expected
        doubted = copy is not None or track.doubted()
        self._add_step([followed.score], end - start,
                       None if not answer else "ambiguous" if doubted else "localized")  # fmt: skip
        if not answer:
            return None
        if not doubted:
            return self._result("localized", [followed], "")
        followed.confidence = min(followed.confidence, 0.5)  # (the claim is weighed on)
        if copy is None:
            return self._result("ambiguous", [followed], DOUBTED)
        return self._result("ambiguous", [followed, self._copies.rival(followed, copy)],
                            TWIN_DOUBTED)  # fmt: skip

    def _start_track(self, best: Hypothesis) -> None:
        """Track the place found; the search's sets are let go (grown again from the window
        if the claim ends)."""
        assert best.pose is not None
        pairs = [(self.global_map.index_of(g), l) for g, l in best.pairs]
        self._track = Track(best.pose, pairs, best.confidence, best.score, self.config.tracking,
                            self._against)  # fmt: skip
        self._copies = CopyWatch(self._context, self.config.tracking.track_pairs)
        self._search = self._search.renewed()
        self._search.stale = True

    def _end_track(self) -> None:
        self._track = self._copies = None
        self._search.stale = True

    # Answers ----------------------------------------------------------------------------
    def _result(self, status: Status, hypotheses: list[Hypothesis], reason: str) -> Result:
        result = Result.of(status, hypotheses, self._log.steps, self._log.timing, reason,
                           self._changes(hypotheses))  # fmt: skip
        counts = None if self._track is None else self._track.counts()
        result.support = self._sightings.support_of(hypotheses[0] if hypotheses else None, counts)
        result.prior = self._prior
        index, labelled = self._context.candidates, self.window.objects  # (read when first asked)
        result.read_labels = lambda: label_report(index, labelled)
        if status == "ambiguous":  # where to look next, computed when first read
            result.suggest = self._sightings.next_look(hypotheses, self.config.next_look)
        return result

    def _changes(self, hypotheses: list[Hypothesis]) -> Callable[[], Changes] | None:
        """What changed (`semloc.changes`), computed when first read: while a place is
        tracked, the run's report; else what the best hypothesis says."""
        if self._run_changes and self._track is not None:  # (made when first read)
            run, ids = self._run_changes.copy(), self.global_map.ids
            return lambda: run.report(list(ids))
        best = hypotheses[0] if hypotheses else None
        return self._sightings.changes_of(best, self._track is not None, self.config.changes)

    def _add_step(self, scores: list[float], seconds: float, status: Status | None) -> None:
        self._log.add(scores, seconds, status, len(self.window), self._search.n_sets)

    def label_report(self) -> dict[str, LabelResolution]:
        """How each label of the local objects so far was read against the map's labels."""
        return label_report(self._context.candidates, self.window.objects)


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
        localizer.add(by_keyframe[keyframe])
        if progress is not None:
            progress(done, len(keyframes))
    result = localizer.update(by_keyframe[keyframes[-1]])
    if progress is not None:
        progress(len(keyframes), len(keyframes))
    return result
