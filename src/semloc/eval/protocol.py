"""The paper's evaluation protocol on simulated sequences.

For every sequence, `starts` keyframes are drawn uniformly (seeded).  From each start the local
map is fused again (`SimulatedSequence.replay`: new odometry origin and ground truth) and each
method relocalizes against each global map kind: first as soon as more than 2 local objects
are seen (offset 0), again after +15 and +30 keyframes.  Success: 15 deg / 0.5 m.

The Localizer is incremental: it receives every keyframe's new or re-detected objects.  Between
evaluation keyframes only its association sets matter, so those intermediate updates run with a
cheap hypothesis stage (one set, closed form); the hypotheses are recomputed from the current
sets at every update, so the evaluated results are the ones of the full configuration.  The
baselines recompute everything from the local map, so they get the accumulated objects at the
evaluation keyframes.  `ms` is the wall time of the update at the evaluation keyframe.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from semloc.metrics import first_correct_rank, pose_error

OFFSETS = (0, 15, 30)
DEFAULT_METHODS = ("semloc", "clipper", "random-walk", "segmatch", "fpfh-ransac")
DESCRIPTOR_VARIANTS = ("semloc+geometric", "semloc+voxnet")
"""Opt-in methods: semloc with the shape-descriptor gate of that kind at its calibrated δ."""


class BenchConfig(BaseModel):
    """What a benchmark run does (the defaults are the full run)."""

    model_config = ConfigDict(extra="forbid")

    seed: int = Field(0, description="Base seed: sequence worlds, start keyframes, methods.")
    sequences: int = Field(6, ge=1, description="Simulated sequences (worlds).")
    size: str = Field("small", description="World size of the simulated sequences.")
    keyframes: int = Field(80, ge=40, description="Keyframes per sequence.")
    starts: int = Field(8, ge=1, description="Random start keyframes per sequence.")
    map_kinds: list[str] = Field(default_factory=lambda: ["reconstruction", "cad", "dynamic"])
    methods: list[str] = Field(default_factory=lambda: list(DEFAULT_METHODS))
    gammas: list[float] = Field(
        default_factory=lambda: [0.5, 0.6, 0.7, 0.8, 0.9, 0.95],
        description="Ablation over the clustering threshold (semloc, reconstruction maps).",
    )
    ablation_starts: int = Field(4, ge=0, description="Starts per sequence of the γ ablation.")
    ablation_top_k: int = Field(20, ge=1, description="Hypotheses kept in the γ ablation.")
    real: bool = Field(True, description="Add the real-layout pairs when their data is present.")
    real_walks: bool = Field(
        False, description="Also walk through the real scans (eval.realwalks)."
    )
    real_walk_count: int = Field(3, ge=1, description="Camera walks per real scan.")
    real_walk_keyframes: int = Field(80, ge=40, description="Keyframes per real walk.")
    real_walk_starts: int = Field(8, ge=1, description="Random start keyframes per real walk.")

    @classmethod
    def quick(cls, **overrides: Any) -> BenchConfig:
        """A small but meaningful subset: minutes on 2 cores."""
        base = dict(sequences=2, keyframes=60, starts=3, gammas=[0.5, 0.8, 0.95],
                    ablation_starts=2, real_walk_count=2, real_walk_starts=4)  # fmt: skip
        return cls(**{**base, **overrides})


def sequence_seed(config: BenchConfig, index: int) -> int:
    return config.seed * 1000 + index


def simulate(config: BenchConfig, index: int):
    """The simulated sequence `index` of a run (deterministic)."""
    from semloc.sim import simulate_sequence

    return simulate_sequence(
        sequence_seed(config, index), config.size, config.map_kinds, "walk",
        n_keyframes=config.keyframes,
    )  # fmt: skip


def start_keyframes(config: BenchConfig, index: int, n_keyframes: int, count: int) -> list[int]:
    """Uniformly drawn start keyframes (leaving room for +30 keyframes), seeded."""
    rng = np.random.default_rng([config.seed, index, 7])
    last = max(1, n_keyframes - 35)
    count = min(count, last)
    return sorted(int(s) for s in rng.choice(last, size=count, replace=False))


def make_method(name: str, global_map, local_up, settings: dict[str, Any] | None = None):
    """A method by name. `settings` are `LocalizerConfig` fields for the semloc methods (flat
    names such as `gamma`, `top_k`, `min_fitness`); the baselines have none."""
    from semloc.baselines import METHODS
    from semloc.localizer import LocalizerConfig

    if name == "semloc" or name in DESCRIPTOR_VARIANTS:
        overrides: dict[str, Any] = dict(settings or {})
        if name in DESCRIPTOR_VARIANTS:
            overrides["descriptor"] = name.removeprefix("semloc+")
        return METHODS["semloc"](global_map, LocalizerConfig(**overrides), local_up)
    return METHODS[name](global_map, None, local_up)


def run_attempts(
    seq,
    sequence: str,
    start: int,
    kind: str,
    method: str,
    label: str | None = None,
    settings: dict[str, Any] | None = None,
) -> tuple[list[dict], list[dict]]:
    """One start, one map kind, one method (with `make_method`'s `settings`): rows of
    results.csv and hypotheses.csv."""
    from semloc.localizer import Localizer

    replay = seq.replay(start, min(len(seq.recording.detections), start + 70))
    truth = replay.T_global_local
    gmap = replay.global_maps[kind]
    loc = make_method(method, gmap, replay.local_map.up, settings)
    incremental = isinstance(loc, Localizer)
    full_config = loc.config if incremental else None
    cheap = None
    if incremental:
        pose = full_config.pose.model_copy(update={"refine": False})
        cheap = full_config.model_copy(update={"top_k": 1, "screened_sets": 1, "pose": pose})
    seen: set[str] = set()
    targets: dict[int, int] = {}
    for kf in replay.keyframes:
        seen.update(o.id for o in kf.objects)
        if len(seen) > 2:
            targets = {kf.index + off: off for off in OFFSETS}
            break
    rows, hyps = [], []
    pending: dict = {}
    name = label or method
    for kf in replay.keyframes:
        pending.update({o.id: o for o in kf.objects})
        if kf.index in targets:
            if incremental:
                loc.config = full_config
            tick = time.perf_counter()
            result = loc.update(list(pending.values()))
            ms = (time.perf_counter() - tick) * 1e3
            pending.clear()
            best = result.hypotheses[0] if result.hypotheses else None
            rot = trans = None
            if best is not None and best.pose is not None:
                rot, trans = pose_error(best.pose, truth)
            base = dict(method=name, map_kind=kind, sequence=sequence, start=start,
                        offset=targets[kf.index])  # fmt: skip
            rows.append({
                **base, "n_local": result.steps[-1].n_local,
                "rank_of_first_correct": first_correct_rank(result.hypotheses, truth),
                "rot_err_deg": rot, "trans_err_m": trans, "ms": ms,
                "status": result.status,  # not a results.csv column; benchmarks read it
            })  # fmt: skip
            for h in result.hypotheses:
                if h.pose is not None:
                    r, t = pose_error(h.pose, truth)
                    hyps.append({**base, "rank": h.rank, "rot_err_deg": r, "trans_err_m": t})
        elif incremental and pending:
            loc.config = cheap
            loc.update(list(pending.values()))
            pending.clear()
    return rows, hyps


# Real layouts (the importers' samples), when their data is present -------------------------
REAL_PAIRS = {
    "3rscan/scene_2->scene_1": "rscan",
    "scan2cad/scene0470_00:scan->cad": "scan2cad",
}


def real_maps(data: str, pair: str):
    """(global map, local map, true T_global_local) of a real pair under the folder `data`."""
    from pathlib import Path

    root = Path(data)
    if REAL_PAIRS[pair] == "rscan":
        from semloc.io.rscan import load_rscan

        folder = root / "3rscan_subscans"
        return load_rscan(folder / "scene_1"), load_rscan(folder / "scene_2"), np.eye(4)
    from semloc.io.scan2cad import load_scan2cad

    maps = load_scan2cad(root / "scan2cad" / "scene0470_00")
    return maps.cad, maps.scan, np.eye(4)


def run_real_attempt(data: str, pair: str, method: str) -> tuple[list[dict], list[dict]]:
    """One real pair, one method: the whole local map at once (map_kind 'real')."""
    gmap, local, truth = real_maps(data, pair)
    loc = make_method(method, gmap, local.up)
    tick = time.perf_counter()
    result = loc.update(list(local))
    ms = (time.perf_counter() - tick) * 1e3
    base = dict(method=method, map_kind="real", sequence=pair, start=0, offset=0)
    best = result.hypotheses[0] if result.hypotheses else None
    rot = trans = None
    if best is not None and best.pose is not None:
        rot, trans = pose_error(best.pose, truth)
    row = {**base, "n_local": len(local), "rank_of_first_correct":
           first_correct_rank(result.hypotheses, truth), "rot_err_deg": rot,
           "trans_err_m": trans, "ms": ms}  # fmt: skip
    hyps = []
    for h in result.hypotheses:
        if h.pose is not None:
            r, t = pose_error(h.pose, truth)
            hyps.append({**base, "rank": h.rank, "rot_err_deg": r, "trans_err_m": t})
    return [row], hyps
