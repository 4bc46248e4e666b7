"""What every baseline shares: the `Relocalizer` interface, hypotheses from association groups,
the shared pose recovery (`semloc.pose.estimate_pose`), results and decision; and the
`ImageRelocalizer` interface of the image methods (SIFT), which localize query keyframes
(`semloc.frontend.frames.RGBDFrame`) against a map's keyframes instead of objects.

A baseline subclasses `ObjectBaseline` and implements `_groups(local_objects)`, returning
association groups (score, [(global index, local index)]) best first.  `update(objects)` keeps
the latest version of every local object (same id = updated), recomputes the groups from the
whole local map (the baselines are not incremental), turns the best distinct groups into
ranked hypotheses with poses (`semloc.decision.distinct`) and decides with the Localizer's
rules (`semloc.decision.decide`, ranked by the baseline's own score) — only the association
step differs from semloc's.
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Sequence
from typing import Any, Protocol

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from semloc.decision import DecisionConfig, decide, distinct
from semloc.frontend.frames import KeyframeMap, RGBDFrame
from semloc.maps import MapError, ObjectMap, SemanticObject
from semloc.pose import PoseConfig, align_positions, cached_cloud, estimate_pose
from semloc.results import Hypothesis, Result, Step
from semloc.transforms import centre_residual

Group = tuple[float, list[tuple[int, int]]]  # (score, [(global index, local index)])


class Relocalizer(Protocol):
    """What the evaluation needs of a method: the Localizer's constructor and update."""

    global_map: ObjectMap

    def add(self, objects: Iterable[SemanticObject]) -> None:
        """Add new or re-detected local objects without an answer."""
        ...

    def update(self, objects: Iterable[SemanticObject]) -> Result:
        """Add new or re-detected local objects; the current answer."""
        ...


class ImageRelocalizer(Protocol):
    """What the evaluation needs of an image method: built on a `KeyframeMap` (the global
    map's keyframes, world frame), fed query keyframes posed in the local frame."""

    keyframe_map: KeyframeMap

    def update_frames(self, frames: Iterable[RGBDFrame], answer: bool = True) -> Result | None:
        """Add query keyframes; the current answer (None if not asked)."""
        ...


class BaselineConfig(BaseModel):
    """Settings shared by all baselines: hypotheses, pose recovery and the shared decision."""

    model_config = ConfigDict(extra="forbid")

    top_k: int = Field(10, ge=1, description="How many distinct hypotheses are reported.")
    pose: PoseConfig = Field(default_factory=PoseConfig)
    decision: DecisionConfig = Field(default_factory=DecisionConfig)


def consistency_groups(
    candidates: Sequence[tuple[int, int, float]],
    local_xyz: np.ndarray,
    global_xyz: np.ndarray,
    tolerance: float,
    min_size: int = 2,
) -> list[Group]:
    """Geometric-consistency grouping (as PCL's GeometricConsistencyGrouping used by SegMatch).

    `candidates`: (global index, local index, weight).  Each candidate seeds a group; the other
    candidates are added greedily (heaviest first) when one-to-one and pairwise consistent
    (|local distance - global distance| < tolerance) with every member.  Groups of at least
    `min_size` are returned, deduplicated, by (size, total weight) descending.
    """
    cands = sorted(candidates, key=lambda c: -c[2])
    n = len(cands)
    if n == 0:
        return []
    g = np.array([c[0] for c in cands])
    loc = np.array([c[1] for c in cands])
    w = np.array([c[2] for c in cands], dtype=float)
    dl = np.linalg.norm(local_xyz[loc][:, None] - local_xyz[loc][None], axis=2)
    dg = np.linalg.norm(global_xyz[g][:, None] - global_xyz[g][None], axis=2)
    ok = (np.abs(dl - dg) < tolerance) & (g[:, None] != g[None]) & (loc[:, None] != loc[None])
    seen: set[frozenset] = set()
    groups: list[Group] = []
    for seed in range(n):
        members = [seed]
        alive = ok[seed].copy()
        for j in range(n):
            if alive[j]:
                members.append(j)
                alive &= ok[j]
        key = frozenset(members)
        if len(members) < min_size or key in seen:
            continue
        seen.add(key)
        groups.append((float(w[members].sum()), [(int(g[j]), int(loc[j])) for j in members]))
    groups.sort(key=lambda item: (-len(item[1]), -item[0]))
    return groups


