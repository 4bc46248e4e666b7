"""Fitting the confidence model (`semloc.decision.ConfidenceModel`) on simulated attempts.

Data: the attempts of the benchmark protocol (`semloc.eval.protocol`: simulated sequences,
random starts, every map kind, offsets 0 / +15 / +30 keyframes) with the Localizer, every
reported hypothesis labelled right when its pose is within 15 deg / 0.5 m of the truth.  The
real layouts are never used here (they are the held-out evaluation).

Fit: (1) the evidence logit, a logistic regression of right on `FEATURES` over all hypotheses,
each weight constrained to its sign in `SIGNS` (a feature whose fitted weight has the wrong
sign is left out); (2) the confidence, a logistic regression of right on (evidence, rival)
over the same hypotheses, rival = sigmoid(best evidence among the answer's other places that
are rivals of the hypothesis: `decision.is_rival`, sharing less than half of its pairs).
Operating point: the smallest `min_confidence` at which the best hypotheses that would be
claimed (>= 3 pairs, fitness >= 0.3) are right at least `precision` of the time.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from semloc.decision import (
    FEATURES,
    GAP_CAP,
    NO_RIVAL,
    RESIDUAL_RANK,
    SEARCH_CUT,
    SIGNS,
    ConfidenceModel,
    DecisionConfig,
    decide,
    is_rival,
    missing_penalty,
    shipped_model,
    told_apart,
)
from semloc.eval.protocol import BenchConfig, _targets, simulate, start_keyframes
from semloc.eval.success import ROTATION_TOLERANCE_DEG, TRANSLATION_TOLERANCE_M, is_success
from semloc.eval.variants import OBJECT_COUNTS, VARIANTS, make_case
from semloc.localizer import Localizer, localize
from semloc.maps import ObjectMap
from semloc.results import Hypothesis, Result
from semloc.search import NEWEST_CONTRADICT, STALE
from semloc.settings import LocalizerConfig
from semloc.sim.layouts import layout, observe
from semloc.sim.longwalk import LongWalk, WalkConfig
from semloc.transforms import pose_error

LAYOUT_COUNTS = (3, 4, 5, 6, 8)
LAYOUT_POINTS = 80
OBSERVED_COUNTS = (3, 4, 5, 6, 8, 10)


@dataclass
class Sample:
    """One reported hypothesis of one answer: its features, rank and whether it is right."""

    answer: int
    map_kind: str
    rank: int
    pairs: int
    fitness: float
    features: dict[str, float]
    right: bool
    matches: frozenset[tuple[str, str]] = frozenset()  # its pairs (global id, local id)
    objects: int = 0  # local objects of the answer
    status: str = ""  # of its answer
    confidence: float | None = None  # as the answer reported it
    missing: float = 0.0  # the evidence it lost to objects it expected in view that nobody saw
    apart: frozenset[int] = frozenset()  # ranks of copies the view told apart: not its rivals
    held: bool = False  # its answer is kept from a claim by more than the confidence


def collect(config: BenchConfig, first_answer: int = 0) -> list[Sample]:
    """Every hypothesis of every answer of the protocol's semloc attempts under `config`."""
    samples: list[Sample] = []
    answer = first_answer
    for index in range(config.sequences):
        seq = simulate(config, index)
        n_keyframes = len(seq.recording.detections)
        for start in start_keyframes(config, index, n_keyframes, config.starts):
            replay = seq.replay(start, min(n_keyframes, start + 70))
            targets = _targets(replay.keyframes)
            for kind in config.map_kinds:
                localizer = Localizer(replay.global_maps[kind], local_up=replay.local_map.up)
                for kf in replay.keyframes:
                    if kf.index not in targets:
                        if kf.objects:
                            localizer.add(kf.objects)
                        continue
                    result = localizer.update(kf.objects)
                    samples += samples_of(result, replay.T_global_local, answer, kind)
                    answer += 1
    return samples


