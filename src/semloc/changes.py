"""What changed since the map was made: every local object explained under a hypothesis' pose.

Under the pose T_global_local of a hypothesis each local object is

    matched   one of the hypothesis' pairs, or a map object it may be (the Localizer's
              candidates) lies within `match_radius` of where the pose puts it, or failing
              that a map object of another label and a similar size does (the same object
              under another name: a detector's label is not a change of the world);
    moved     nothing it may be is at its place, but the map holds an object it may be
              elsewhere (within `max_offset`) that no other local object explains, of a similar
              size where both have boxes (`size_ratio`), whose old place was in view (an
              observed local point within `source_radius`): the same instance, moved by
              `offset_m` (of several such objects, the one whose box agrees best, then the
              nearest: a moved chair is more likely the chair of its own size than the next);
    new       nothing in the map explains it.

A map object that nobody matched or moved is `missing` when the place where it stood was
observed: some observed local point lies within `observed_radius` of that place.  That is the
bound: a local map holds the points of the objects seen, not the free space seen, so only a
place right beside observed surfaces counts as seen; objects farther away are not reported,
since nothing says whether they are still there.  A local object without points but with a box
(size, rotation) was seen on its box's surface (sampled); one with a centre only vouches for
nothing, so with centres only a moved object reads as `new` and nothing is `missing`.  Greedy and one to one (matches nearest first, moved objects by box agreement,
then nearest), so that a moved object and a new one of the same class are not both explained
by one map object.  Pure computation on numpy arrays.

A report of changes against a map that moved on since (the service's change reports) still
applies unless the versions written since touched what it changes or relies on
(`check_still_applies`, `ReportConflict`).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError
from scipy.spatial import cKDTree

from semloc import schema
from semloc.association import AssociationConfig, CandidateIndex
from semloc.maps import MAX_ID_LENGTH, ObjectMap, SemanticObject

if TYPE_CHECKING:
    from semloc.tracking import Verdict

POINTS_PER_OBJECT = 48
"""Observed surfaces are sampled to about this many points per local object: the radii asked
about (0.5 m, 1.5 m) are far larger than the gaps between them."""


class ChangesConfig(BaseModel):
    """When a local object is matched, moved or new, and a map object missing."""

    model_config = ConfigDict(extra="forbid")

    match_radius: float = Field(
        0.5, gt=0, description="A map object it may be within this (m) of its place: matched."
    )
    max_offset: float = Field(
        3.0, gt=0, description="Farthest (m) an object may have moved to be reported as moved."
    )
    size_ratio: float = Field(
        1.5, ge=1, description="Boxes of a moved object and its map object differ at most this."
    )
    source_radius: float = Field(
        1.5,
        gt=0,
        description="A moved object's old place must lie this near (m) to an "
        "observed local point: its absence there was seen.",
    )
    observed_radius: float = Field(
        0.5,
        gt=0,
        description="A map object's place counts as observed within this (m) of a "
        "local point: then an unmatched map object there is missing.",
    )


@dataclass(frozen=True)
class Moved:
    global_id: str
    local_id: str
    offset_m: float
    evidence: int | None = None  # detections that saw it moved over a run (None: one view)
    last_seen: int | None = None  # the `seen` keyframe of the latest of them


@dataclass(frozen=True)
class Changes:
    """The changes one hypothesis implies (empty when nothing changed)."""

    moved: list[Moved] = field(default_factory=list)
    new: list[str] = field(default_factory=list)  # local ids
    missing: list[str] = field(default_factory=list)  # global ids
    matched: list[str] = field(default_factory=list, compare=False)
    """Map objects seen where the map has them (global ids): no change, so not in `to_dict`;
    `semloc update-map` clears their `missing` flag."""
    evidence: dict[str, dict[str, int]] | None = None
    """Over a run (`RunChanges`): how many detections (new) or looks (missing) said so, by id."""

    def to_model(self) -> schema.Changes:
        moved = [schema.Moved(global_=m.global_id, local=m.local_id, offset_m=m.offset_m,
                              evidence=m.evidence, last_seen=m.last_seen)
                 for m in self.moved]  # fmt: skip
        return schema.Changes(moved=moved, new=list(self.new), missing=list(self.missing),
                              evidence=self.evidence)  # fmt: skip

    @classmethod
    def of_model(cls, m: schema.Changes) -> Changes:
        moved = [Moved(x.global_, x.local, x.offset_m, x.evidence, x.last_seen) for x in m.moved]
        return cls(moved, list(m.new), list(m.missing), evidence=m.evidence)

    def to_dict(self) -> dict[str, Any]:
        return self.to_model().model_dump(by_alias=True)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Changes:
        """The changes of a `to_dict` document (`ValueError` for one that is not)."""
        try:
            return cls.of_model(schema.Changes.model_validate(data))
        except ValidationError as exc:
            raise ValueError(
                f"'changes' is not a changes object ({schema.field_error(exc)})"
            ) from None


UNDECIDED_KEPT = 1000
"""The run's report keeps this many of the latest undecided detections (`RunChanges`)."""


