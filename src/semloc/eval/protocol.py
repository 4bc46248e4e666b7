"""The paper's evaluation protocol on simulated sequences.

For every sequence, `starts` keyframes are drawn uniformly (seeded).  From each start the local
map is fused again (`SimulatedSequence.replay`: new odometry origin and ground truth) and each
method relocalizes against each global map kind: first as soon as more than 2 local objects
are seen (offset 0), again after +15 and +30 keyframes.  Success: 15 deg / 0.5 m.

Every method receives every keyframe's new or re-detected objects, and is asked for an answer
(`update(objects)`) only at the evaluation keyframes; in between `add(objects)` only grows
the Localizer's association sets (the baselines, which recompute
everything from the local map, just remember the objects).  `ms` is the wall time of the
update at the evaluation keyframe.

Image methods (SIFT) receive every keyframe's colour image and depth instead
(`update_frames`, same evaluation keyframes) and localize against the global map's keyframes
(`semloc.eval.images`); their `n_local` is the number of local objects seen, like the others'.

Day / night: the map kind `night` is the reconstruction map (made by day) with the query
images relit at night (`semloc.sim.illumination.NIGHT`); the `reconstruction` rows are its day
half.  Object methods get the same objects at night as by day (the paper's premise: instance
segmentation is robust to the illumination), so their night rows are their day rows (copied,
not run again: `with_night_rows`).
"""

from __future__ import annotations

import time
from collections import OrderedDict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from semloc.baselines import DEFAULT_METHODS, METHODS, make_method
from semloc.eval.images import keyframe_map, query_frame
from semloc.eval.success import first_correct_rank
from semloc.io.importers.rscan import load_rscan
from semloc.io.importers.scan2cad import load_scan2cad
from semloc.results import Result
from semloc.sim.mapkinds import MAP_KINDS
from semloc.sim.scenario import simulate_sequence
from semloc.transforms import pose_error

OFFSETS = (0, 15, 30)
NIGHT = "night"
"""The map kind of the night queries against the (day) reconstruction map."""


def conditions(map_kind: str) -> tuple[str, str]:
    """(global map kind, illumination of the queries) of a benchmark map kind."""
    return ("reconstruction", "night") if map_kind == NIGHT else (map_kind, "day")


class BenchConfig(BaseModel):
    """What a benchmark run does (the defaults are the full run)."""

    model_config = ConfigDict(extra="forbid")

    seed: int = Field(0, description="Base seed: sequence worlds, start keyframes, methods.")
    sequences: int = Field(
        6, ge=0, description="Simulated sequences (worlds); 0: only the real-data parts."
    )
    size: str = Field("small", description="World size of the simulated sequences.")
    keyframes: int = Field(80, ge=40, description="Keyframes per sequence.")
    starts: int = Field(8, ge=1, description="Random start keyframes per sequence.")
    map_kinds: list[str] = Field(default_factory=lambda: list(MAP_KINDS))
    methods: list[str] = Field(default_factory=lambda: list(DEFAULT_METHODS))
    gammas: list[float] = Field(
        default_factory=lambda: [0.5, 0.6, 0.7, 0.8, 0.9, 0.95],
        description="Ablation over the clustering threshold (semloc, reconstruction maps).",
    )
    ablation_starts: int = Field(4, ge=0, description="Starts per sequence of the γ ablation.")
    ablation_top_k: int = Field(20, ge=1, description="Hypotheses kept in the γ ablation.")
    night: bool = Field(
        True,
        description="Add the day / night pair: the reconstruction map (day) with night queries.",
    )
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
                    ablation_starts=2, real_walk_count=1, real_walk_starts=4)  # fmt: skip
        return cls(**{**base, **overrides})


def run_at_night(method: str) -> bool:
    """Whether the night queries are run for `method`: image methods only.  An object method
    gets the same objects at night as by day, so its night rows are its day rows
    (`with_night_rows`), not the same work done twice."""
    found = METHODS.get(method)
    return found is not None and found.images


