"""The Localizer: association → clustering → pose → decision, one incremental update at a time.

`Localizer(global_map, config).update(objects)` takes the local objects that are new or were
re-detected (same id = updated), grows the association sets, turns the best of them into
distinct pose hypotheses and decides:

    localized   the best hypothesis has ≥ `min_pairs` pairs, a fitness of at least
                `min_fitness` (its points land on the map) and dominates every *rival* in
                the terms of the ranking (more pairs or a clearly smaller residual; or a
                score / fitness larger by the factor 1 + margin); a rival has a different
                pose that shares less than `rival_overlap` of its pairs with the best one
                (one swapped association is a variant of the same answer, not a rival);
    ambiguous   hypotheses exist (≥ 2 pairs) but none dominates;
    failed      no association set has 2 or more pairs.

Hypotheses are distinct locations: walking down the ranked association sets, a set whose
closed-form pose is within `distinct_rotation_deg` / `distinct_translation` of a hypothesis
already listed (or whose pairs are a subset of one) is skipped, so the top-k are k different
answers.  Only the chosen hypotheses get the full pose recovery (global search, robust ICP).

`localize(global_map, local_map)` replays a local map by its `seen` keyframes.
"""

from __future__ import annotations

import time
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from semloc.association import AssociationConfig, CandidateIndex
from semloc.clustering import AssociationSet, ClusteringConfig, HierarchicalClustering
from semloc.maps import MapError, ObjectMap, SemanticObject
from semloc.metrics import pose_error
from semloc.pointsets import voxel_downsample
from semloc.pose import PoseConfig, PoseEstimate, align_positions_batch, estimate_pose

Status = Literal["localized", "ambiguous", "failed"]


class DecisionConfig(BaseModel):
    """When a hypothesis counts as the answer, and when two hypotheses are the same place."""

    model_config = ConfigDict(extra="forbid")

    min_pairs: int = Field(3, ge=2, description="Pairs the best set needs to be 'localized'.")
    min_fitness: float = Field(
        0.3,
        ge=0,
        le=1,
        description="Fitness the best hypothesis needs to be 'localized': the share of its local "
        "points (without points: of its matched centres) that land on the global map; 0 = off.",
    )
    margin: float = Field(
        0.5,
        ge=0,
        description="Dominance factor over every rival: residual (m) at least (1 + margin) x "
        "the best's plus residual_floor, or score / fitness at most 1 / (1 + margin) of it.",
    )
    residual_floor: float = Field(
        0.02, ge=0, description="Residual difference (m) below which two hypotheses tie."
    )
    rival_overlap: float = Field(
        0.5,
        ge=0,
        le=1,
        description="A hypothesis sharing at least this share of pairs with the best one is a "
        "variant of it, not a rival, when deciding dominance.",
    )
    distinct_rotation_deg: float = Field(
        10.0, gt=0, description="Hypotheses closer than this in rotation are the same place."
    )
    distinct_translation: float = Field(
        0.3, gt=0, description="Hypotheses closer than this (m) in translation are the same place."
    )


_COMPONENTS: dict[str, type[BaseModel]] = {
    "association": AssociationConfig,
    "clustering": ClusteringConfig,
    "pose": PoseConfig,
    "decision": DecisionConfig,
}