class RunChanges:
    """What changed since the map was made, accumulated over the tracked claims of a run.

    Fed by tracking's judgement for the report (`semloc.tracking.one_to_one`: each map object
    explains one detection, nearest first, against the claim's other pairs): an object changed
    under the claim (the map object it takes lies beyond the tracking tolerance, within a
    plausible move) is evidence that that map object moved; one without candidates, or
    contradicting, that it is new; a map object the sensor's look should have shown that
    nobody accounts for, that it is missing.  A map object seen at its place cancels its moved
    and missing evidence, and is no one's source for the rest of the run.  A changed object
    with several free sources within reach (two chairs gone from their places, one chair
    between them) is undecided: its detection counts for the source left once the run has
    seen the others at their places, and for none while several are left (a wrong source is
    two errors: a chair reported moved that is not, and one moved that is not reported).  A
    change is reported once `min_evidence` detections (or looks) said so: a phantom or a
    mislabel is seen once, a moved chair again at each look.

    The report survives the end of a claim (a kidnap, a contradiction, a lapse) and is never
    reset within a run: it is about the map, not the claim, and a chair that moved is still
    moved after the robot was carried off, so dropping it would lose what the run already
    established (the next tracked answer shows it again, with the later evidence added; the
    Localizer's `state` keeps it).  The price is that a wrong claim's evidence stays too; it
    needs `min_evidence` detections, and the map objects later seen at their places cancel
    it."""

    def __init__(self, min_evidence: int = 2) -> None:
        self.min_evidence = min_evidence
        self.moved: dict[int, tuple[str, float, int, int]] = {}  # map index -> (local id,
        # offset m, detections, last seen)
        self.new: dict[str, tuple[int, int]] = {}  # local id -> (detections, last seen)
        self.missing: dict[int, int] = {}  # map index -> looks that missed it
        self.matched: set[int] = set()
        self.undecided: deque[tuple[str, dict[int, float], int]] = deque(maxlen=UNDECIDED_KEPT)
        # (local id, {source map index: offset m}, seen) of detections that may have moved from
        # several map objects

    def __bool__(self) -> bool:
        return bool(self.moved or self.new or self.missing or self.undecided)

    def observe_moved(self, g: int, local_id: str, offset: float, seen: int) -> None:
        g, seen = int(g), int(seen)
        if g in self.matched:
            return
        latest, _, count, last = self.moved.get(g, (local_id, offset, 0, seen))
        if seen < last:  # (an undecided detection decided later: the newer one is named)
            local_id, offset, seen = latest, self.moved[g][1], last
        self.moved[g] = (str(local_id), float(offset), count + 1, seen)

    def observe_undecided(self, local_id: str, offsets: Mapping[int, float], seen: int) -> None:
        """A detection of a changed object that may have moved from any of several map objects
        (map index -> offset m): evidence for the one left once the run saw the others at their
        place."""
        left = {int(g): float(o) for g, o in offsets.items() if int(g) not in self.matched}
        self._decide(str(local_id), left, int(seen))

    def _decide(self, local_id: str, offsets: dict[int, float], seen: int) -> None:
        if len(offsets) == 1:
            g, offset = next(iter(offsets.items()))
            self.observe_moved(g, local_id, offset, seen)
        elif offsets:
            self.undecided.append((local_id, offsets, seen))

    def observe_new(self, local_id: str, seen: int, unknown_label: bool = False) -> None:
        """A detection of a new object: one the map has no candidate for (`unknown_label`,
        reported at once) or one its candidates contradict."""
        count, _ = self.new.get(local_id, (0, seen))
        least = self.min_evidence if unknown_label else 0
        self.new[str(local_id)] = (max(count + 1, least), int(seen))

    def observe_missing(self, indices: Sequence[int]) -> None:
        for g in map(int, indices):
            if g not in self.matched:
                self.missing[g] = self.missing.get(g, 0) + 1

    def observe_update(
        self, verdict: Verdict, objects: list[SemanticObject], candidates: Mapping[str, np.ndarray],
        unseen: np.ndarray, pose: np.ndarray, positions: np.ndarray,
    ) -> None:  # fmt: skip
        """What one update's objects said of a tracked claim at `pose` (`verdict`: tracking's
        judgement for the report), and the map objects its look missed (`unseen`)."""
        by_id = {o.id: o for o in objects}
        R, t = pose[:3, :3], pose[:3, 3]
        for g, object_id in verdict.supported:
            self.observe_matched(g, object_id)
        for g, object_id in verdict.changed:
            obj = by_id[object_id]
            sources = verdict.sources.get(object_id, [g])
            gaps = np.linalg.norm(positions[sources] - (R @ obj.position + t), axis=1)
            self.observe_undecided(object_id, dict(zip(sources, gaps.tolist())), obj.seen)
        for obj in objects:
            if not len(candidates[obj.id]):
                self.observe_new(obj.id, obj.seen, unknown_label=True)
            elif obj.id in verdict.contradicting:
                self.observe_new(obj.id, obj.seen)
        self.observe_missing(unseen.tolist())

    def observe_matched(self, g: int, local_id: str) -> None:
        g = int(g)
        self.matched.add(g)
        self.moved.pop(g, None)
        self.missing.pop(g, None)
        self.new.pop(local_id, None)
        if any(g in offsets for _, offsets, _ in self.undecided):
            undecided, self.undecided = self.undecided, deque(maxlen=UNDECIDED_KEPT)
            for l, offsets, seen in undecided:
                self._decide(l, {h: o for h, o in offsets.items() if h != g}, seen)

    def copy(self) -> RunChanges:
        """The report as it stands (later observations do not change the copy)."""
        copied = RunChanges(self.min_evidence)
        copied.moved, copied.new = dict(self.moved), dict(self.new)
        copied.missing, copied.matched = dict(self.missing), set(self.matched)
        copied.undecided = deque(self.undecided, maxlen=UNDECIDED_KEPT)
        return copied

    def report(self, global_ids: Sequence[str]) -> Changes:
        """The changes seen at least `min_evidence` times, with their evidence."""
        least = self.min_evidence
        moved = [Moved(str(global_ids[g]), l, offset, n, seen)
                 for g, (l, offset, n, seen) in sorted(self.moved.items()) if n >= least]  # fmt: skip
        new = {l: n for l, (n, _) in self.new.items() if n >= least}
        missing = {str(global_ids[g]): n for g, n in sorted(self.missing.items()) if n >= least}
        matched = [str(global_ids[g]) for g in sorted(self.matched)]
        return Changes(moved, list(new), list(missing), matched,
                       evidence={"new": new, "missing": missing})  # fmt: skip

    def state(self, global_ids: Sequence[str]) -> dict[str, Any]:
        ids = global_ids
        return {
            "moved": [[ids[g], l, o, n, s] for g, (l, o, n, s) in self.moved.items()],
            "new": [[l, n, s] for l, (n, s) in self.new.items()],
            "missing": [[ids[g], n] for g, n in self.missing.items()],
            "matched": [ids[g] for g in sorted(self.matched)],
            "undecided": [
                [l, [[ids[g], o] for g, o in offsets.items()], s]
                for l, offsets, s in self.undecided
            ],  # fmt: skip
        }

    @classmethod
    def restored(
        cls, state: Mapping[str, Any], index_of: Callable[[str], int], min_evidence: int = 2
    ) -> RunChanges:
        """The report of `state()`, reporting at `min_evidence` as the one saved did."""
        run = cls(min_evidence)
        run.moved = {index_of(g): (str(l), float(o), int(n), int(s))
                     for g, l, o, n, s in state.get("moved", [])}  # fmt: skip
        run.new = {str(l): (int(n), int(s)) for l, n, s in state.get("new", [])}
        run.missing = {index_of(g): int(n) for g, n in state.get("missing", [])}
        run.matched = {index_of(g) for g in state.get("matched", [])}
        run.undecided.extend((str(l), {index_of(g): float(o) for g, o in offsets}, int(s))
                             for l, offsets, s in state.get("undecided", []))  # fmt: skip
        return run


