"""What the robot has seen: the window's objects with their map candidates, and the looks.

The search and the track both read the local objects of the window (`semloc.window`), each
with the map objects it may be (`CandidateIndex.weighted`: found once per object version), and
the sensor's coverage of the latest updates (`semloc.coverage`), from which the map objects a
pose puts in view that no detection accounts for are negative evidence.  `Sightings` keeps
them; nothing here decides.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Iterable
from typing import Any

import numpy as np

from semloc.changes import Changes, ChangesConfig, answer_changes
from semloc.coverage import Accounting, Coverage, Looks, checked_coverage, expected_objects
from semloc.map_context import MapContext
from semloc.maps import MapError, SemanticObject
from semloc.next_look import NextLookConfig, next_look
from semloc.results import Hypothesis, Support
from semloc.window import LocalWindow, WindowConfig

LOOKS_KEPT = 6
"""The search weighs the sensor's looks of this many latest updates (negative evidence)."""

Found = tuple[SemanticObject, np.ndarray, np.ndarray]  # (object, candidates, similarities)


class Sightings:
    """The window (`LocalWindow`), each window object's candidates, and the latest looks."""

    def __init__(self, context: MapContext, config: WindowConfig) -> None:
        self.context = context
        self.window = LocalWindow(config)
        self.found: dict[str, Found] = {}
        self.look: Coverage | None = None  # what the sensor covered at this update
        self.looks: deque[tuple[int, Coverage]] = deque(maxlen=LOOKS_KEPT)  # (update, look)
        self._unseen_of: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}  # this update's, by pose

    def add(
        self, objects: list[SemanticObject], position: np.ndarray | None, coverage: Any
    ) -> tuple[list[SemanticObject], bool]:
        """A new update: the robot at `position`, what its sensor covered, its objects.  The
        objects still in the window after the oldest retired, and whether any retired."""
        look = checked_coverage(coverage)
        self.look, self._unseen_of = look, {}
        self.window.advance(position)
        if look is not None:
            self.looks.append((self.window.updates, look))
        self.window.add(objects)
        retired = self.window.retire()
        for object_id in retired:
            self.found.pop(object_id, None)
        if retired:  # (an update larger than the window loses its oldest objects too)
            objects = [o for o in objects if o.id in self.window]
        self.register(objects)
        return objects, bool(retired)

    def register(self, objects: list[SemanticObject]) -> None:
        """The candidates of each new object version (kept while it is in the window)."""
        for obj in objects:
            found, similarity = self.context.candidates.weighted(obj)
            self.found[obj.id] = (obj, found, similarity)

    def state(self) -> dict[str, Any]:
        """The window's bookkeeping and the looks kept (JSON types; `Localizer.state`)."""
        looks = [[update, look.to_dict()] for update, look in self.looks]
        return {"window": self.window.state(), "looks": looks}

    def restore(self, state: dict[str, Any], objects: list[SemanticObject]) -> None:
        """Back from `state()` and the window's objects (`ValueError`: they do not match)."""
        self.window = LocalWindow.restored(self.window.config, state["window"], objects)
        self.register(objects)
        looks = state.get("looks", [])
        self.looks.extend((int(update), Coverage.from_dict(look)) for update, look in looks)

    def keep_latest(self, updates: int) -> None:
        """Only the objects of the latest `updates` updates (the older ones may show a place
        the robot has left)."""
        self.window.keep_only(self.window.since(self.window.updates - updates + 1))
        self.found = {i: f for i, f in self.found.items() if i in self.window}
        self._unseen_of = {}

    def candidates(self, objects: list[SemanticObject]) -> dict[str, np.ndarray]:
        return {o.id: self.found[o.id][1] for o in objects}

    def arrived_at(self, update: int) -> list[SemanticObject]:
        """The window objects last detected at `update`."""
        return [self.found[i][0] for i in self.window.since(update)
                if self.window.arrival(i).update == update]  # fmt: skip

    def map_label(self, obj: SemanticObject) -> str:
        """The map's label `obj` is read as (its most similar candidate's; its own without)."""
        _, found, similarity = self.found[obj.id]
        if len(found) == 0:
            return obj.label
        return str(self.context.map.labels[found[int(np.argmax(similarity))]])

    def changes_of(
        self, best: Hypothesis | None, tracked: bool, config: ChangesConfig
    ) -> Callable[[], Changes] | None:
        """What `best` says changed (`semloc.changes.answer_changes`), computed when first
        read: the window's objects and their candidates are taken now (later updates replace
        them).  A `tracked` place is judged on the objects detected since its oldest pair
        used, as the older ones drifted with the odometry."""
        if best is None or best.pose is None:
            return None
        window, local = self.window, self.window.objects
        if tracked:
            oldest = min(window.arrival(l).update for _, l in best.pairs)
            local = [o for o in local if window.arrival(o.id).update >= oldest]
        candidates, global_map = self.candidates(local), self.context.map
        return lambda: answer_changes(
            global_map, local, best.pose, best.pairs, config=config, candidates=candidates
        )

    def next_look(self, hypotheses: list[Hypothesis], config: NextLookConfig) -> Callable[[], Any]:
        """Where to look next to tell `hypotheses` apart (`semloc.next_look`), computed when
        called, from the window's objects as they are now (read as the map's labels)."""
        seen, global_map = self.window.objects, self.context.map
        labels = [self.map_label(o) for o in seen]
        positions = np.array([o.position for o in seen]).reshape(-1, 3)
        return lambda: next_look(hypotheses, global_map, labels, positions, config)

    def stale(self, local_ids: list[str], stale_m: float | None) -> bool:
        """Whether none of these local objects was detected within `stale_m` metres of travel
        (a claim is about where the robot is now)."""
        window = self.window
        found = [window.arrival(l).travel for l in local_ids if l in window]
        return stale_m is not None and (not found or window.travel - max(found) > stale_m)

    def unseen(
        self, pose: np.ndarray, looks: list[tuple[int, Coverage]] | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """The map objects `looks` (default: this update's) expect under `pose`, and those of
        them that no object detected since that look accounts for (`semloc.coverage`: a
        look's update holds every detection in it)."""
        if looks is None:
            assert self.look is not None
            looks = [(self.window.updates, self.look)]
        key = (pose.tobytes(), tuple(update for update, _ in looks))
        if key not in self._unseen_of:  # (the answer's support asks again for its best pose)
            self._unseen_of[key] = self._unseen_now(pose, looks)
        return self._unseen_of[key]

    def _unseen_now(
        self, pose: np.ndarray, looks: list[tuple[int, Coverage]]
    ) -> tuple[np.ndarray, np.ndarray]:
        """`unseen`, computed: each window object's distances to its candidates are measured
        once for all the looks (`semloc.coverage.Accounting`)."""
        context = self.context
        settings = Looks(move_m=context.config.tracking.move_m)
        positions = context.map.positions
        accounting = Accounting(pose, positions, context.allowances, settings.move_m)
        expected: set[int] = set()
        unseen: set[int] = set()
        for update, look in looks:
            origin = pose[:3, :3] @ look.origin + pose[:3, 3]
            near = np.array(context.tree.query_ball_point(origin, look.range_m + 0.5), dtype=int)
            seen = expected_objects(pose, [look], positions, context.diagonals, settings, near)
            expected.update(seen.tolist())
            if len(seen):
                local = [(i, (self.found[i][0].position, self.found[i][1]))
                         for i in self.window.since(update)]  # fmt: skip
                unseen.update(seen[~accounting.accounted(local)[seen]].tolist())
        return np.array(sorted(expected), dtype=int), np.array(sorted(unseen), dtype=int)

    def support_of(self, best: Hypothesis | None, counts: dict[str, int] | None) -> Support | None:
        """How recent the evidence of the best hypothesis is (its local objects' detections);
        `counts`: a tracked claim's judged objects (None: not tracked)."""
        if best is None or best.pose is None:
            return None
        window = self.window
        ids = [l for _, l in best.pairs if l in window]
        if not ids:
            return None
        arrivals = [window.arrival(l) for l in ids]
        keyframes = [self.found[l][0].seen for l in ids]
        missing_ids = None
        if self.looks:
            # the looks the count was made on: while tracked, this update's (when it has one)
            newest = counts is not None and self.look is not None and best.n_missing is not None
            shown, unseen = self.unseen(best.pose, None if newest else list(self.looks))
            if best.n_missing is None:  # (weighed for the refined ones only)
                best.n_missing, best.n_expected = len(unseen), len(shown)
            map_ids = self.context.map.ids
            missing_ids = tuple(str(map_ids[i]) for i in unseen[: Support.MISSING_IDS_KEPT])
        tracked, counts = counts is not None, counts or {}
        return Support(
            n_pairs=len(ids),
            seen=(min(keyframes), max(keyframes)),
            updates_ago=window.updates - min(a.update for a in arrivals),
            metres=window.travel - min(a.travel for a in arrivals),
            tracked=tracked,
            n_changed=counts.get("changed", 0),
            n_contradicting=counts.get("contradicting", 0),
            n_missing=best.n_missing,
            n_expected=best.n_expected,
            missing_ids=missing_ids,
        )


def checked_objects(objects: Any) -> list[SemanticObject]:
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


def robot_position(position: Any) -> np.ndarray | None:
    """The robot's position from a point (3,) or a pose (4, 4); None stays None."""
    if position is None:
        return None
    array = np.asarray(position, dtype=float)
    if array.shape == (4, 4):
        array = array[:3, 3]
    if array.shape != (3,) or not np.all(np.isfinite(array)):
        raise ValueError(f"position must be a finite point (3,) or pose (4, 4), got {array.shape}")
    return array
