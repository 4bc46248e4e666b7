"""The Localizer: association → clustering → hypotheses → decision, one incremental update at a time.

`Localizer(global_map, config).update(objects)` takes the local objects that are new or were
re-detected (same id = updated), grows the association sets, turns the best of them into
distinct pose hypotheses and decides (`decision.py`).  Each screened set is verified first
(`verification.consensus`: the pairs that disagree with the pose the others agree on are
rejected); only the chosen hypotheses get the full pose recovery (global search, robust ICP),
after which their evidence is measured, they are ranked by it, same-place duplicates are
merged and a calibrated confidence is attached.  `update(objects, answer=False)` only grows
the association sets, for callers that read the answer later (a replay reads only its last one).

Streaming: the poses of the last answer are kept per association set (keyed by its pairs and
whether it was refined).  A set that is unchanged at the next answer reuses its estimate; a set
that grew is recovered warm-started from the pose of its largest kept subset; a re-detected
local object drops the kept poses that used it.  Object clouds for pose recovery are prepared
once per object (`pose.cached_cloud`), so all Localizers of one map share them.

`localize(global_map, local_map)` replays a local map by its `seen` keyframes.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable
from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from semloc.association import (
    AssociationConfig,
    CandidateIndex,
    Describer,
    LabelResolution,
    label_report,
)
from semloc.changes import Changes, ChangesConfig, answer_changes
from semloc.clustering import ClusteringConfig, HierarchicalClustering, SetPairs
from semloc.decision import (
    DecisionConfig,
    RankBy,
    decide,
    distinct,
    local_anchor,
    rank_places,
    shipped_model,
)
from semloc.maps import MapError, ObjectMap, SemanticObject, unit_vector
from semloc.pose import PoseConfig, PoseEstimate, cached_cloud, estimate_pose
from semloc.results import Hypothesis, Result, Status, Step
from semloc.semantics import pair_weight
from semloc.transforms import centre_residual
from semloc.verification import (
    Evidence,
    MapSupport,
    VerificationConfig,
    Verified,
    verify_sets,
)

_COMPONENTS: dict[str, type[BaseModel]] = {
    "association": AssociationConfig,
    "clustering": ClusteringConfig,
    "pose": PoseConfig,
    "verification": VerificationConfig,
    "decision": DecisionConfig,
    "changes": ChangesConfig,
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
        self._pose_unrefined = config.pose.model_copy(update={"refine": False})
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
        self._similarity_of: dict[int, np.ndarray] = {}  # local index -> their similarity
        self._support = MapSupport(
            [], global_map.positions, config.verification, axis=global_map.sweep_order.axis
        )
        self._steps: list[Step] = []
        self._timing = {"association": 0.0, "clustering": 0.0, "pose": 0.0, "total": 0.0}

    @property
    def local_map(self) -> ObjectMap:
        """The local objects received so far (latest version of each)."""
        return ObjectMap(self._local.values(), up=self.local_up, name="local")

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
        self, objects: Iterable[SemanticObject] | ObjectMap, answer: bool = True
    ) -> Result | None:
        """Add new or re-detected local objects and return the current answer.

        With `answer=False` only the association sets grow (no hypotheses, no pose recovery,
        no decision) and None is returned; a later update with an answer sees the same sets.
        """
        start = time.perf_counter()
        if isinstance(objects, ObjectMap) and objects.up is not None and self.local_up is None:
            self.local_up = objects.up
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
        detections = self._associate(objects)
        tick = time.perf_counter()
        if detections:
            self._clustering.update(
                np.array([o.position for o in self._local.values()]).reshape(-1, 3),
                list(self._local),
                detections,
            )
        tock = time.perf_counter()
        status: Status | None = None
        reason = ""
        hypotheses: list[Hypothesis] = []
        if answer:
            hypotheses = self._hypotheses()
            status, reason = decide(hypotheses, self.config.decision, self.config.rank_by)
            if not hypotheses:
                reason = self._why_no_sets()
            scores = [h.score for h in hypotheses]
        else:
            scores = self._clustering.top_scores(self.config.top_k, min_size=2)
        end = time.perf_counter()
        self._add_timing(tick - start, tock - tick, end - tock)
        self._steps.append(
            Step(
                step=len(self._steps),
                n_local=len(self._local),
                n_sets=self._clustering.n_sets,
                top_scores=sorted(scores, reverse=True),
                ms=(end - start) * 1e3,
                status=status,
            )
        )
        if status is None:
            return None
        return Result.of(
            status, hypotheses, self._steps, self._timing, reason, self._changes(hypotheses)
        )

    def _changes(self, hypotheses: list[Hypothesis]) -> Callable[[], Changes] | None:
        """What the best hypothesis says changed (`semloc.changes`), computed when first read:
        the local objects and their candidates are taken now (later updates replace them)."""
        if not hypotheses or hypotheses[0].pose is None:
            return None
        candidates = {oid: self._candidates_of[i] for oid, i in self._local_index.items()}
        local, best, config = list(self._local.values()), hypotheses[0], self.config.changes
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
        """Register objects; return candidate global indices per local index."""
        detections: dict[int, np.ndarray] = {}
        if self._describer is not None:
            objects = self._describer.describe(objects)
        for obj in objects:
            index = self._local_index.setdefault(obj.id, len(self._local_index))
            if obj.id in self._local:  # re-detected: poses that used the old version are stale
                self._poses = {
                    k: v for k, v in self._poses.items() if all(l != index for _, l in k[1])
                }
            self._local[obj.id] = obj
            detections[index], self._similarity_of[index] = self._candidates.weighted(obj)
            self._candidates_of[index] = detections[index]
            self._support.assign(index, detections[index])
        return detections

    # Hypotheses -------------------------------------------------------------------------
    def _hypotheses(self) -> list[Hypothesis]:
        """Distinct places, best first: verify many sets by closed-form consensus, recover the
        poses of the top-k, measure their evidence, rank, merge duplicates, attach confidence."""
        cfg = self.config
        by_size = cfg.rank_by in ("residual", "evidence")
        sets = self._clustering.top_pairs(cfg.screened_sets, min_size=2, largest_first=by_size)
        local_xyz = np.array([o.position for o in self._local.values()]).reshape(-1, 3)
        screened = [c for c in self._verified_all(sets, local_xyz) if len(c.pairs) >= 2]
        if by_size:  # pairs include the guided matches
            screened.sort(key=lambda c: (-len(c.pairs), round(c.residual, 9), -c.score))
        places = [(c.pairs, c.pose) for c in screened]
        anchor = local_anchor(local_xyz)
        chosen = [screened[i] for i in distinct(places, cfg.top_k, cfg.decision, anchor)]
        previous, self._poses = self._poses, {}
        hypotheses = [
            self._hypothesis(rank, c, local_xyz, previous) for rank, c in enumerate(chosen, 1)
        ]
        return rank_places(hypotheses, cfg.rank_by, cfg.decision, shipped_model(), anchor)

    def _verified_all(self, sets: SetPairs, local_xyz: np.ndarray) -> list[Verified]:
        """Each set verified against the map (`semloc.verification.verify_sets`)."""
        return verify_sets(
            sets.pairs, sets.sizes, sets.scores, local_xyz, self.global_map.positions,
            (self.local_up, self.global_map.up), self.config.verification, self._support,
        )  # fmt: skip

    def _hypothesis(
        self, rank: int, verified: Verified, local_xyz: np.ndarray, previous: dict
    ) -> Hypothesis:
        """Full pose recovery of a verified set's inlier pairs, and its evidence."""
        local_objects = list(self._local.values())
        globals_ = [self.global_map[g] for g, _ in verified.pairs]
        locals_ = [local_objects[l] for _, l in verified.pairs]
        l_xyz = np.array([o.position for o in locals_])
        g_xyz = np.array([o.position for o in globals_])
        matched = (l_xyz, g_xyz, locals_, globals_)
        refine = rank <= self.config.refine_top
        estimate = self._recover(verified.pairs, refine, previous, matched)
        residual, features = verified.residual, None
        tolerance = self.config.verification.inlier_tolerance
        if estimate is not None:
            residual = centre_residual(estimate.T, l_xyz, g_xyz)
            if refine and residual > tolerance >= verified.residual:
                # ICP on points that do not fit dragged the pose off the agreeing centres
                estimate = self._recover(verified.pairs, False, previous, matched)
                assert estimate is not None  # the closed form was determined before
                residual = centre_residual(estimate.T, l_xyz, g_xyz)
        pose = None if estimate is None else estimate.T
        if estimate is not None:
            features = Evidence(
                len(verified.pairs), len(verified.rejected), residual, estimate.fitness,
                verified.support, verified.conflicts, len(local_xyz),
                self._semantic_weight(verified.pairs),
            ).features()  # fmt: skip
        ids = self.global_map.ids
        return Hypothesis(
            rank=rank,
            score=verified.score,
            pairs=[(g.id, l.id) for g, l in zip(globals_, locals_)],
            pose=pose,
            fitness=None if estimate is None else estimate.fitness,
            rmse=None if estimate is None else estimate.rmse,
            residual=None if pose is None else residual,
            method="" if estimate is None else estimate.method,
            features=features,
            rejected=[(str(ids[g]), local_objects[l].id) for g, l in verified.rejected],
        )

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
        return label_report(self._candidates, self._local.values())

    def _recover(
        self, pairs: list[tuple[int, int]], refine: bool, previous: dict, matched: tuple
    ) -> PoseEstimate | None:
        """The set's pose: reused when the previous answer recovered it for the same pairs
        (same object versions), else recovered, warm-started from the pose of the largest
        subset of its pairs that the previous answer recovered (refined ones first)."""
        key: _PoseKey = (refine, frozenset(pairs))
        if key in previous:
            estimate = previous[key]
        else:
            l_xyz, g_xyz, locals_, globals_ = matched
            pose_cfg = self.config.pose if refine else self._pose_unrefined
            estimate = estimate_pose(
                l_xyz,
                g_xyz,
                [cached_cloud(o, pose_cfg) for o in locals_],
                [cached_cloud(o, pose_cfg) for o in globals_],
                self.local_up,
                self.global_map.up,
                pose_cfg,
                init=_warm_start(key[1], previous),
            )
        self._poses[key] = estimate
        return estimate


