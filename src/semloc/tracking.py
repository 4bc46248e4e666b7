"""Staying at a place once it is found: check the tracked pose on every update's objects, follow
odometry drift, tell changes of an old map from contradictions, and end the claim as soon as
the evidence turns against it.

After a `localized` answer the Localizer tracks that place instead of searching again (the
search's cost grows with the local objects; tracking costs a lookup per new object):

* **Check.**  Each new or re-detected object with map candidates is put where the tracked pose
  says it is.  It *supports* the place when a candidate lies within `track_tolerance` plus a
  quarter of that candidate's diagonal (a partial view moves a large object's centre) of that
  point; it is *changed* when the nearest candidate lies farther but within `move_m` (a moved
  chair of an old map); otherwise it *contradicts* the place.  A map object supports one
  object of the update, the nearest: two chairs of one view are not one chair of the map (a
  wrong place's few chairs would otherwise explain a view of many); the other, unless it lies
  within half the map object's footprint of the first (a detector's split: a part, it says
  nothing), is judged on its other candidates.  Objects without candidates say
  nothing (a label the map does not hold: new).  A re-detection of an object already paired
  with the same map object is the same evidence again: it refreshes the pair for the pose but
  counts as half a supporting object in the decision, so that re-detections of paired objects
  never outvote new objects that contradict the place.
* **The change report's judgement.**  The check above weighs a place; what changed is told
  one to one (`one_to_one`, fed to `semloc.changes.RunChanges`): nearest first, each map
  object explains one object, of this update or of the claim's other pairs, so that a moved
  chair standing by another chair that its own detection holds is not that chair, and
  re-takes the nearest free candidate instead; a map object the run saw at its place is no
  one's source.  A changed object with several free candidates within `move_m` lists them
  all as its sources: which one moved is decided later, if ever.  Only the report reads this
  judgement; the place is weighed on the check's, as before.
* **Missing.**  When the update says what the sensor covered (`semloc.coverage`), the map
  objects the place puts well inside that look that no window object accounts for, beyond
  `coverage.GONE_SHARE` of those it expects (an old map loses objects), count against it.
* **Follow.**  The supporting pairs are kept, newest last (one per map object and per local
  object); the pose is refitted to the newest `pairs` of them, warm-started from the tracked
  pose.  Changed objects never refit the pose.  Odometry drift is slow, so the newest objects,
  seen near the robot, give the pose that is right *now* where the robot is.
* **Contradiction.**  The evidence against an update is its contradicting and its changed
  objects (a change is no support: a wrong place explains detections by "moves" as readily
  as a right one) and its missing ones beyond the tolerated share; for it, its supporting
  objects (re-detections at half).  An update whose evidence against is at least `contradiction` and
  more than twice the evidence for it, or the last `CONTRADICTION_UPDATES` updates together
  holding at least `contradiction` + 1 against and more than twice as much as for, end the
  claim at once (`ambiguous`, reason `"contradicted"`): the robot was carried elsewhere, its
  odometry jumped, or the place was a wrong one.  One moved chair among agreeing objects does
  not.  Over the whole claim, the objects judged since it began must stay at least half
  supporting (`min_support_share`, once `min_judged` are judged): a wrong place that a few
  lucky objects keep alive update by update loses it there.
* **Unusual against this run.**  An old map and an erring detector make some objects judged
  against a right place (changed or contradicting): few in a clean world, a quarter or more
  in a hard one.  The run keeps that share over its tracked claims (`AgainstRate`, from a
  prior of `PRIOR_AGAINST` worth `PRIOR_WEIGHT` objects); when the objects first judged in
  the latest `CONTRADICTION_UPDATES` updates hold at least two against, more than that share
  makes likely at `UNUSUAL` (a one-sided binomial test), the claim ends: the robot was carried
  into a look-alike place whose objects mostly fit, but not as this run's places fit.
* **Doubt.**  Short of that, when the newest `DOUBT_OBJECTS` judged objects (whatever the
  updates they came in) hold at least two against, more than the run's share makes likely at
  `DOUBT`, the claim is doubted: the answer is `ambiguous` until newer objects support the
  place again or the evidence ends the claim.  A robot carried off sees a few objects that
  happen to fit, then a few that do not, then nothing for a while: a claim is an action's
  licence, and it is not given while the newest evidence speaks against it.
* **Confidence.**  The claim's confidence moves with its evidence: the search's confidence
  (as a logit, at most `CONFIDENCE_CAP`) plus a log-likelihood ratio per judged object
  (`EVIDENCE_LOGITS`: supporting, changed, contradicting, missing).
* **Lapse.**  When fewer than `min_pairs` supporting pairs remain in the window (the robot saw
  nothing it could check for a while), the claim is not renewed and the search resumes on the
  window.  Nor is it when none of its supporting objects was detected within the last
  `stale_m` metres of travel: a robot carried off while it saw nothing (an empty corridor)
  would otherwise keep a place it cannot check; the search then answers `ambiguous` until
  something is seen (a claim is about now).
"""