class ObjectBaseline:
    """Base class: the Localizer's interface over association groups found by `_groups`."""

    name = "baseline"
    incremental = False  # recomputes from the whole local map at every update
    config_class: type[BaselineConfig] = BaselineConfig

    def __init__(
        self, global_map: ObjectMap, config: BaselineConfig | None = None, local_up: Any = None
    ) -> None:
        self.config = config or self.config_class()
        self.global_map = global_map
        self.local_up = None if local_up is None else np.asarray(local_up, dtype=float)
        self._local: dict[str, SemanticObject] = {}
        self._steps: list[Step] = []
        self._timing = {"association": 0.0, "pose": 0.0, "total": 0.0}

    @property
    def local_map(self) -> ObjectMap:
        return ObjectMap(self._local.values(), up=self.local_up, name="local")

    def add(self, objects: Iterable[SemanticObject] | ObjectMap) -> None:
        """Remember new or re-detected local objects (the answer is recomputed when asked)."""
        self.update(objects, answer=False)

    def update(
        self, objects: Iterable[SemanticObject] | ObjectMap, answer: bool = True
    ) -> Result | None:
        """Add new or re-detected local objects and return the current answer (with
        `answer=False` only remember them: a baseline recomputes everything when asked)."""
        start = time.perf_counter()
        if isinstance(objects, ObjectMap) and objects.up is not None and self.local_up is None:
            self.local_up = objects.up
        for obj in list(objects):
            if not isinstance(obj, SemanticObject):
                raise MapError(f"update() takes SemanticObject items, got {type(obj).__name__}")
            self._local[obj.id] = obj
        if not answer:
            return None
        local = list(self._local.values())
        groups = self._groups(local) if len(local) >= 1 else []
        tick = time.perf_counter()
        hypotheses = self._hypotheses(groups, local)
        status, reason = decide(hypotheses, self.config.decision, "score")
        end = time.perf_counter()
        for key, value in (("association", tick - start), ("pose", end - tick)):
            self._timing[key] += value * 1e3
        self._timing["total"] += (end - start) * 1e3
        self._steps.append(
            Step(len(self._steps), len(local), len(groups),
                 [h.score for h in hypotheses], (end - start) * 1e3, status)
        )  # fmt: skip
        return Result.of(status, hypotheses, self._steps, self._timing, reason)

    # To implement -------------------------------------------------------------------------
    def _groups(self, local: list[SemanticObject]) -> list[Group]:
        raise NotImplementedError

    # Shared -------------------------------------------------------------------------------
    def _closed_form(self, pairs, local) -> np.ndarray | None:
        l_xyz = np.array([local[j].position for _, j in pairs])
        g_xyz = self.global_map.positions[[i for i, _ in pairs]]
        try:
            return align_positions(l_xyz, g_xyz, self.local_up, self.global_map.up)
        except ValueError:
            return None

    def _hypotheses(self, groups: list[Group], local: list[SemanticObject]) -> list[Hypothesis]:
        places = ((pairs, self._closed_form(pairs, local)) for _, pairs in groups)
        anchor = np.mean([o.position for o in local], axis=0) if local else None
        chosen = distinct(places, self.config.top_k, self.config.decision, anchor)
        return [
            self.make_hypothesis(rank, groups[i][0], groups[i][1], local)
            for rank, i in enumerate(chosen, 1)
        ]

    def make_hypothesis(
        self,
        rank: int,
        score: float,
        pairs: list[tuple[int, int]],
        local: list[SemanticObject],
        fallback: np.ndarray | None = None,
    ) -> Hypothesis:
        """A hypothesis whose pose comes from the shared pose recovery on `pairs`."""
        globals_ = [self.global_map[int(i)] for i, _ in pairs]
        locals_ = [local[j] for _, j in pairs]
        l_xyz = np.array([o.position for o in locals_]).reshape(-1, 3)
        g_xyz = np.array([o.position for o in globals_]).reshape(-1, 3)
        estimate = None
        if pairs:
            estimate = estimate_pose(
                l_xyz, g_xyz, [cached_cloud(o, self.config.pose) for o in locals_],
                [cached_cloud(o, self.config.pose) for o in globals_],
                self.local_up, self.global_map.up, self.config.pose,
            )  # fmt: skip
        pose = fallback if estimate is None else estimate.T
        return Hypothesis(
            rank=rank,
            score=float(score),
            pairs=[(g.id, o.id) for g, o in zip(globals_, locals_, strict=True)],
            pose=pose,
            fitness=None if estimate is None else estimate.fitness,
            rmse=None if estimate is None else estimate.rmse,
            residual=None if pose is None or not pairs else centre_residual(pose, l_xyz, g_xyz),
            method=self.name if estimate is None else f"{self.name}+{estimate.method}",
        )
