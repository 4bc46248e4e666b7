"""Fitting the confidence model: the operating point holds on every kind of attempt, the
ranking logit is fitted apart, and the collectors label hypotheses against the truth."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from semloc.decision import FEATURES, shipped_model
from semloc.eval.calibration import (
    Sample,
    best_operating_point,
    collect_observations,
    collect_walk,
    confidences,
    fit,
    is_right,
    operating_point,
)
from semloc.sim.layouts import layout
from semloc.sim.longwalk import LongWalk, WalkConfig, World, tiled

SURE = {"n_pairs": 8.0, "rejected_share": 0.0, "residual": 0.05, "fitness": 0.95, "n_support": 0.0,
        "conflict_share": 0.0}  # fmt: skip
WEAK = SURE | {"n_pairs": 3.0, "fitness": 0.4, "conflict_share": 0.3}


def _answers(kind: str, rights: list[bool], features: dict, first: int) -> list[Sample]:
    return [Sample(first + i, kind, 1, int(features["n_pairs"]), features["fitness"], features, ok)
            for i, ok in enumerate(rights)]  # fmt: skip


def test_the_operating_point_holds_on_every_kind():
    model = shipped_model()
    middle = SURE | {"n_pairs": 4.0, "fitness": 0.7}
    conf = {name: model.confidence(model.evidence(f), None)
            for name, f in (("sure", SURE), ("middle", middle), ("weak", WEAK))}  # fmt: skip
    assert conf["sure"] > conf["middle"] > conf["weak"]
    good = _answers("a", [True] * 40, SURE, 0) + _answers("a", [True] * 40, WEAK, 100)
    mixed = _answers("b", [True] * 40, SURE, 200) + _answers("b", [False] * 2, middle, 300)
    assert operating_point(good, model, 0.99) == pytest.approx(max(conf["weak"], 0.5))
    # kind b's wrong claims are at the middle confidence: the threshold must pass them
    assert operating_point(good + mixed, model, 0.99) > conf["middle"]


def test_the_ranking_logit_is_fitted_on_its_kinds_alone():
    rng = np.random.default_rng(0)
    samples = []
    for i in range(300):  # kind "r": fitness decides; kind "o": pairs decide
        f = {k: float(rng.uniform(0, 1)) for k in FEATURES} | {"n_pairs": float(rng.integers(2, 9))}
        samples.append(Sample(i, "r", 1, int(f["n_pairs"]), f["fitness"], f, f["fitness"] > 0.5))
        g = dict(f)
        samples.append(
            Sample(1000 + i, "o", 1, int(g["n_pairs"]), g["fitness"], g, g["n_pairs"] > 5)
        )
    model = fit(samples, ranking=["r"])
    assert model.ranking_weights is not None
    assert model.ranking_weights["fitness"] > 5 * abs(model.ranking_weights["n_pairs"])
    assert model.evidence_weights["n_pairs"] > 0.5
    assert model.ranking(samples[0].features) != model.evidence(samples[0].features)


def test_observations_are_labelled_against_the_truth():
    samples = collect_observations([30], 1, counts=(8,))
    assert samples and {s.map_kind for s in samples} == {"observed"}
    assert len({s.answer for s in samples}) == 1
    assert any(s.right for s in samples)
    assert all(set(s.features) == set(FEATURES) for s in samples)


def test_only_real_rivals_enter_the_fit():
    model = shipped_model()
    four = frozenset({("g0", "l0"), ("g1", "l1"), ("g2", "l2"), ("g3", "l3")})
    variant = (four - {("g3", "l3")}) | {("g9", "l3")}
    other = frozenset({("g5", "l0"), ("g6", "l1"), ("g7", "l2"), ("g8", "l3")})

    def confidence_of_first(second: frozenset) -> float:
        answer = [Sample(0, "a", 1, 4, SURE["fitness"], SURE, True, four),
                  Sample(0, "a", 2, 4, SURE["fitness"], SURE, False, second)]  # fmt: skip
        return float(confidences(answer, model)[0])

    alone = float(confidences(_answers("a", [True], SURE, 0), model)[0])
    assert confidence_of_first(variant) == pytest.approx(alone)
    assert confidence_of_first(other) < alone - 0.1
    assert alone == pytest.approx(model.confidence(model.evidence(SURE), None))


def test_the_best_operating_point_is_the_threshold_with_the_most_right_claims():
    model = shipped_model()
    middle = SURE | {"n_pairs": 4.0, "fitness": 0.7}
    conf = {name: model.confidence(model.evidence(f), None)
            for name, f in (("sure", SURE), ("middle", middle), ("weak", WEAK))}  # fmt: skip
    samples = (_answers("a", [True] * 98, SURE, 0) + _answers("a", [False], middle, 100)
               + _answers("a", [True] * 20, WEAK, 200))  # fmt: skip
    # at 99 %: down to the weak answers, 118 right of 119 claims (the wrong one passed)
    threshold, coverage = best_operating_point(samples, model, 0.99)
    assert threshold == pytest.approx(conf["weak"]) and coverage == pytest.approx(118 / 119)
    # at 99.5 % the wrong claim cannot be passed: the sure answers alone
    threshold, coverage = best_operating_point(samples, model, 0.995)
    assert threshold == pytest.approx(conf["sure"]) and coverage == pytest.approx(98 / 119)


def test_a_hypothesis_off_far_from_the_origin_is_judged_at_the_robot():
    truth, pose = np.eye(4), np.eye(4)
    angle = np.radians(2.0)  # 2 deg about the origin: 3.5 m off at a robot 100 m away
    pose[:2, :2] = [[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]]
    assert is_right(pose, truth)
    assert is_right(pose, truth, at=np.array([5.0, 0.0, 0.0]))
    assert not is_right(pose, truth, at=np.array([100.0, 0.0, 0.0]))


def test_held_answers_and_negative_evidence_enter_as_the_decision_has_them():
    model = shipped_model()
    middle = SURE | {"n_pairs": 4.0, "fitness": 0.7}
    sure = _answers("a", [True] * 40, SURE, 0)
    wrong = _answers("a", [False] * 2, middle, 100)
    held = [replace(s, held=True) for s in wrong]
    assert operating_point(sure + wrong, model, 0.99) > operating_point(sure + held, model, 0.99)
    (lost,) = confidences([replace(sure[0], missing=2.0)], model)
    assert lost == pytest.approx(model.confidence(model.evidence(SURE) - 2.0, None))


def test_walk_attempts_are_the_searchs_answers_on_an_old_map_with_an_erring_detector():
    world = World(moved=0.3, gone=0.1, phantoms=0.5)
    global_map = tiled(layout(60, seed=3, points_per_object=40), 2, 1, seed=3)
    config = WalkConfig(keyframes=40, points_per_object=40, wrong_label_rate=0.2, world=world,
                        kidnap_at=20, redetections=10)  # fmt: skip
    walk = LongWalk(global_map, config, seed=5)
    frames = list(walk)
    assert np.any(walk.offsets != 0) and not walk.present.all()  # the map is old
    sent = [(o.label, g) for f in frames for o in f.objects if (g := f.truth[o.id]) is not None]
    assert any(label != global_map.labels[g] for label, g in sent)  # mislabelled detections
    assert any(g is None for f in frames for g in f.truth.values())  # phantoms
    samples = collect_walk(global_map, config, seed=5, kind="walk", every=4, first_answer=7)
    assert {s.map_kind for s in samples} == {"walk"}
    assert {s.answer for s in samples} <= set(range(7, 17))  # keyframes 0, 4, ..., 36
    assert any(s.right for s in samples) and any(not s.right for s in samples)
    assert all(s.confidence is not None for s in samples)
    # the calibration's confidences are those the answers reported (negative evidence and
    # copies told apart included; a hypothesis refined late may differ a little)
    reported = [s.confidence for s in samples]
    assert confidences(samples, shipped_model()) == pytest.approx(reported, abs=0.05)