def samples_of(
    result: Result, truth: np.ndarray, answer: int, kind: str, at: np.ndarray | None = None
) -> list[Sample]:
    """The hypotheses of one answer that carry features, labelled against `truth` (with `at`,
    a point of the local frame: the translation is judged there, e.g. at the robot)."""
    held = _held(result)
    return [
        Sample(
            answer,
            kind,
            h.rank,
            len(h.pairs),
            h.fitness or 0.0,
            h.features,
            is_right(h.pose, truth, at),
            frozenset(h.pairs),
            result.steps[-1].n_local if result.steps else 0,
            result.status,
            h.confidence,
            missing_penalty(h),
            _told_apart(h, result.hypotheses),
            held,
        )  # fmt: skip
        for h in result.hypotheses
        if h.features is not None
    ]


def _held(result: Result) -> bool:
    """Whether more than the confidence keeps the answer's best hypothesis from a claim at
    any operating point: too few pairs, a low fitness or a rival that fits the centres nearly
    as well (`decision.decide`), a cut search, the newest objects or stale evidence."""
    if not result.hypotheses or result.reason.startswith((SEARCH_CUT, NEWEST_CONTRADICT, STALE)):
        return True
    return decide(result.hypotheses, DecisionConfig(min_confidence=0.0), "evidence").status != (
        "localized"
    )


def _told_apart(h: Hypothesis, hypotheses: Sequence[Hypothesis]) -> frozenset[int]:
    """The ranks of the rivals that `h`'s reported confidence did not count: copies of a
    place that the view told apart from it (`decision.score_confidence`'s twins; the answer
    does not say which places were weighed as copies), found as the fewest of the strongest
    told-apart rivals whose leaving out reproduces the reported confidence."""
    if h.evidence is None or h.confidence is None:
        return frozenset()
    model, overlap = shipped_model(), DecisionConfig(min_confidence=0.5).rival_overlap
    rivals = [o for o in hypotheses if o is not h and o.evidence is not None
              and o.features is not None and is_rival(h.pairs, o.pairs, overlap)]  # fmt: skip
    apart = sorted((o for o in rivals if told_apart(h, o)), key=lambda o: -(o.evidence or 0.0))
    for n in range(len(apart) + 1):
        out = {id(o) for o in apart[:n]}
        rest = [o.evidence for o in rivals if id(o) not in out and o.evidence is not None]
        if abs(model.confidence(h.evidence, max(rest, default=None)) - h.confidence) < 1e-9:
            return frozenset(o.rank for o in apart[:n])
    return frozenset()


def is_right(pose: np.ndarray | None, truth: np.ndarray, at: np.ndarray | None = None) -> bool:
    """The paper's success (`eval.success.is_success`); with `at`, the translation is judged
    at that point of the local frame (far from the origin a small rotation moves it a lot)."""
    if at is None or pose is None:
        return is_success(pose, truth)
    point = np.append(np.asarray(at, dtype=float), 1.0)
    rotation, _ = pose_error(pose, truth)
    off = float(np.linalg.norm((pose - truth) @ point))
    return rotation < ROTATION_TOLERANCE_DEG and off < TRANSLATION_TOLERANCE_M


def collect_layouts(
    buildings: Sequence[int], views: int, counts: Sequence[int] = LAYOUT_COUNTS,
    first_answer: int = 0,
) -> list[Sample]:  # fmt: skip
    """Views of the simulated buildings `sim.layouts.layout(seed=b)` (with points) in the
    real-layout variants of `eval.variants` (clean, noisy, dynamic; `counts` objects)."""
    samples: list[Sample] = []
    answer = first_answer
    for b in buildings:
        full = layout(150, seed=b, points_per_object=LAYOUT_POINTS)
        for v, variant in enumerate(VARIANTS):
            for k in counts:
                rng = np.random.default_rng([7, b, v, k])
                for _ in range(views):
                    case = make_case(full, variant, k, rng)
                    result = localize(case.prior, case.local)
                    samples += samples_of(result, case.truth, answer, f"layout-{variant}")
                    answer += 1
    return samples