from __future__ import annotations

import math
from collections import OrderedDict, deque
from collections.abc import Callable, Collection, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from semloc.coverage import GONE_SHARE
from semloc.maps import ObjectMap, SemanticObject
from semloc.pose import cached_cloud, estimate_pose
from semloc.results import Hypothesis
from semloc.transforms import centre_residual

if TYPE_CHECKING:
    from semloc.sightings import Sightings

CONTRADICTION_UPDATES = 3
"""How many of the latest updates are weighed together for a contradiction."""

DOUBTED = "the newest objects speak against the tracked place"
"""The reason of a tracked place's answer doubted by its newest objects (`Track.doubted`)."""
CONTRADICTED = "contradicted"
"""The reason of the answer whose new objects ended a claim."""

EVIDENCE_LOGITS = {"supported": 0.6, "changed": -0.4, "contradicting": -1.2, "missing": -0.8}
"""Log-likelihood ratio (right place against a wrong one) of one judged object: a right place of
an old map seen by an erring detector has about 65 % of its objects supporting, 15 % changed
and 20 % contradicting; a wrong place about 25 / 25 / 50 %."""
PRIOR_AGAINST = 0.25
"""The share of new objects judged against a right place before the run has shown its own."""
PRIOR_WEIGHT = 20.0
"""How many judged objects the prior share is worth."""
UNUSUAL = 0.01
"""How unlikely, under the run's share, the latest updates' objects against a claim must be to
end it."""
DOUBT_OBJECTS = 6
"""The newest judged objects weighed for a doubt (`Track.doubted`), across updates: a robot
carried off may see nothing for several updates, and nothing seen is no news."""
DOUBT = 0.05
"""How unlikely, under the run's share, the newest judged objects against a claim must be to
doubt it."""
_VERDICTS = ("supported", "changed", "contradicting")
CONFIDENCE_CAP = 4.0
"""The search's confidence enters a claim's confidence as a logit of at most this."""


class TrackingConfig(BaseModel):
    """Tracking a found place (see the module docstring)."""

    model_config = ConfigDict(extra="forbid")

    track: bool = Field(
        True, description="Track a place once localized (False: search at every update)."
    )
    track_tolerance: float = Field(
        0.6,
        gt=0,
        description="A new object supports the tracked place when a map object it may be "
        "lies within this distance (m), plus a quarter of that object's diagonal, of where "
        "the pose puts it.",
    )
    track_pairs: int = Field(
        12, ge=2, description="The tracked pose is refitted to this many newest supporting pairs."
    )
    track_min_pairs: int = Field(
        3, ge=2, description="Fewer supporting pairs in the window: the search resumes."
    )
    contradiction: int = Field(
        2,
        ge=1,
        description="Contradicting objects in one update that end the claim when they "
        "are more than twice the supporting ones.",
    )
    move_m: float = Field(
        3.0,
        ge=0,
        description="An object whose nearest candidate lies beyond the tolerance but within "
        "this distance (m) of where the pose puts it is a change of the map (moved), not a "
        "contradiction; it never refits the pose.",
    )
    min_support_share: float = Field(
        0.5,
        ge=0,
        le=1,
        description="Share of the objects judged since the claim began that must support it.",
    )
    min_judged: int = Field(
        8, ge=1, description="Objects judged since the claim began before that share is asked."
    )
    stale_m: float | None = Field(
        6.0,
        gt=0,
        description="A claim needs a detection of its place within this many metres of "
        "odometry travel: older evidence says where the robot was, not where it is (needs "
        "robot positions; None: no bound).",
    )