def answer_changes(
    global_map: ObjectMap,
    local_objects: Sequence[SemanticObject],
    pose: np.ndarray,
    pairs: Sequence[tuple[str, str]],
    association: AssociationConfig | None = None,
    config: ChangesConfig | None = None,
    candidates: Mapping[str, np.ndarray] | None = None,
) -> Changes:
    """The changes an answer implies: its best hypothesis' `pose` and `pairs` (global id,
    local id) over `local_objects`, each local object's candidates by the Localizer's rule
    (`CandidateIndex` with `association`, or the Localizer's own `candidates`).  Pairs naming
    an object of neither map are left out (a saved or reported answer).  The one rule of the
    Localizer's answers, `semloc update-map --result` and the service's change reports."""
    local = list(local_objects)
    if candidates is None:
        index = CandidateIndex(global_map, association or AssociationConfig())
        candidates = {o.id: index.candidates(o) for o in local}
    known, local_ids = set(global_map.ids.tolist()), {o.id for o in local}
    kept = [(g, l) for g, l in pairs if g in known and l in local_ids]
    return explain(global_map, local, pose, kept, candidates, config)


def explain(
    global_map: ObjectMap,
    local_objects: Sequence[SemanticObject],
    pose: np.ndarray,
    pairs: Sequence[tuple[str, str]],
    candidates: Mapping[str, np.ndarray],
    config: ChangesConfig | None = None,
) -> Changes:
    """The changes under `pose` (T_global_local) with the hypothesis' `pairs` (global id,
    local id); `candidates[local id]` are the indices of the map objects it may be."""
    config = config or ChangesConfig()
    R, t = pose[:3, :3], pose[:3, 3]
    placed = {o.id: R @ o.position + t for o in local_objects}
    index = {gid: i for i, gid in enumerate(global_map.ids.tolist())}
    used = {index[g] for g, _ in pairs if g in index}
    explained = {l for _, l in pairs}
    xyz = global_map.positions
    rest = [o for o in local_objects if o.id not in explained]
    _match_nearby(rest, placed, candidates, xyz, used, explained, config.match_radius)
    _relabelled(rest, placed, global_map, used, explained, config)
    gap = _gap_to_observed(global_map, local_objects, pose,
                           max(config.source_radius, config.observed_radius))  # fmt: skip
    unseen = set(np.flatnonzero(gap > config.source_radius).tolist())
    moved, new = _moved_or_new(
        [o for o in rest if o.id not in explained], placed, candidates, global_map,
        used | unseen, config,
    )  # fmt: skip
    sources = {index[m.global_id] for m in moved}  # not missing: seen elsewhere
    missing = [str(global_map.ids[g]) for g in np.flatnonzero(gap <= config.observed_radius)
               if g not in used and g not in sources]  # fmt: skip
    return Changes(moved, new, missing, sorted(str(global_map.ids[g]) for g in used))