def with_night_rows(rows: list[dict], day: str, night: str) -> list[dict]:
    """`rows` and a copy, as map kind `night`, of every object method's row of map kind `day`."""
    copies = [{**r, "map_kind": night} for r in rows
              if r["map_kind"] == day and not run_at_night(r["method"])]  # fmt: skip
    return rows + copies


def bench_kinds(config: BenchConfig) -> list[str]:
    """The map kinds of the comparison: the configured ones and, with `night`, `night`."""
    kinds = list(config.map_kinds)
    if config.night and "reconstruction" in kinds:
        kinds.insert(kinds.index("reconstruction") + 1, NIGHT)
    return kinds


def sequence_seed(config: BenchConfig, index: int) -> int:
    return config.seed * 1000 + index


def simulate(config: BenchConfig, index: int):
    """The simulated sequence `index` of a run (deterministic)."""
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


@dataclass(frozen=True)
class Attempt:
    """One chain of attempts: a start keyframe of a sequence, a map kind and a method.

    `label` names the method in the outputs (the method's name unless set); `settings` are its
    config fields (`make_method`); `ablation` rows go to ablation.csv.
    """

    sequence: int
    start: int
    map_kind: str
    method: str
    label: str = ""
    settings: dict[str, Any] = field(default_factory=dict)
    ablation: bool = False

    @property
    def name(self) -> str:
        return self.label or self.method


def attempt_rows(
    result: Result, truth: np.ndarray, base: dict[str, Any], ms: float
) -> tuple[dict, list[dict]]:
    """The results.csv row and the hypotheses.csv rows of one answer against `truth`."""
    best = result.best
    rot = trans = None
    if best is not None and best.pose is not None:
        rot, trans = pose_error(best.pose, truth)
    row = {
        **base, "n_local": result.steps[-1].n_local if result.steps else 0,
        "rank_of_first_correct": first_correct_rank(result.hypotheses, truth),
        "rot_err_deg": rot, "trans_err_m": trans, "ms": ms,
        "status": result.status,  # not a results.csv column; benchmarks read it
    }  # fmt: skip
    hyps = []
    for h in result.hypotheses:
        if h.pose is not None:
            r, t = pose_error(h.pose, truth)
            hyps.append({**base, "rank": h.rank, "rot_err_deg": r, "trans_err_m": t})
    return row, hyps


_REPLAYS: OrderedDict[tuple[int, int, int], tuple[Any, Any]] = OrderedDict()
_REPLAY_CACHE_SIZE = 12


def replayed(seq, start: int, stop: int):
    """`seq.replay(start, stop)`, remembered per process for the last few (sequence, start,
    stop): every method and map kind of one start replays the same keyframes, and the
    replay is deterministic, so the chains of a worker share one."""
    key = (id(seq), start, stop)
    hit = _REPLAYS.pop(key, None)
    if hit is None or hit[0] is not seq:  # an id can be reused by a new object
        hit = (seq, seq.replay(start, stop))
    _REPLAYS[key] = hit  # most recently used last
    while len(_REPLAYS) > _REPLAY_CACHE_SIZE:
        _REPLAYS.popitem(last=False)
    return hit[1]