@dataclass(frozen=True)
class Verdict:
    """What one update's objects say of the tracked place."""

    supported: list[tuple[int, str]]  # (global index, local id)
    contradicting: list[str]  # local ids
    changed: list[tuple[int, str]] = field(default_factory=list)  # (nearest candidate, local)
    repeated: int = 0  # supporting objects already paired with the same map object
    missing: float = 0.0  # map objects the look expected but nothing accounts for, beyond
    # the tolerated share
    sources: dict[str, list[int]] = field(default_factory=dict)  # changed local id -> the
    # map objects it may have moved from, when more than one (`one_to_one`)

    @property
    def against(self) -> float:
        return len(self.contradicting) + len(self.changed) + self.missing

    @property
    def towards(self) -> float:
        return len(self.supported) - 0.5 * self.repeated


def check(
    pose: np.ndarray,
    objects: Iterable[SemanticObject],
    candidates: Mapping[str, np.ndarray],
    global_positions: np.ndarray,
    allowance: np.ndarray,
    move_m: float = 0.0,
    paired: Mapping[str, int] | None = None,
    part_m: np.ndarray | None = None,
) -> Verdict:
    """Each object with candidates, put by `pose` (T_global_local) into the global frame:
    supported by its nearest candidate g within `allowance[g]` (metres), changed when its
    nearest candidate lies within `move_m`, else contradicting.  A map object supports one
    object of the update, the nearest (two chairs of one view are not one chair of the map):
    another object within its allowance is a part of it when within `part_m[g]` of the first
    (half its footprint: a detector's split; it says nothing), else it takes its next free
    candidate, or is judged on the free ones.  `paired`: the local objects already paired
    (local id -> map index), whose support again is a repeat."""
    R, t = pose[:3, :3], pose[:3, 3]
    paired = paired or {}
    placed: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
    near: list[tuple[float, str, int]] = []
    for obj in objects:
        found = np.asarray(candidates.get(obj.id, ()), dtype=int)
        if not len(found):
            continue
        at = R @ obj.position + t
        gaps = np.linalg.norm(global_positions[found] - at, axis=1)
        placed[obj.id] = (at, found, gaps)
        near += [(float(d), obj.id, int(g)) for d, g in zip(gaps, found) if d <= allowance[g]]
    taken: dict[int, str] = {}  # map index -> the local id it supports
    support_of: dict[str, int] = {}
    for _, local_id, g in sorted(near):
        if g not in taken and local_id not in support_of:
            taken[g], support_of[local_id] = local_id, g
    supported = [(support_of[l], l) for l in placed if l in support_of]
    contradicting, changed = [], []
    for local_id, (at, found, gaps) in placed.items():
        if local_id in support_of or _a_part(at, found, gaps, allowance, taken, placed, part_m):
            continue
        free = [i for i, g in enumerate(found) if g not in taken]
        nearest = min(free, key=lambda i: gaps[i]) if free else None
        if nearest is not None and gaps[nearest] <= move_m:
            changed.append((int(found[nearest]), local_id))
        else:
            contradicting.append(local_id)
    repeated = sum(paired.get(l) == g for g, l in supported)
    return Verdict(supported, contradicting, changed, repeated)


def _a_part(
    at: np.ndarray, found: np.ndarray, gaps: np.ndarray, allowance: np.ndarray,
    taken: Mapping[int, str], placed: Mapping[str, tuple[np.ndarray, ...]],
    part_m: np.ndarray | None,
) -> bool:  # fmt: skip
    """Whether an object at `at` is a part of a map object that another object took: within
    that object's allowance, and within `part_m` of the object that took it."""
    if part_m is None:
        return False
    return any(g in taken and gaps[i] <= allowance[g]
               and np.linalg.norm(at - placed[taken[g]][0]) < part_m[g]
               for i, g in enumerate(found.tolist()))  # fmt: skip