def _candidate_distances(rest, placed, candidates, xyz) -> list[tuple[float, str, int]]:
    """(distance, local id, map index) from each placed local object to each map object it
    may be, nearest first."""
    found = []
    for obj in rest:
        indices = np.asarray(candidates.get(obj.id, ()), dtype=int)
        distances = np.linalg.norm(xyz[indices] - placed[obj.id], axis=1)
        found += [(float(d), obj.id, int(g)) for d, g in zip(distances, indices)]
    return sorted(found)


def _match_nearby(rest, placed, candidates, xyz, used, explained, radius) -> None:
    """Local objects with a free map object they may be within `radius`: matched (nearest
    first over all of them)."""
    for distance, local_id, g in _candidate_distances(rest, placed, candidates, xyz):
        if distance >= radius:
            break
        if local_id not in explained and g not in used:
            explained.add(local_id)
            used.add(g)


def _relabelled(rest, placed, global_map, used, explained, config: ChangesConfig) -> None:
    """Local objects standing where an unexplained map object of another label and a similar
    size stands: the same object under another name (a detector's label), matched, not moved
    or new (a moved chair that lands beside a table is not the table)."""
    for obj in rest:
        if obj.id in explained:
            continue
        distance = np.linalg.norm(global_map.positions - placed[obj.id], axis=1)
        free = [g for g in np.flatnonzero(distance < config.match_radius).tolist()
                if g not in used and _similar_size(obj, global_map[g], config)]  # fmt: skip
        if free:
            explained.add(obj.id)
            used.add(min(free, key=lambda g: distance[g]))


