"""Watching a tracked place's look-alike copies: was the robot carried into one?

A look-alike room differs from the tracked one where one of them lacks an object, so per copy
(`semloc.twins` of the claim's newest pairs: the copies of where the robot is) each update
weighs the objects that tell the two apart.  For the copy: a detection the place does not
explain (changed or contradicting) that lies where the copy holds a map object it may be, and,
with the sensor's coverage, a map object the look expects of the place that no detection
accounts for where the copy holds none of its label.  For the place: a supporting detection
where the copy holds no map object it may be (`semloc.twins.copy_leads`).  Only the updates
with such objects are kept (`TWIN_UPDATES` of them): a robot carried off may see nothing that
tells the rooms apart for a while, and nothing seen is no news.  The copies are looked up again
when the robot walked on (the claim's newest pairs changed) and an update has objects against
the place or missing from its look, or a copy leads; the kept evidence follows the same copies.

The Localizer doubts the claim while a copy leads (`TWIN_DOUBTED`) and ends it when a copy
leads by `TWIN_KIDNAP` objects.
"""

from __future__ import annotations

from collections import deque
from typing import Any

import numpy as np

from semloc.decision import PLACE_APART
from semloc.map_context import MapContext
from semloc.maps import SemanticObject
from semloc.results import Hypothesis
from semloc.tracking import Track, Verdict
from semloc.twins import copy_holds, twin_lead, twin_pairs

TWIN_KIDNAP = 2
"""By how many objects of the latest updates a copy of the tracked place must explain them
better than the place to end the claim; leading by less, the copy makes the answer
`ambiguous` (`TWIN_DOUBTED`) and the claim is weighed on: an old map's change or a detector's
error is as likely to speak for the copy as against it, and the robot carried into a copy must
not be claimed where it was while the evidence says otherwise."""
TWIN_DOUBTED = "a copy of the tracked place explains the latest objects better"
TWIN_UPDATES = 12
"""The latest updates with objects that tell the tracked place from a copy weighed for it
(`TWIN_KIDNAP`): a view shows what tells look-alike rooms apart one object at a time, often
several updates apart."""
TRACK_ANCHORS = 8
"""Anchor pairs tried for the copies of a tracked place (`semloc.twins.ANCHORS` before a
claim): the copy the robot may be carried into must be among them, and a tracked place looks
its copies up only when its objects change; a copy keeping a random 70 % of the objects is
missed about once in 200 (three pairs: once in eight)."""