def one_to_one(
    pose: np.ndarray,
    objects: Iterable[SemanticObject],
    candidates: Mapping[str, np.ndarray],
    global_positions: np.ndarray,
    allowance: np.ndarray,
    move_m: float,
    held: Mapping[int, np.ndarray],
    settled: Collection[int] = (),
    part_m: np.ndarray | None = None,
) -> Verdict:
    """The update's objects judged for the run's change report: `check`'s rule, but each map
    object explains one object, and a move names the sources it may come from.

    `held`: the map objects the claim's other local objects are paired with (map index ->
    where that object lies under `pose`); `settled`: map objects seen at their place before,
    which may be seen there again but are no one's source.  Nearest first over all of them,
    each object takes its nearest candidate within `move_m` that no nearer object took; it
    supports it within `allowance`, else it is changed.  An object within `allowance` of a map
    object g that a nearer object took, and within `part_m[g]` of that object (half g's
    footprint diagonal, `footprints`: two objects do not overlap), is a part of it (a
    detector's split): it says nothing.  A changed object with other free candidates within
    `move_m` (neither taken, held nor settled) lists them all in `sources`, nearest first: of
    two chairs gone from their places, which one stands here cannot be told yet.  An object
    that takes none is contradicting."""
    R, t = pose[:3, :3], pose[:3, 3]
    found = [
        (float(np.linalg.norm(global_positions[g] - p)), None, int(g)) for g, p in held.items()
    ]
    placed: dict[str, np.ndarray] = {}
    reach: dict[str, dict[int, float]] = {}  # local id -> its candidates within move_m
    for obj in objects:
        indices = np.asarray(candidates.get(obj.id, ()), dtype=int)
        if not len(indices):
            continue
        placed[obj.id] = R @ obj.position + t
        gaps = np.linalg.norm(global_positions[indices] - placed[obj.id], axis=1)
        reach[obj.id] = {int(g): float(d) for g, d in zip(indices, gaps) if d <= move_m}
        found += [(float(d), obj.id, int(g)) for d, g in zip(gaps, indices)
                  if d <= allowance[g] or (d <= move_m and g not in settled)]  # fmt: skip
    taken: dict[int, tuple[float, str | None]] = {}  # map index -> (gap, its taker; None: held)
    assigned: set[str] = set()  # local ids that took a map object or are a part of one
    for gap, local_id, g in sorted(found, key=lambda f: (f[0], f[1] or "", f[2])):
        if local_id is None:
            taken.setdefault(g, (gap, None))
        elif local_id in assigned:
            continue
        elif g not in taken:
            taken[g] = (gap, local_id)
            assigned.add(local_id)
        elif part_m is not None and gap <= allowance[g]:
            taker = taken[g][1]
            where = held[g] if taker is None else placed[taker]
            if np.linalg.norm(placed[local_id] - where) < part_m[g]:
                assigned.add(local_id)
    supported = [(g, l) for g, (d, l) in taken.items() if l is not None and d <= allowance[g]]
    changed = [(g, l) for g, (d, l) in taken.items() if l is not None and d > allowance[g]]
    claimed = set(taken) | set(settled)
    sources = {l: [g, *sorted(reach[l].keys() - claimed, key=lambda h: reach[l][h])]
               for g, l in changed if reach[l].keys() - claimed}  # fmt: skip
    return Verdict(sorted(supported, key=lambda p: p[1]),
                   [l for l in placed if l not in assigned],
                   sorted(changed, key=lambda p: p[1]), sources=sources)  # fmt: skip


def recent_contradiction(verdicts: Sequence[Verdict], least: int) -> bool:
    """Whether the latest updates' verdicts on a place (oldest first) contradict it: the
    newest alone holds at least `least` against and more than twice as much for, or all of
    them together hold at least `least` + 1 against and more than twice as much for."""
    if not verdicts:
        return False
    newest = verdicts[-1]
    if newest.against >= least and newest.against > 2 * newest.towards:
        return True
    against = sum(v.against for v in verdicts)
    towards = sum(v.towards for v in verdicts)
    return against >= least + 1 and against > 2 * towards


def allowances(global_map: ObjectMap, tolerance: float) -> np.ndarray:
    """How far (m) from each map object a detection of it may land: `tolerance` plus a quarter
    of the object's diagonal (its box, else its points), since a partial view moves a centre
    towards the side seen, by up to about half the object's extent."""
    return tolerance + 0.25 * diagonals(global_map)