class LocalizerConfig(BaseModel):
    """All settings, one model per component.  Component fields may also be given flat:
    `LocalizerConfig(gamma=0.7, delta=0.4)` sets `clustering.gamma` and `association.delta`."""

    model_config = ConfigDict(extra="forbid")

    association: AssociationConfig = Field(default_factory=AssociationConfig)
    clustering: ClusteringConfig = Field(default_factory=ClusteringConfig)
    pose: PoseConfig = Field(default_factory=PoseConfig)
    decision: DecisionConfig = Field(default_factory=DecisionConfig)
    top_k: int = Field(10, ge=1, description="How many distinct hypotheses are reported.")
    screened_sets: int = Field(
        60, ge=1, description="Association sets screened by closed-form pose for hypotheses."
    )
    refine_top: int = Field(
        3,
        ge=0,
        description="How many of the best hypotheses get robust ICP (the rest: closed "
        "form or search, with fitness).",
    )
    rank_by: Literal["residual", "score", "fitness"] = Field(
        "residual",
        description="Order of the reported hypotheses: 'residual' (most pairs, then smallest "
        "residual of the aligned object centres), 'score' (the paper's clustering score) or "
        "'fitness' (point-set fitness of the recovered pose).",
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


@dataclass
class Hypothesis:
    """One candidate answer: an association set and the pose it implies."""

    rank: int
    score: float
    pairs: list[tuple[str, str]]  # (global id, local id)
    pose: np.ndarray | None
    fitness: float | None = None
    rmse: float | None = None
    residual: float | None = None  # RMS distance (m) of aligned local centres to their partners
    method: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {
            "rank": self.rank,
            "score": round(self.score, 6),
            "pairs": [{"global": g, "local": l} for g, l in self.pairs],
            "pose": None if self.pose is None else np.round(self.pose, 9).tolist(),
            "fitness": None if self.fitness is None else round(self.fitness, 6),
            "rmse": None if self.rmse is None else round(self.rmse, 6),
            "residual": None if self.residual is None else round(self.residual, 6),
            "method": self.method,
        }


@dataclass
class Step:
    """What one update did: local objects so far, sets in the pool, top scores, time."""

    step: int
    n_local: int
    n_sets: int
    top_scores: list[float]
    ms: float
    status: Status = "failed"

    def to_dict(self) -> dict[str, Any]:
        return {
            "step": self.step,
            "n_local": self.n_local,
            "n_sets": self.n_sets,
            "top_scores": [round(s, 6) for s in self.top_scores],
            "ms": round(self.ms, 3),
            "status": self.status,
        }


@dataclass
class Result:
    """The answer after an update: status, best pose, ranked hypotheses and per-step records."""

    status: Status
    pose: np.ndarray | None
    hypotheses: list[Hypothesis]
    steps: list[Step] = field(default_factory=list)
    timing_ms: dict[str, float] = field(default_factory=dict)

    @classmethod
    def of(
        cls, status: Status, hypotheses: list[Hypothesis], steps: list[Step], timing_ms: dict
    ) -> Result:
        """The result of an update: the pose is the best hypothesis's unless `failed`."""
        pose = hypotheses[0].pose if hypotheses and status != "failed" else None
        return cls(status, pose, hypotheses, list(steps), dict(timing_ms))

    @property
    def best(self) -> Hypothesis | None:
        return self.hypotheses[0] if self.hypotheses else None

    def to_dict(self) -> dict[str, Any]:
        return {
            "status": self.status,
            "pose": None if self.pose is None else np.round(self.pose, 9).tolist(),
            "hypotheses": [h.to_dict() for h in self.hypotheses],
            "steps": [s.to_dict() for s in self.steps],
            "timing_ms": {k: round(v, 3) for k, v in self.timing_ms.items()},
        }


class Localizer:
    """Incremental object-level relocalization against one global map."""

    def __init__(
        self,
        global_map: ObjectMap,
        config: LocalizerConfig | None = None,
        local_up: Any = None,
        **overrides: Any,
    ) -> None:
        if config is None:
            config = LocalizerConfig(**overrides)
        elif overrides:
            config = LocalizerConfig(**{**config.model_dump(), **overrides})
        self.config = config
        if config.association.computed_descriptor is not None:
            from semloc.descriptors import with_descriptors

            global_map = with_descriptors(global_map, config.association.computed_descriptor)
        self.global_map = global_map
        self.local_up = None if local_up is None else np.asarray(local_up, dtype=float)
        self._candidates = CandidateIndex(global_map, config.association)
        self._pose_unrefined = config.pose.model_copy(update={"refine": False})
        self._global_clouds: dict[int, np.ndarray | None] = {}
        self._local_clouds: dict[str, np.ndarray | None] = {}
        self._clustering = HierarchicalClustering(
            global_map.positions, list(global_map.ids), config.clustering
        )
        self._local: dict[str, SemanticObject] = {}
        self._local_index: dict[str, int] = {}
        self._steps: list[Step] = []
        self._timing = {"association": 0.0, "clustering": 0.0, "pose": 0.0, "total": 0.0}

    @property
    def local_map(self) -> ObjectMap:
        """The local objects received so far (latest version of each)."""
        return ObjectMap(self._local.values(), up=self.local_up, name="local")

    @property
    def n_sets(self) -> int:
        return self._clustering.n_sets

    def update(self, objects: Iterable[SemanticObject] | ObjectMap) -> Result:
        """Add new or re-detected local objects and return the current answer."""
        start = time.perf_counter()
        if isinstance(objects, ObjectMap) and objects.up is not None and self.local_up is None:
            self.local_up = objects.up
        objects = list(objects)
        for obj in objects:
            if not isinstance(obj, SemanticObject):
                raise MapError(f"update() takes SemanticObject items, got {type(obj).__name__}")
        detections = self._associate(objects)
        tick = time.perf_counter()
        if detections:
            self._clustering.update(
                np.array([o.position for o in self._local.values()]).reshape(-1, 3),
                list(self._local),
                detections,
            )
        tock = time.perf_counter()
        hypotheses = self._hypotheses()
        status = self._decide(hypotheses)
        end = time.perf_counter()
        self._add_timing(tick - start, tock - tick, end - tock)
        self._steps.append(
            Step(
                step=len(self._steps),
                n_local=len(self._local),
                n_sets=self._clustering.n_sets,
                top_scores=sorted((h.score for h in hypotheses), reverse=True),
                ms=(end - start) * 1e3,
                status=status,
            )
        )
        return Result.of(status, hypotheses, self._steps, self._timing)

    def _add_timing(self, association: float, clustering: float, pose: float) -> None:
        for key, seconds in (
            ("association", association),
            ("clustering", clustering),
            ("pose", pose),
            ("total", association + clustering + pose),
        ):
            self._timing[key] += seconds * 1e3

    def _associate(self, objects: list[SemanticObject]) -> dict[int, np.ndarray]:
        """Register objects; return candidate global indices per local index."""
        detections: dict[int, np.ndarray] = {}
        kind = self.config.association.computed_descriptor
        if kind is not None:
            from semloc.descriptors import describe_objects

            objects = describe_objects(objects, kind)
        for obj in objects:
            index = self._local_index.setdefault(obj.id, len(self._local_index))
            self._local[obj.id] = obj
            self._local_clouds[obj.id] = _cloud(obj.points, self.config.pose)
            detections[index] = self._candidates.candidates(obj)
        return detections

    # Hypotheses -------------------------------------------------------------------------
    def _hypotheses(self) -> list[Hypothesis]:
        """Distinct places, best first: screen many sets by closed form, refine the top-k."""
        cfg = self.config
        by_size = cfg.rank_by == "residual"
        sets = self._clustering.top(cfg.screened_sets, min_size=2, largest_first=by_size)
        screened = list(zip(sets, *self._closed_forms(sets)))
        if by_size:
            screened.sort(key=lambda item: (-len(item[0]), item[2], -item[0].score))
        chosen: list[tuple[AssociationSet, np.ndarray | None, float]] = []
        for candidate in screened:
            if len(chosen) == cfg.top_k:
                break
            if not any(self._same_place(candidate, other) for other in chosen):
                chosen.append(candidate)
        hypotheses = [
            self._hypothesis(rank, s, residual) for rank, (s, _, residual) in enumerate(chosen, 1)
        ]
        hypotheses.sort(key=_RANKINGS[cfg.rank_by])
        for rank, h in enumerate(hypotheses, 1):
            h.rank = rank
        return hypotheses

    def _matched(self, aset: AssociationSet) -> tuple[list[SemanticObject], list[SemanticObject]]:
        local_objects = list(self._local.values())
        return (
            [self.global_map[g] for g, _ in aset.pairs],
            [local_objects[l] for _, l in aset.pairs],
        )

    def _closed_forms(
        self, sets: list[AssociationSet]
    ) -> tuple[list[np.ndarray | None], list[float]]:
        """Closed-form pose of each set and the RMS residual of its aligned centres (None and
        inf where under-determined); sets of one size are aligned in one batch."""
        poses: list[np.ndarray | None] = [None] * len(sets)
        residuals = [_INF] * len(sets)
        local_xyz = np.array([o.position for o in self._local.values()]).reshape(-1, 3)
        global_xyz = self.global_map.positions
        sizes = np.array([len(s) for s in sets])
        for size in np.unique(sizes):
            rows = np.flatnonzero(sizes == size)
            pairs = np.array([sets[i].pairs for i in rows])  # (S, size, 2): global, local
            l_xyz, g_xyz = local_xyz[pairs[..., 1]], global_xyz[pairs[..., 0]]
            T, determined = align_positions_batch(l_xyz, g_xyz, self.local_up, self.global_map.up)
            rms = centre_residuals(T, l_xyz, g_xyz)
            for i, pose, ok, r in zip(rows, T, determined, rms):
                if ok:
                    poses[i], residuals[i] = pose, float(r)
        return poses, residuals

    def _same_place(
        self,
        candidate: tuple[AssociationSet, np.ndarray | None, float],
        other: tuple[AssociationSet, np.ndarray | None, float],
    ) -> bool:
        if set(candidate[0].pairs) <= set(other[0].pairs):
            return True
        if candidate[1] is None or other[1] is None:
            return False
        rotation, translation = pose_error(candidate[1], other[1])
        d = self.config.decision
        return rotation < d.distinct_rotation_deg and translation < d.distinct_translation

    def _hypothesis(self, rank: int, aset: AssociationSet, residual: float) -> Hypothesis:
        """Full pose recovery of one set; `residual` is its closed-form centre residual."""
        globals_, locals_ = self._matched(aset)
        l_xyz = np.array([o.position for o in locals_])
        g_xyz = np.array([o.position for o in globals_])
        estimate: PoseEstimate | None = estimate_pose(
            l_xyz,
            g_xyz,
            [self._local_clouds[o.id] for o in locals_],
            [self._global_cloud(self.global_map.index_of(o.id)) for o in globals_],
            self.local_up,
            self.global_map.up,
            self.config.pose if rank <= self.config.refine_top else self._pose_unrefined,
        )
        pose = None if estimate is None else estimate.T
        if pose is not None and not np.isfinite(residual):  # pose found by the search
            residual = centre_residual(pose, l_xyz, g_xyz)
        return Hypothesis(
            rank=rank,
            score=aset.score,
            pairs=[(g.id, l.id) for g, l in zip(globals_, locals_)],
            pose=pose,
            fitness=None if estimate is None else estimate.fitness,
            rmse=None if estimate is None else estimate.rmse,
            residual=None if pose is None else residual,
            method="" if estimate is None else estimate.method,
        )

    def _global_cloud(self, index: int) -> np.ndarray | None:
        """The global object's points, downsampled once for pose recovery."""
        if index not in self._global_clouds:
            self._global_clouds[index] = _cloud(self.global_map[index].points, self.config.pose)
        return self._global_clouds[index]

    def _decide(self, hypotheses: list[Hypothesis]) -> Status:
        if not hypotheses:
            return "failed"
        best, d = hypotheses[0], self.config.decision
        if len(best.pairs) < d.min_pairs or best.pose is None:
            return "ambiguous"
        if best.fitness is not None and best.fitness < d.min_fitness:
            return "ambiguous"  # consistent centres, but the objects' points do not overlap
        rivals = [h for h in hypotheses[1:] if _is_rival(best, h, d.rival_overlap)]
        if all(_dominates(best, rival, self.config.rank_by, d) for rival in rivals):
            return "localized"
        return "ambiguous"


def _cloud(points: np.ndarray | None, pose: PoseConfig) -> np.ndarray | None:
    """An object's points voxel-downsampled as pose recovery would (None when it has none)."""
    if points is None or len(points) == 0:
        return None
    return voxel_downsample(points, pose.icp_voxel)


def centre_residual(pose: np.ndarray, local_xyz: np.ndarray, global_xyz: np.ndarray) -> float:
    """RMS distance (m) between aligned local centres and their global partners."""
    return float(centre_residuals(pose[None], local_xyz[None], global_xyz[None])[0])


def centre_residuals(poses: np.ndarray, local_xyz: np.ndarray, global_xyz: np.ndarray):
    """`centre_residual` of S sets at once: (S, 4, 4) poses, (S, m, 3) centres -> (S,)."""
    aligned = local_xyz @ np.swapaxes(poses[:, :3, :3], 1, 2) + poses[:, None, :3, 3]
    return np.sqrt(np.mean(np.sum((aligned - global_xyz) ** 2, axis=2), axis=1))


def _dominates(best: Hypothesis, rival: Hypothesis, rank_by: str, d: DecisionConfig) -> bool:
    """Whether `best` beats `rival` clearly, in the terms of the chosen ranking."""
    if rank_by == "score":
        return best.score >= (1.0 + d.margin) * rival.score
    if rank_by == "fitness":
        return (best.fitness or 0.0) >= (1.0 + d.margin) * (rival.fitness or 0.0)
    if len(rival.pairs) < len(best.pairs) or rival.residual is None:
        return True
    return rival.residual > (1.0 + d.margin) * (best.residual or 0.0) + d.residual_floor


_INF = float("inf")
_RANKINGS = {
    "score": lambda h: -h.score,
    "residual": lambda h: (-len(h.pairs), _INF if h.residual is None else h.residual, -h.score),
    "fitness": lambda h: (-(h.fitness if h.fitness is not None else -1.0), -h.score),
}


def _is_rival(best: Hypothesis, other: Hypothesis, max_overlap: float) -> bool:
    """Whether `other` is a different answer: it shares few of its pairs with `best`."""
    shared = len(set(best.pairs) & set(other.pairs))
    return shared < max_overlap * min(len(best.pairs), len(other.pairs))


def localize(
    global_map: ObjectMap,
    local_map: ObjectMap,
    config: LocalizerConfig | None = None,
    **overrides: Any,
) -> Result:
    """Replay `local_map` by its `seen` keyframes (one update per keyframe); the last Result."""
    localizer = Localizer(global_map, config, local_up=local_map.up, **overrides)
    result = Result(status="failed", pose=None, hypotheses=[])
    for keyframe in sorted(set(local_map.seen.tolist())):
        result = localizer.update([o for o in local_map if o.seen == keyframe])
    return result
