"""Fitting the confidence model (`semloc.decision.ConfidenceModel`) on simulated attempts.

Data: the attempts of the benchmark protocol (`semloc.eval.protocol`: simulated sequences,
random starts, every map kind, offsets 0 / +15 / +30 keyframes) with the Localizer, every
reported hypothesis labelled right when its pose is within 15 deg / 0.5 m of the truth.  The
real layouts are never used here (they are the held-out evaluation).

Fit: (1) the evidence logit, a logistic regression of right on `FEATURES` over all hypotheses,
each weight constrained to its sign in `SIGNS` (a feature whose fitted weight has the wrong
sign is left out); (2) the confidence, a logistic regression of right on (evidence, rival)
over the same hypotheses, rival = sigmoid(best evidence among the other places of the answer).
Operating point: the smallest `min_confidence` at which the best hypotheses that would be
claimed (>= 3 pairs, fitness >= 0.3) are right at least `precision` of the time.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from semloc.decision import FEATURES, SIGNS, ConfidenceModel, DecisionConfig
from semloc.eval.protocol import BenchConfig, _targets, simulate, start_keyframes
from semloc.eval.success import is_success
from semloc.localizer import Localizer


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
                            localizer.update(kf.objects, answer=False)
                        continue
                    result = localizer.update(kf.objects)
                    for h in result.hypotheses:
                        if h.features is not None:
                            right = is_success(h.pose, replay.T_global_local)
                            samples.append(Sample(answer, kind, h.rank, len(h.pairs),
                                                  h.fitness or 0.0, h.features, right))  # fmt: skip
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


def fit(samples: list[Sample], precision: float = 0.995, data: str = "") -> ConfidenceModel:
    """The confidence model fitted on `samples` (see the module docstring)."""
    y = np.array([s.right for s in samples], dtype=float)
    X = np.array([[s.features[k] for k in FEATURES] for s in samples])
    used = list(FEATURES)
    while True:
        columns = [FEATURES.index(k) for k in used]
        w = logistic(X[:, columns], y)
        wrong = [k for k, v in zip(used, w[1:]) if v * SIGNS[k] < 0]  # sign 0: free
        if not wrong:
            break
        used.remove(wrong[0])
    weights = dict.fromkeys(FEATURES, 0.0) | {k: float(v) for k, v in zip(used, w[1:])}
    model = ConfidenceModel(
        evidence_bias=float(w[0]), evidence_weights=weights, confidence_bias=0.0,
        confidence_evidence=1.0, confidence_rival=0.0, min_confidence=0.5,
    )  # fmt: skip
    evidence, rival = _evidence_and_rival(samples, model)
    c = logistic(np.column_stack([evidence, rival]), y)
    model = model.model_copy(
        update=dict(
            confidence_bias=float(c[0]),
            confidence_evidence=max(float(c[1]), 0.0),
            confidence_rival=min(float(c[2]), 0.0),
        )  # fmt: skip
    )
    threshold = operating_point(samples, model, precision)
    return model.model_copy(update=dict(min_confidence=threshold, data=data))


def _evidence_and_rival(samples: list[Sample], model: ConfidenceModel):
    evidence = np.array([model.evidence(s.features) for s in samples])
    answers = np.array([s.answer for s in samples])
    rival = np.zeros(len(samples))
    for a in np.unique(answers):
        rows = np.flatnonzero(answers == a)
        for i in rows:
            others = evidence[rows[rows != i]]
            rival[i] = 1.0 / (1.0 + np.exp(-others.max())) if len(others) else 0.0
    return evidence, rival


def confidences(samples: list[Sample], model: ConfidenceModel) -> np.ndarray:
    """The model's confidence of every sample (rivals: the other places of its answer)."""
    evidence, rival = _evidence_and_rival(samples, model)
    logit = model.confidence_bias + model.confidence_evidence * evidence
    logit += model.confidence_rival * rival
    return 1.0 / (1.0 + np.exp(-np.clip(logit, -50, 50)))


def best_of_answers(samples: list[Sample], model: ConfidenceModel) -> list[tuple[Sample, float]]:
    """Per answer, the hypothesis the model ranks first, with its confidence."""
    conf = confidences(samples, model)
    best: dict[int, tuple[float, Sample, float]] = {}
    for s, c in zip(samples, conf):
        e = model.evidence(s.features)
        if s.answer not in best or e > best[s.answer][0]:
            best[s.answer] = (e, s, float(c))
    return [(s, c) for _, s, c in best.values()]


def operating_point(samples: list[Sample], model: ConfidenceModel, precision: float) -> float:
    """The smallest threshold whose claims (best hypotheses, >= min_pairs, >= min_fitness)
    are right at least `precision` of the time."""
    gate = DecisionConfig(min_confidence=0.5)
    claims = sorted(
        ((c, s.right) for s, c in best_of_answers(samples, model)
         if s.pairs >= gate.min_pairs and s.fitness >= gate.min_fitness),
        reverse=True,
    )  # fmt: skip
    threshold, right = 1.0, 0
    for n, (c, ok) in enumerate(claims, 1):
        right += ok
        if right / n >= precision:
            threshold = c
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