def footprints(global_map: ObjectMap) -> np.ndarray:
    """Each map object's footprint diagonal (m) across the map's `up` (z when it has none): its
    box's, else its points' bounding box's; 0 without either."""
    up = np.array([0.0, 0.0, 1.0]) if global_map.up is None else global_map.up
    across = np.eye(3) - np.outer(up, up)
    corners = np.array(np.meshgrid(*[[-0.5, 0.5]] * 3)).reshape(3, -1).T
    sizes = global_map.sizes
    boxed = ~np.isnan(sizes).any(axis=1)
    found = np.zeros(len(global_map))
    # A box is symmetric about its centre: its widest pair of corners, flattened across up,
    # is a corner and its opposite, twice the farthest corner from the centre.
    turned = np.einsum("bij,bkj->bki", global_map.rotations[boxed], corners * sizes[boxed, None])
    found[boxed] = 2 * np.linalg.norm(turned @ across, axis=2).max(axis=1, initial=0.0)
    for i in np.flatnonzero(~boxed):
        if (points := global_map[int(i)].points) is not None and len(points):
            found[i] = np.linalg.norm(np.ptp(points @ across, axis=0))
    return found


def diagonals(global_map: ObjectMap) -> np.ndarray:
    """Each map object's diagonal (m): its box's, else its points' (0 without either)."""
    diagonal = np.linalg.norm(global_map.sizes, axis=1)
    for i in np.flatnonzero(np.isnan(diagonal)):
        points = global_map[int(i)].points
        diagonal[i] = (
            0.0 if points is None or not len(points) else np.linalg.norm(np.ptp(points, axis=0))
        )
    return diagonal


@dataclass
class AgainstRate:
    """The share of new objects this run's tracked claims judged against them (changed or
    contradicting): what the latest updates of a claim are weighed against."""

    against: float = 0.0
    judged: float = 0.0

    def add(self, against: int, judged: int) -> None:
        self.against += against
        self.judged += judged

    @property
    def share(self) -> float:
        return (self.against + PRIOR_WEIGHT * PRIOR_AGAINST) / (self.judged + PRIOR_WEIGHT)

    def unusual(self, against: int, judged: int, level: float = UNUSUAL) -> bool:
        """Whether `against` of `judged` new objects is unlikely at this run's share (at
        least two, one-sided binomial test at `level`)."""
        if against < 2:
            return False
        p = self.share
        tail = sum(math.comb(judged, k) * p**k * (1 - p) ** (judged - k)
                   for k in range(against, judged + 1))  # fmt: skip
        return tail < level