_PoseKey = tuple[bool, frozenset[tuple[int, int]]]  # (refined, pairs)


def _warm_start(pairs: frozenset, previous: dict[_PoseKey, PoseEstimate | None]):
    """The pose of the largest recovered subset of `pairs` (refined first), or None."""
    subsets = [
        (len(k[1]), k[0], estimate.T)
        for k, estimate in previous.items()
        if estimate is not None and k[1] <= pairs
    ]
    return max(subsets, key=lambda s: s[:2])[2] if subsets else None


EMPTY_LOCAL_MAP = "the local map has no objects"


def localize(
    global_map: ObjectMap,
    local_map: ObjectMap,
    config: LocalizerConfig | None = None,
    *,
    progress: Callable[[int, int], None] | None = None,
    **overrides: Any,
) -> Result:
    """Replay `local_map` by its `seen` keyframes (one update per keyframe); the last Result.

    Only the last update builds hypotheses and recovers poses: the answers in between would
    not be read.  `progress(done, total)` is called after each update.
    """
    if not isinstance(local_map, ObjectMap):
        raise TypeError(f"localize needs an ObjectMap as local map, got {type(local_map).__name__}")
    localizer = Localizer(global_map, config, local_up=local_map.up, **overrides)
    keyframes = sorted(set(local_map.seen.tolist()))
    if not keyframes:
        return Result(status="failed", pose=None, hypotheses=[], reason=EMPTY_LOCAL_MAP)
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