def _moved_or_new(rest, placed, candidates, global_map, used, config) -> tuple[list, list]:
    by_id = {o.id: o for o in rest}
    moved: dict[str, Moved] = {}
    reachable = [f for f in _candidate_distances(rest, placed, candidates, global_map.positions)
                 if f[0] <= config.max_offset]  # fmt: skip
    reachable.sort(key=lambda f: (_size_mismatch(by_id[f[1]], global_map[f[2]]), f[0]))
    for offset, local_id, g in reachable:
        if (local_id not in moved and g not in used
                and _similar_size(by_id[local_id], global_map[g], config)):  # fmt: skip
            used.add(g)
            moved[local_id] = Moved(str(global_map.ids[g]), local_id, offset)
    new = [o.id for o in rest if o.id not in moved]
    return sorted(moved.values(), key=lambda m: m.local_id), new


SIZE_STEP = 0.1
"""Box mismatches (largest log-ratio of the sorted extents) are compared in steps of this
(about 10 %): boxes that agree within a step are equally good sources, the nearest wins."""


def _size_mismatch(local: SemanticObject, mapped: SemanticObject) -> int:
    """How far apart two boxes are, in `SIZE_STEP`s (0 when either has no box)."""
    return int(round(_box_log_ratio(local, mapped) / SIZE_STEP))


def _similar_size(local: SemanticObject, mapped: SemanticObject, config: ChangesConfig) -> bool:
    return _box_log_ratio(local, mapped) <= np.log(config.size_ratio)


def _box_log_ratio(local: SemanticObject, mapped: SemanticObject) -> float:
    """The largest log-ratio of the two boxes' sorted extents (each at least 5 cm); 0 when
    either has no box."""
    if local.size is None or mapped.size is None:
        return 0.0
    a, b = np.maximum(np.sort(local.size), 0.05), np.maximum(np.sort(mapped.size), 0.05)
    return float(np.max(np.abs(np.log(a / b))))


def _gap_to_observed(global_map, local_objects, pose, reach: float) -> np.ndarray:
    """Per map object: the distance from its place to the nearest observed local point (inf
    beyond `reach`, and for all when no local object has points or a box)."""
    gap = np.full(len(global_map), np.inf)
    clouds = [cloud for cloud in map(_observed_surface, local_objects) if cloud is not None]
    if not clouds:
        return gap
    observed = np.vstack(clouds) @ pose[:3, :3].T + pose[:3, 3]
    xyz = global_map.positions
    low, high = observed.min(axis=0) - reach, observed.max(axis=0) + reach
    near = np.flatnonzero(np.all((xyz >= low) & (xyz <= high), axis=1))
    if len(near):
        gap[near] = cKDTree(observed).query(xyz[near], distance_upper_bound=reach)[0]
    return gap


_BOX_LATTICE = np.array(
    [p for p in np.array(np.meshgrid(*[np.linspace(-0.5, 0.5, 4)] * 3)).reshape(3, -1).T
     if np.abs(p).max() == 0.5]
)  # fmt: skip
"""56 points on the surface of the unit cube, a third of an edge apart: a box's surface."""