class Track:
    """The place being tracked: its pose, confidence and score (from the answer that found it)
    and its supporting pairs, newest last."""

    def __init__(
        self,
        pose: np.ndarray,
        pairs: Sequence[tuple[int, str]],
        confidence: float | None,
        score: float,
        config: TrackingConfig,
        rate: AgainstRate | None = None,
    ) -> None:
        self.pose = pose
        self.rate = AgainstRate() if rate is None else rate  # (the run's, shared by its claims)
        self._recent: deque[tuple[int, int]] = deque(maxlen=CONTRADICTION_UPDATES)
        self.confidence = confidence
        self.score = score
        self.config = config
        self.pairs: OrderedDict[str, int] = OrderedDict()  # local id -> global index
        self._verdicts: deque[Verdict] = deque(maxlen=CONTRADICTION_UPDATES)
        self._newest: deque[bool] = deque(maxlen=DOUBT_OBJECTS)  # judged against, newest last
        self.judged: dict[str, str] = {}  # local id -> its latest verdict since the claim began
        self.missing = 0.0  # missing objects beyond the tolerated share, since the claim began
        self.base = _logit(confidence, CONFIDENCE_CAP)
        self.accept(Verdict(list(pairs), []))

    def contradicted(self, verdict: Verdict) -> int:
        """How many of the latest updates (this one included) contradict the place: 0 when
        they do not; 1 also when the claim's judged objects lost their supporting share."""
        self._verdicts.append(verdict)
        new = self._judge(verdict)
        if len(self._recent) == self._recent.maxlen:  # (the test's own updates stay out)
            self.rate.add(*self._recent[0])
        self._recent.append(new)
        least = self.config.contradiction
        if recent_contradiction([verdict], least):
            return 1
        if recent_contradiction(self._verdicts, least):
            return len(self._verdicts)
        counts = self.counts()
        judged = counts["supported"] + counts["changed"] + counts["contradicting"] + self.missing
        if judged >= self.config.min_judged and counts["supported"] < (
            self.config.min_support_share * judged
        ):
            return 1
        if self.rate.unusual(*map(sum, zip(*self._recent))):
            return len(self._recent)
        return 0

    def _judge(self, verdict: Verdict) -> tuple[int, int]:
        """Record the verdict's judgements (latest wins); how many of them are new or changed
        (against the place, and in all)."""
        judged = {l: "supported" for _, l in verdict.supported}
        judged |= {l: "changed" for _, l in verdict.changed}
        judged |= dict.fromkeys(verdict.contradicting, "contradicting")
        new = [v for l, v in judged.items() if self.judged.get(l) != v]
        self._newest.extend(v != "supported" for v in new)
        self.judged |= judged
        self.missing += verdict.missing
        return sum(v != "supported" for v in new), len(new)

    def doubted(self) -> bool:
        """Whether the newest judged objects speak against the place beyond this run's share
        (at `DOUBT`; see the module docstring)."""
        return self.rate.unusual(sum(self._newest), len(self._newest), DOUBT)

    def counts(self) -> dict[str, int]:
        """The objects judged since the claim began, by their latest verdict."""
        found = dict.fromkeys(_VERDICTS, 0)
        for verdict in self.judged.values():
            found[verdict] += 1
        return found

    def current_confidence(self) -> float:
        """The claim's confidence from its accumulated evidence (see the module docstring)."""
        counts = self.counts()
        logit = self.base + self.missing * EVIDENCE_LOGITS["missing"]
        logit += sum(EVIDENCE_LOGITS[k] * n for k, n in counts.items())
        return 1.0 / (1.0 + math.exp(-max(min(logit, 50.0), -50.0)))

    def accept(self, verdict: Verdict) -> None:
        """Keep the verdict's supporting pairs (newest last, one per map and local object)."""
        for object_id in [*verdict.contradicting, *(l for _, l in verdict.changed)]:
            self.pairs.pop(object_id, None)  # re-detected elsewhere: no longer evidence
        for g, object_id in verdict.supported:
            for other in [l for l, h in self.pairs.items() if h == g]:
                del self.pairs[other]
            self.pairs.pop(object_id, None)
            self.pairs[object_id] = g

    def keep_only(self, object_ids: Iterable[str]) -> None:
        """Forget the pairs of local objects that left the window."""
        keep = set(object_ids)
        for object_id in [l for l in self.pairs if l not in keep]:
            del self.pairs[object_id]
        for object_id in [l for l in self.judged if l not in keep]:
            del self.judged[object_id]

    def state(self, global_ids: Sequence[str]) -> dict[str, Any]:
        """What rebuilds this track (JSON types; map objects by id)."""
        verdicts = [[[[global_ids[g], l] for g, l in v.supported], v.contradicting,
                     [[global_ids[g], l] for g, l in v.changed], v.repeated, v.missing]
                    for v in self._verdicts]  # fmt: skip
        return {
            "pose": self.pose.tolist(),
            "pairs": [[global_ids[g], l] for l, g in self.pairs.items()],
            "confidence": self.confidence,
            "score": self.score,
            "verdicts": verdicts,
            "judged": dict(self.judged),
            "missing": self.missing,
            "recent": [list(r) for r in self._recent],
            "newest": [int(a) for a in self._newest],
        }

    @classmethod
    def restored(
        cls, state: dict[str, Any], index_of: Callable[[str], int], config: TrackingConfig,
        rate: AgainstRate | None = None,
    ) -> Track:  # fmt: skip
        """The track of `state` (from `state()`); `index_of` maps a map object's id to its index."""
        pairs = [(index_of(g), str(l)) for g, l in state["pairs"]]
        track = cls(np.asarray(state["pose"], dtype=float), [], state["confidence"],
                    float(state["score"]), config, rate)  # fmt: skip
        track.pairs = OrderedDict((l, g) for g, l in pairs)
        for supported, contradicting, *more in state["verdicts"]:  # (a state before changes:
            changed, repeated, missing = more or [[], 0, 0.0]  # two items a verdict)
            verdict = Verdict([(index_of(g), str(l)) for g, l in supported],
                              [str(l) for l in contradicting],
                              [(index_of(g), str(l)) for g, l in changed], int(repeated),
                              float(missing))  # fmt: skip
            track._verdicts.append(verdict)
        judged = state.get("judged", {})
        track.judged = {str(l): str(v) for l, v in judged.items() if v in _VERDICTS}
        track.missing = float(state.get("missing", 0.0))
        track._recent.extend((int(a), int(n)) for a, n in state.get("recent", []))
        track._newest.extend(bool(a) for a in state.get("newest", []))
        return track

    def check(
        self, sightings: Sightings, objects: list[SemanticObject]
    ) -> tuple[Verdict, np.ndarray, int | None]:
        """What the update's objects say of the place (Check; `check`), with Missing when the
        update says what the sensor covered: the verdict, the map objects the look expected
        that nothing accounts for, and how many it expected (None: no coverage given)."""
        context = sightings.context
        verdict = check(
            self.pose, objects, sightings.candidates(objects), context.map.positions,
            context.allowances, self.config.move_m, self.pairs, context.parts,
        )  # fmt: skip
        if sightings.look is None:
            return verdict, np.zeros(0, dtype=int), None
        expected, unseen = sightings.unseen(self.pose)
        excess = max(0.0, len(unseen) - GONE_SHARE * len(expected))
        verdict = Verdict(verdict.supported, verdict.contradicting, verdict.changed,
                          verdict.repeated, excess)  # fmt: skip
        return verdict, unseen, len(expected)

    def newest(self, n: int) -> list[tuple[int, str]]:
        """The newest `n` supporting pairs (global index, local id), oldest first."""
        return [(g, l) for l, g in list(self.pairs.items())[-n:]]

    def follow(
        self, sightings: Sightings, min_pairs: int, local_up: np.ndarray | None, prior: bool
    ) -> Hypothesis | None:
        """The place refitted to its newest supporting pairs (Follow), as the answer's one
        hypothesis (`prior`: whether a prior is in effect, which the place lies within); None
        when the claim lapses (Lapse: fewer than `min_pairs` pairs in the window, none of
        them detected within `stale_m`) or the pose no longer fits its newest pairs."""
        if len(self.pairs) < min_pairs or sightings.stale(list(self.pairs), self.config.stale_m):
            return None
        pairs = self.newest(self.config.track_pairs)
        global_map, cfg = sightings.context.map, sightings.context.config.pose
        locals_ = [sightings.found[l][0] for _, l in pairs]
        globals_ = [global_map[g] for g, _ in pairs]
        l_xyz = np.array([o.position for o in locals_])
        g_xyz = np.array([o.position for o in globals_])
        estimate = estimate_pose(
            l_xyz, g_xyz, [cached_cloud(o, cfg) for o in locals_],
            [cached_cloud(o, cfg) for o in globals_], local_up, global_map.up, cfg,
            init=self.pose,
        )  # fmt: skip
        if estimate is None:
            return None
        residual = centre_residual(estimate.T, l_xyz, g_xyz)
        if residual > self.config.track_tolerance:
            return None
        self.pose = estimate.T
        return Hypothesis(
            rank=1,
            score=self.score,
            pairs=[(g.id, l.id) for g, l in zip(globals_, locals_)],
            pose=estimate.T,
            fitness=estimate.fitness,
            rmse=estimate.rmse,
            residual=residual,
            method=f"tracked/{estimate.method}",
            confidence=self.confidence,
            outside_prior=False if prior else None,
        )

    def judged_one_to_one(
        self, sightings: Sightings, objects: list[SemanticObject], verdict: Verdict,
        matched: Collection[int],
    ) -> Verdict:  # fmt: skip
        """This update's objects judged for the run's change report (`one_to_one`): against
        the claim's pairs of other local objects (before this update's replace them) and the
        map objects the run saw at their place (`matched`); its contradicting objects are the
        check's."""
        context, found = sightings.context, sightings.found
        R, t = self.pose[:3, :3], self.pose[:3, 3]
        now = {o.id for o in objects}
        held = {g: R @ found[l][0].position + t
                for l, g in self.pairs.items() if l not in now and l in found}  # fmt: skip
        judged = one_to_one(self.pose, objects, sightings.candidates(objects),
                            context.map.positions, context.allowances, self.config.move_m, held,
                            matched, context.parts)  # fmt: skip
        return Verdict(judged.supported, verdict.contradicting, judged.changed,
                       sources=judged.sources)  # fmt: skip


def _logit(probability: float | None, cap: float) -> float:
    """The logit of `probability`, within +-`cap` (0 for None)."""
    if probability is None:
        return 0.0
    p = min(max(probability, 1e-9), 1 - 1e-9)
    return max(min(math.log(p / (1 - p)), cap), -cap)