def collect_variants(
    maps: Mapping[str, ObjectMap], views: int, seed: int, kind: str,
    rename: Callable[[ObjectMap], ObjectMap] | None = None, counts: Sequence[int] = OBJECT_COUNTS,
    first_answer: int = 0,
) -> list[Sample]:  # fmt: skip
    """Views of `maps` (e.g. the real samples: `eval.variants.variant_maps`) in the clean /
    noisy / dynamic variants, `views` per map, variant and object count, drawn with `seed`
    (the real-layout benchmarks draw theirs with seed 0: another seed gives other views); with
    `rename`, the local objects are renamed first (a detector's vocabulary).  Kinds
    `{kind}-{variant}`."""
    samples: list[Sample] = []
    answer = first_answer
    for m, full in enumerate(maps.values()):
        for v, variant in enumerate(VARIANTS):
            for k in counts:
                rng = np.random.default_rng([seed, m, v, k])
                for _ in range(views):
                    case = make_case(full, variant, k, rng)
                    local = case.local if rename is None else rename(case.local)
                    result = localize(case.prior, local)
                    samples += samples_of(result, case.truth, answer, f"{kind}-{variant}")
                    answer += 1
    return samples


def collect_observations(
    buildings: Sequence[int], trials: int, counts: Sequence[int] = OBSERVED_COUNTS,
    first_answer: int = 0,
) -> list[Sample]:  # fmt: skip
    """Centre-only observations of the simulated buildings (`sim.layouts.observe`: biased
    centres, a spurious detection, wrong labels; rows of identical chairs and desks)."""
    samples: list[Sample] = []
    answer = first_answer
    for b in buildings:
        full = layout(150, seed=b)
        for k in counts:
            for t in range(trials):
                obs = observe(full, k, seed=10_000 * b + 100 * k + t)
                result = localize(full, obs.local_map)
                samples += samples_of(result, obs.T_global_local, answer, "observed")
                answer += 1
    return samples


def collect_walk(
    global_map: ObjectMap, config: WalkConfig, seed: int, kind: str, every: int = 5,
    first_answer: int = 0,
) -> list[Sample]:  # fmt: skip
    """The search's answers along a long walk through `global_map` (`semloc.sim.longwalk`:
    an old map, an erring detector, kidnaps into look-alike copies, as `config` has them),
    with tracking off so that every answer is the search's; each `every`-th keyframe answers
    (the others are added), with the sensor's coverage.  Hypotheses are judged at the robot."""
    walk = LongWalk(global_map, config, seed=seed)
    localizer = Localizer(global_map, LocalizerConfig(tracking={"track": False}),
                          local_up=[0, 0, 1])  # fmt: skip
    samples: list[Sample] = []
    answer = first_answer
    for frame in walk:
        if frame.index % every:
            localizer.add(frame.objects, position=frame.T_odom_robot, coverage=frame.coverage)
            continue
        result = localizer.update(frame.objects, position=frame.T_odom_robot,
                                  coverage=frame.coverage)  # fmt: skip
        samples += samples_of(result, frame.T_global_local, answer, kind,
                              at=frame.T_odom_robot[:3, 3])  # fmt: skip
        answer += 1
    return samples


def logistic(X: np.ndarray, y: np.ndarray, l2: float = 1e-3, iterations: int = 50) -> np.ndarray:
    """Weights (bias first) of an L2-regularized logistic regression by Newton's method."""
    A = np.column_stack([np.ones(len(X)), X])
    w = np.zeros(A.shape[1])
    ridge = l2 * len(X) * np.eye(A.shape[1])
    ridge[0, 0] = 0.0
    for _ in range(iterations):
        p = 1.0 / (1.0 + np.exp(-np.clip(A @ w, -50, 50)))
        gradient = A.T @ (p - y) + ridge @ w
        hessian = (A * (p * (1 - p))[:, None]).T @ A + ridge + 1e-9 * np.eye(len(w))
        step = np.linalg.solve(hessian, gradient)
        w -= step
        if np.max(np.abs(step)) < 1e-8:
            break
    return w


