"""All of a Localizer's settings: one pydantic model per component, gathered in one.

Each component owns its settings and their documentation (`AssociationConfig`,
`ClusteringConfig`, ...); `LocalizerConfig` holds one of each and the few that span them (how
many hypotheses are reported, screened, refined, and how they are ranked).
"""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ConfigDict, Field, model_validator

from semloc.association import AssociationConfig
from semloc.changes import ChangesConfig
from semloc.clustering import ClusteringConfig
from semloc.decision import DecisionConfig, RankBy
from semloc.next_look import NextLookConfig
from semloc.places import RetrievalConfig
from semloc.pose import PoseConfig
from semloc.tracking import TrackingConfig
from semloc.verification import VerificationConfig
from semloc.window import WindowConfig

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

    @classmethod
    def of(cls, config: Any, overrides: dict[str, Any]) -> LocalizerConfig:
        """`config` (None: the defaults) with keyword `overrides` (flat or by component);
        `TypeError` when `config` is not a LocalizerConfig."""
        if config is not None and not isinstance(config, LocalizerConfig):
            raise TypeError(
                f"config must be a LocalizerConfig, got {type(config).__name__}; give settings "
                "as keywords (Localizer(global_map, gamma=0.7)) or LocalizerConfig(**settings)"
            )
        if config is None:
            return cls(**overrides)
        return cls(**{**config.model_dump(), **overrides}) if overrides else config

    @property
    def gamma(self) -> float:
        return self.clustering.gamma

    @property
    def delta(self) -> float:
        return self.association.delta