def _observed_surface(obj: SemanticObject) -> np.ndarray | None:
    """Where `obj` was seen (its frame): about `POINTS_PER_OBJECT` of its points, or without
    points its box's surface; None for a centre only."""
    if obj.points is not None and len(obj.points):
        return obj.points[:: max(1, len(obj.points) // POINTS_PER_OBJECT)]
    if obj.size is None:
        return None
    rotation = np.eye(3) if obj.rotation is None else obj.rotation
    return (_BOX_LATTICE * obj.size) @ rotation.T + obj.position


# Applying changes to a map ------------------------------------------------------------------
def apply_changes(
    prior: ObjectMap, local: ObjectMap, pose: np.ndarray, changes: Changes
) -> ObjectMap:
    """`prior` with `changes` applied: a moved object is put where it was observed (its points
    shifted with it, its other fields kept, `moved_from` / `moved_m` noted), a new object is added
    in the global frame (its id prefixed `new:` when taken, `new2:` ... when that is, `new: true`), a missing one is flagged
    `missing: true` (kept: one look is no proof that it is gone); the flag goes when a later view
    sees the object again, where it was or moved."""
    seen = {o.id: o.transformed(pose) for o in local}
    moved = {m.global_id: m for m in changes.moved}
    missing = set(changes.missing)
    found = set(changes.matched) | set(moved)
    objects = []
    for obj in prior:
        if obj.id in moved:
            obj = _moved(obj, seen[moved[obj.id].local_id], moved[obj.id])
        if obj.id in missing:
            obj = obj.replace(extra={**obj.extra, "missing": True})
        elif obj.id in found and "missing" in obj.extra:  # flagged before, seen again
            obj = obj.replace(extra={k: v for k, v in obj.extra.items() if k != "missing"})
        objects.append(obj)
    taken = {o.id for o in objects}
    for local_id in changes.new:
        new = seen[local_id]
        new_id = _free_id(local_id, taken)
        taken.add(new_id)
        objects.append(new.replace(id=new_id, extra={**new.extra, "new": True}))
    return prior.with_objects(objects)


def _free_id(local_id: str, taken: set[str]) -> str:
    """`local_id`, else `new:local_id` (then `new2:`, `new3:`, ...), within the id length."""
    candidate, number = local_id, 1
    while candidate in taken:
        prefix = "new:" if number == 1 else f"new{number}:"
        candidate = (prefix + local_id)[:MAX_ID_LENGTH]
        number += 1
    return candidate


def _moved(obj: SemanticObject, observed: SemanticObject, change: Moved) -> SemanticObject:
    shift = observed.position - obj.position
    points = None if obj.points is None else obj.points + shift
    return obj.replace(
        position=observed.position,
        points=points,
        extra={**obj.extra, "moved_from": obj.position.tolist(), "moved_m": change.offset_m},
    )


# Reports of changes against a map that moved on ---------------------------------------------
class ReportConflict(Exception):
    """A change report no longer applies: the versions written since its base changed what it
    changes or relies on."""


def flags_to_clear(base: ObjectMap, changes: Changes) -> bool:
    """Whether a matched object carries a `missing` flag the report would clear (a change even
    when nothing moved, appeared or vanished)."""
    matched = set(changes.matched)
    return any(o.id in matched and "missing" in o.extra for o in base)


def check_still_applies(
    base: ObjectMap, current: ObjectMap, local: ObjectMap, pose: np.ndarray, changes: Changes
) -> None:
    """Raise `ReportConflict` when the versions written since `base` (the report's version; the
    latest is `current`) touched what the report changes or relies on: an object it moves,
    flags missing or matched was changed or removed, or an object added since lies within
    1 m of where the report adds one (two devices reporting one new chair)."""
    before = {o.id: o for o in base}
    after = {o.id: o for o in current}
    touched = {i for i, o in before.items() if i not in after or not _same(o, after[i])}
    relied = {m.global_id for m in changes.moved} | set(changes.missing) | set(changes.matched)
    clash = sorted(relied & touched)
    if clash:
        raise ReportConflict(f"objects changed since the report's version: {', '.join(clash[:10])}")
    added = [o for i, o in after.items() if i not in before]
    if added and changes.new:
        R, t = pose[:3, :3], pose[:3, 3]
        placed = {o.id: R @ o.position + t for o in local}
        for local_id in changes.new:
            for other in added:
                if np.linalg.norm(other.position - placed[local_id]) < NEW_CLASH_M:
                    raise ReportConflict(
                        f"new object {local_id} lies where object {other.id} was added since"
                    )


NEW_CLASH_M = 1.0
"""Two reports adding an object within this distance (m) of each other add the same object."""


def _same(a: SemanticObject, b: SemanticObject) -> bool:
    return (
        a.label == b.label
        and np.allclose(a.position, b.position, atol=1e-6)
        and (a.extra.get("missing") == b.extra.get("missing"))
    )