def run_attempts(seq, attempt: Attempt) -> tuple[list[dict], list[dict]]:
    """One start, one map kind, one method: rows of results.csv and hypotheses.csv.

    Every keyframe's new or re-detected objects go to the method; only the evaluation
    keyframes ask for an answer (image methods: `run_image_attempts`)."""
    if METHODS[attempt.method].images:
        return run_image_attempts(seq, attempt)
    replay = replayed(seq, attempt.start, min(len(seq.recording.detections), attempt.start + 70))
    truth = replay.T_global_local
    method = make_method(
        attempt.method, replay.global_maps[conditions(attempt.map_kind)[0]],
        replay.local_map.up, attempt.settings,
    )  # fmt: skip
    targets = _targets(replay.keyframes)
    rows, hyps = [], []
    base = dict(method=attempt.name, map_kind=attempt.map_kind, sequence=f"seq{attempt.sequence}",
                start=attempt.start)  # fmt: skip
    for kf in replay.keyframes:
        if kf.index not in targets:
            if kf.objects:
                method.add(kf.objects)
            continue
        tick = time.perf_counter()
        result = method.update(kf.objects)
        ms = (time.perf_counter() - tick) * 1e3
        row, hyp_rows = attempt_rows(result, truth, {**base, "offset": targets[kf.index]}, ms)
        rows.append(row)
        hyps += hyp_rows
    return rows, hyps


def run_image_attempts(seq, attempt: Attempt) -> tuple[list[dict], list[dict]]:
    """`run_attempts` for an image method: every keyframe's colour image and depth (lit as the
    map kind says) until the last evaluation keyframe, answers at the evaluation keyframes."""
    replay = replayed(seq, attempt.start, min(len(seq.recording.detections), attempt.start + 70))
    kind, light = conditions(attempt.map_kind)
    method = make_method(attempt.method, keyframe_map(seq.world, kind), replay.local_map.up,
                         attempt.settings)  # fmt: skip
    targets = _targets(replay.keyframes)
    rows, hyps = [], []
    base = dict(method=attempt.name, map_kind=attempt.map_kind, sequence=f"seq{attempt.sequence}",
                start=attempt.start)  # fmt: skip
    seen: set[str] = set()
    for kf in replay.keyframes:
        if not targets or kf.index > max(targets):
            break
        seen.update(o.id for o in kf.objects)
        frame = query_frame(seq.world, kf, light)
        if kf.index not in targets:
            method.update_frames([frame], answer=False)
            continue
        tick = time.perf_counter()
        result = method.update_frames([frame])
        ms = (time.perf_counter() - tick) * 1e3
        base_row = {**base, "offset": targets[kf.index]}
        row, hyp_rows = attempt_rows(result, replay.T_global_local, base_row, ms)
        row["n_local"] = len(seen)
        rows.append(row)
        hyps += hyp_rows
    return rows, hyps


def _targets(keyframes) -> dict[int, int]:
    """Evaluation keyframes -> offset: when more than 2 objects are seen, then +15 and +30."""
    seen: set[str] = set()
    for kf in keyframes:
        seen.update(o.id for o in kf.objects)
        if len(seen) > 2:
            return {kf.index + off: off for off in OFFSETS}
    return {}


# Real layouts (the importers' samples), when their data is present -------------------------
REAL_PAIRS = {
    "3rscan/scene_2->scene_1": "rscan",
    "scan2cad/scene0470_00:scan->cad": "scan2cad",
}


def real_maps(data: str, pair: str):
    """(global map, local map, true T_global_local) of a real pair under the folder `data`."""
    root = Path(data)
    if REAL_PAIRS[pair] == "rscan":
        folder = root / "3rscan_subscans"
        return load_rscan(folder / "scene_1"), load_rscan(folder / "scene_2"), np.eye(4)
    maps = load_scan2cad(root / "scan2cad" / "scene0470_00")
    return maps.cad, maps.scan, np.eye(4)


def run_real_attempt(data: str, pair: str, method: str) -> tuple[list[dict], list[dict]]:
    """One real pair, one method: the whole local map at once (map_kind 'real').  The pairs
    are object maps without images: image methods are not run on them."""
    gmap, local, truth = real_maps(data, pair)
    loc = make_method(method, gmap, local.up)
    tick = time.perf_counter()
    result = loc.update(list(local))
    ms = (time.perf_counter() - tick) * 1e3
    base = dict(method=method, map_kind="real", sequence=pair, start=0, offset=0)
    row, hyps = attempt_rows(result, truth, base, ms)
    return [row], hyps