class CopyWatch:
    """The tracked place's copies and, per latest update that held any, the objects that
    told each copy from the place."""

    def __init__(self, context: MapContext, track_pairs: int) -> None:
        self.context, self.track_pairs = context, track_pairs
        self.copies: tuple[np.ndarray, list[np.ndarray]] | None = None  # (the map objects
        # they were found from, the copies as map motions)
        self.fits: deque[tuple[int, list[list[str]]]] = deque(maxlen=TWIN_UPDATES)

    def weigh(
        self, update: int, track: Track, verdict: Verdict, objects: list[SemanticObject],
        candidates: dict, unseen: np.ndarray,
    ) -> tuple[int, int, np.ndarray | None]:  # fmt: skip
        """By how many objects the latest updates show the robot in a copy of the tracked
        place rather than in it, over how many updates, and that copy (a map motion; (0, 0,
        None): no copy leads), after update `update`'s objects (see the module docstring)."""
        context = self.context
        against = {l for _, l in verdict.changed} | set(verdict.contradicting)
        members = np.array([g for g, _ in track.newest(self.track_pairs)])
        held = self.copies[0] if self.copies else np.zeros(0, dtype=int)
        if np.isin(members, held).sum() < 0.5 * len(members):  # the robot walked on
            leading = bool(self.fits) and self.lead(update)[0] > 0
            if not against and not len(unseen) and not leading:
                return 0, 0, None
            old = self.copies[1] if self.copies else []
            self.copies = (members, context.copies_of(members, TRACK_ANCHORS))
            self._carry_fits(old, self.copies[1], track.pose[:3, 3])
        motions = self.copies[1]
        if not motions:
            return 0, 0, None
        R, t, ids, codes = track.pose[:3, :3], track.pose[:3, 3], context.map.ids, context.codes
        by_id = {o.id: o for o in objects}
        # (where, the kinds it may be, key, whether it is evidence when the copy holds it)
        placed = [(R @ by_id[l].position + t, codes[candidates[l]], f"+local {l}", True)
                  for l in against]  # fmt: skip
        placed += [(R @ by_id[l].position + t, codes[candidates[l]], f"-map {ids[g]}", False)
                   for g, l in verdict.supported]  # fmt: skip
        placed += [(context.map.positions[u], codes[[u]], f"+map {ids[u]}", False)
                   for u in unseen]  # fmt: skip
        where = (context.map.positions, codes, context.allowances, context.tree)
        told = [[key for at, kinds, key, if_held in placed
                 if copy_holds(S, at, kinds, *where) == if_held] for S in motions]  # fmt: skip
        if any(told):
            self.fits.append((update, told))
        lead, updates, best = self.lead(update)
        return (lead, updates, motions[best]) if lead > 0 else (0, 0, None)

    def lead(self, update: int) -> tuple[int, int, int]:
        """The kept evidence's lead of the best copy over the tracked place, how many of the
        latest updates (up to `update`) it spans, and that copy's index
        (`semloc.twins.twin_lead`)."""
        lead, kept, best = twin_lead([told for _, told in self.fits])
        if lead <= 0:
            return 0, 0, 0
        return lead, update - self.fits[-kept][0] + 1, best

    def _carry_fits(self, old: list[np.ndarray], new: list[np.ndarray], at: np.ndarray) -> None:
        """The kept evidence of the copies `old`, for the copies `new` of the place the robot
        walked on to: a copy is the same when it puts the robot (`at`) within `PLACE_APART`
        of where the other does; a new copy has none."""
        moved = [S[:3, :3] @ at + S[:3, 3] for S in old]
        same = [next((i for i, m in enumerate(moved)
                      if np.linalg.norm(S[:3, :3] @ at + S[:3, 3] - m) < PLACE_APART), None)
                for S in new]  # fmt: skip
        kept = [(update, [[] if i is None else told[i] for i in same])
                for update, told in self.fits]  # fmt: skip
        self.fits.clear()
        self.fits.extend((u, told) for u, told in kept if any(told))

    def rival(self, place: Hypothesis, S: np.ndarray) -> Hypothesis:
        """The copy `S` (a map motion) of a tracked place, as its rival: the place's pairs
        moved onto the copy's objects, the place's pose moved by `S`."""
        assert place.pose is not None
        context = self.context
        index, ids = context.map.index_of, context.map.ids
        moved = twin_pairs(
            S, [(index(g), i) for i, (g, _) in enumerate(place.pairs)], context.map.positions,
            context.codes, context.config.verification.inlier_tolerance, context.tree,
        )  # fmt: skip
        pairs = [(str(ids[g]), place.pairs[i][1]) for g, i in moved]
        return Hypothesis(rank=2, score=float(len(pairs)), pairs=pairs, pose=S @ place.pose,
                          method="copy")  # fmt: skip

    def state(self) -> dict[str, list] | None:
        """The map objects the copies were found from, the kept evidence (None: no copies
        looked up yet)."""
        if self.copies is None:
            return None
        ids = self.context.map.ids
        return {
            "members": [str(ids[g]) for g in self.copies[0].tolist()],
            "fits": [[update, told] for update, told in self.fits],
        }

    def restore(self, state: dict[str, Any] | None, updates: int) -> None:
        """Back from `state()` (a Localizer at update `updates`)."""
        if state is None:
            return
        index_of = self.context.map.index_of
        members = np.array([index_of(g) for g in state["members"]], int)
        self.copies = (members, self.context.copies_of(members, TRACK_ANCHORS))
        fits = state["fits"]
        for i, fit in enumerate(fits):
            if fit and isinstance(fit[0], int) and len(fit) == 2:
                update, told = fit
            else:  # (a state of every update's objects, consecutive, or of counts: none)
                update, told = updates - len(fits) + 1 + i, fit
            if told and all(isinstance(keys, list) for keys in told) and any(told):
                self.fits.append((int(update), told))
