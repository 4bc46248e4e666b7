"""Staying at a place once it is found: check the tracked pose on every update's objects, follow
odometry drift, and end the claim as soon as new objects contradict it.

After a `localized` answer the Localizer tracks that place instead of searching again (the
search's cost grows with the local objects; tracking costs a lookup per new object):

* **Check.**  Each new or re-detected object with map candidates is put where the tracked pose
  says it is; it *supports* the place when a candidate lies within `track_tolerance` plus a
  quarter of that candidate's diagonal (a partial view moves a large object's centre) of
  that point, and *contradicts* it otherwise.  Objects without candidates say nothing.
* **Follow.**  The supporting pairs are kept, newest last (one per map object and per local
  object); the pose is refitted to the newest `pairs` of them, warm-started from the tracked
  pose.  Odometry drift is slow, so the newest objects, seen near the robot, give the pose
  that is right *now* where the robot is.
* **Contradiction.**  An update whose contradicting objects number at least `contradiction`
  and more than twice its supporting ones, or the last `CONTRADICTION_UPDATES` updates
  together holding at least `contradiction` + 1 contradicting objects and more than twice as
  many as supporting ones, end the claim at once (`ambiguous`, reason `"contradicted"`): the
  robot was carried elsewhere, its odometry jumped, or the place was a wrong one.  One moved
  chair among agreeing objects does not.
* **Lapse.**  When fewer than `min_pairs` supporting pairs remain in the window (the robot saw
  nothing it could check for a while), the claim is not renewed and the search resumes on the
  window.
"""

from __future__ import annotations

from collections import OrderedDict, deque
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from semloc.maps import ObjectMap, SemanticObject

CONTRADICTION_UPDATES = 3
"""How many of the latest updates are weighed together for a contradiction."""

CONTRADICTED = "contradicted"
"""The reason of the answer whose new objects ended a claim."""


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


@dataclass(frozen=True)
class Verdict:
    """What one update's objects say of the tracked place."""

    supported: list[tuple[int, str]]  # (global index, local id)
    contradicting: list[str]  # local ids


def check(
    pose: np.ndarray,
    objects: Iterable[SemanticObject],
    candidates: Mapping[str, np.ndarray],
    global_positions: np.ndarray,
    allowance: np.ndarray,
) -> Verdict:
    """Each object with candidates, put by `pose` (T_global_local) into the global frame:
    supported by its nearest candidate g within `allowance[g]` (metres), else contradicting."""
    supported, contradicting = [], []
    R, t = pose[:3, :3], pose[:3, 3]
    for obj in objects:
        found = candidates.get(obj.id)
        if found is None or not len(found):
            continue
        gaps = np.linalg.norm(global_positions[found] - (R @ obj.position + t), axis=1)
        nearest = int(np.argmin(gaps))
        if gaps[nearest] <= allowance[found[nearest]]:
            supported.append((int(found[nearest]), obj.id))
        else:
            contradicting.append(obj.id)
    return Verdict(supported, contradicting)


def allowances(global_map: ObjectMap, tolerance: float) -> np.ndarray:
    """How far (m) from each map object a detection of it may land: `tolerance` plus a quarter
    of the object's diagonal (its box, else its points), since a partial view moves a centre
    towards the side seen, by up to about half the object's extent."""
    sizes = global_map.sizes
    diagonal = np.linalg.norm(sizes, axis=1)
    for i in np.flatnonzero(np.isnan(diagonal)):
        points = global_map[int(i)].points
        diagonal[i] = (
            0.0 if points is None or not len(points) else np.linalg.norm(np.ptp(points, axis=0))
        )
    return tolerance + 0.25 * diagonal


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
    ) -> None:
        self.pose = pose
        self.confidence = confidence
        self.score = score
        self.config = config
        self.pairs: OrderedDict[str, int] = OrderedDict()  # local id -> global index
        self._verdicts: deque[Verdict] = deque(maxlen=CONTRADICTION_UPDATES)
        self.accept(Verdict(list(pairs), []))

    def contradicted(self, verdict: Verdict) -> int:
        """How many of the latest updates (this one included) contradict the place: 0 when
        they do not."""
        self._verdicts.append(verdict)
        least = self.config.contradiction
        against = len(verdict.contradicting)
        if against >= least and against > 2 * len(verdict.supported):
            return 1
        against = sum(len(v.contradicting) for v in self._verdicts)
        supporting = sum(len(v.supported) for v in self._verdicts)
        if against >= least + 1 and against > 2 * supporting:
            return len(self._verdicts)
        return 0

    def accept(self, verdict: Verdict) -> None:
        """Keep the verdict's supporting pairs (newest last, one per map and local object)."""
        for object_id in verdict.contradicting:
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

    def state(self, global_ids: Sequence[str]) -> dict[str, Any]:
        """What rebuilds this track (JSON types; map objects by id)."""
        verdicts = [[[[global_ids[g], l] for g, l in v.supported], v.contradicting]
                    for v in self._verdicts]  # fmt: skip
        return {
            "pose": self.pose.tolist(),
            "pairs": [[global_ids[g], l] for l, g in self.pairs.items()],
            "confidence": self.confidence,
            "score": self.score,
            "verdicts": verdicts,
        }

    @classmethod
    def restored(
        cls, state: dict[str, Any], index_of: Callable[[str], int], config: TrackingConfig
    ) -> Track:
        """The track of `state` (from `state()`); `index_of` maps a map object's id to its index."""
        pairs = [(index_of(g), str(l)) for g, l in state["pairs"]]
        track = cls(np.asarray(state["pose"], dtype=float), [], state["confidence"],
                    float(state["score"]), config)  # fmt: skip
        track.pairs = OrderedDict((l, g) for g, l in pairs)
        for supported, contradicting in state["verdicts"]:
            verdict = Verdict([(index_of(g), str(l)) for g, l in supported],
                              [str(l) for l in contradicting])  # fmt: skip
            track._verdicts.append(verdict)
        return track

    def newest(self, n: int) -> list[tuple[int, str]]:
        """The newest `n` supporting pairs (global index, local id), oldest first."""
        return [(g, l) for l, g in list(self.pairs.items())[-n:]]