def fit(
    samples: list[Sample],
    precision: float = 0.995,
    data: str = "",
    features: Sequence[str] = FEATURES,
    ranking: Sequence[str] | None = None,
) -> ConfidenceModel:
    """The confidence model fitted on `samples` (see the module docstring); the evidence
    uses only `features` (the others get weight 0).  With `ranking` (map kinds), the ranking
    logit is fitted apart on the samples of those kinds."""
    y = np.array([s.right for s in samples], dtype=float)
    bias, weights = _evidence_weights(samples, y, features)
    model = ConfidenceModel(
        evidence_bias=bias, evidence_weights=weights, confidence_bias=0.0,
        confidence_evidence=1.0, confidence_rival=0.0, min_confidence=0.5,
    )  # fmt: skip
    if ranking is not None:
        mine = [s for s in samples if s.map_kind in ranking]
        rank_bias, rank_weights = _evidence_weights(
            mine, np.array([s.right for s in mine], dtype=float), features
        )
        model = model.model_copy(update=dict(ranking_bias=rank_bias, ranking_weights=rank_weights))
    evidence, rival, gap = _evidence_and_rival(samples, model)
    inputs = {"evidence": evidence, "rival": rival, "gap": gap}
    signs = {"evidence": 1, "rival": -1, "gap": 1}
    used = list(inputs)
    while True:  # each input constrained to its sign, as the evidence weights
        c = logistic(np.column_stack([inputs[k] for k in used]), y)
        wrong = [k for k, v in zip(used, c[1:]) if v * signs[k] < 0]
        if not wrong:
            break
        used.remove(wrong[0])
    fitted = dict.fromkeys(inputs, 0.0) | {k: float(v) for k, v in zip(used, c[1:])}
    model = model.model_copy(
        update=dict(
            confidence_bias=float(c[0]),
            confidence_evidence=fitted["evidence"],
            confidence_rival=fitted["rival"],
            confidence_gap=fitted["gap"],
        )  # fmt: skip
    )
    threshold = operating_point(samples, model, precision)
    return model.model_copy(update=dict(min_confidence=threshold, data=data))


def _evidence_weights(
    samples: list[Sample], y: np.ndarray, features: Sequence[str]
) -> tuple[float, dict[str, float]]:
    """Bias and weights of the evidence logit, each weight constrained to its sign."""
    X = np.array([[s.features[k] for k in FEATURES] for s in samples])
    used = [k for k in FEATURES if k in features]
    while True:
        columns = [FEATURES.index(k) for k in used]
        w = logistic(X[:, columns], y)
        wrong = [k for k, v in zip(used, w[1:]) if v * SIGNS[k] < 0]  # sign 0: free
        if not wrong:
            break
        used.remove(wrong[0])
    return float(w[0]), dict.fromkeys(FEATURES, 0.0) | {k: float(v) for k, v in zip(used, w[1:])}


def _evidence_and_rival(samples: list[Sample], model: ConfidenceModel):
    """Per sample: its evidence, the rival share and the capped evidence gap to the best
    rival place of its answer (`decision.is_rival`, as `decision.score_confidence` and
    `ConfidenceModel.confidence` compute them)."""
    evidence = np.array([model.evidence(s.features) - s.missing for s in samples])
    answers = np.array([s.answer for s in samples])
    strongest = np.full(len(samples), NO_RIVAL)
    overlap = DecisionConfig(min_confidence=0.5).rival_overlap
    for a in np.unique(answers):
        rows = np.flatnonzero(answers == a)
        for i in rows:
            others = [evidence[j] for j in rows if j != i
                      and is_rival(samples[i].matches, samples[j].matches, overlap)
                      and samples[j].rank not in samples[i].apart]  # fmt: skip
            if others:
                strongest[i] = max(max(others), NO_RIVAL)
    rival = 1.0 / (1.0 + np.exp(-strongest))
    return evidence, rival, np.minimum(evidence - strongest, GAP_CAP)


def confidences(samples: list[Sample], model: ConfidenceModel) -> np.ndarray:
    """The model's confidence of every sample (rivals: the other places of its answer)."""
    evidence, rival, gap = _evidence_and_rival(samples, model)
    logit = model.confidence_bias + model.confidence_evidence * evidence
    logit += model.confidence_rival * rival + model.confidence_gap * gap
    return 1.0 / (1.0 + np.exp(-np.clip(logit, -50, 50)))


def best_of_answers(samples: list[Sample], model: ConfidenceModel) -> list[tuple[Sample, float]]:
    """Per answer, the hypothesis the model ranks first, with its confidence."""
    conf = confidences(samples, model)
    best: dict[int, tuple[float, Sample, float]] = {}
    for s, c in zip(samples, conf):
        e = model.ranking(s.features) - s.missing - RESIDUAL_RANK * s.features["residual"]
        if s.answer not in best or e > best[s.answer][0]:
            best[s.answer] = (e, s, float(c))
    return [(s, c) for _, s, c in best.values()]


def _claimable(sample: Sample) -> bool:
    """Whether the decision's gates let a best hypothesis be claimed (>= min_pairs, >=
    min_fitness, not `held`), its confidence aside."""
    gate = DecisionConfig(min_confidence=0.5)
    return sample.pairs >= gate.min_pairs and sample.fitness >= gate.min_fitness and not sample.held


def _ranked_claims(samples: list[Sample], model: ConfidenceModel) -> list[tuple[float, bool]]:
    """(confidence, right) of the claimable best hypotheses of the answers, surest first."""
    found = [(c, s.right) for s, c in best_of_answers(samples, model) if _claimable(s)]
    return sorted(found, key=lambda x: -x[0])


def claims(samples: list[Sample], model: ConfidenceModel, threshold: float) -> list[Sample]:
    """The best hypotheses of the answers of `samples` that would be claimed at `threshold`."""
    return [s for s, c in best_of_answers(samples, model) if c >= threshold and _claimable(s)]


def best_operating_point(
    samples: list[Sample], model: ConfidenceModel, precision: float
) -> tuple[float, float]:
    """(threshold, coverage): the confidence threshold that claims the largest share of the
    answers of `samples` right while its claims stay right at least `precision` of the time,
    and that share (1.0, 0.0 when none does): what this confidence could give on these
    attempts alone, e.g. as `min_confidence` for a user who knows the world is static."""
    best, threshold, right = 0, 1.0, 0
    for n, (c, ok) in enumerate(_ranked_claims(samples, model), 1):
        right += ok
        if right / n >= precision and right > best:
            best, threshold = right, c
    answers = len({s.answer for s in samples})
    return threshold, best / answers if answers else 0.0


def operating_point(samples: list[Sample], model: ConfidenceModel, precision: float) -> float:
    """The smallest threshold whose claims (best hypotheses, >= min_pairs, >= min_fitness)
    are right at least `precision` of the time on every map kind of `samples`."""
    kinds = sorted({s.map_kind for s in samples})
    return max(_threshold([s for s in samples if s.map_kind == k], model, precision) for k in kinds)


def _threshold(samples: list[Sample], model: ConfidenceModel, precision: float) -> float:
    ranked = _ranked_claims(samples, model)
    threshold, right = 1.0, 0
    for n, (c, ok) in enumerate(ranked, 1):
        right += ok
        if right / n >= precision:
            threshold = c if n < len(ranked) else 0.0  # all claims hold: no bound from here
    return float(min(max(threshold, 0.5), 0.999))


def reliability(predicted: np.ndarray, right: np.ndarray, bins: int = 10) -> list[tuple]:
    """(bin low, bin high, count, mean predicted, observed share right) per confidence bin."""
    edges = np.linspace(0, 1, bins + 1)
    rows = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        mask = (predicted >= lo) & ((predicted < hi) | (hi == 1.0))
        if mask.any():
            rows.append((lo, hi, int(mask.sum()), float(predicted[mask].mean()),
                         float(right[mask].mean())))  # fmt: skip
    return rows
