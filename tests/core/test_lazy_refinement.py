"""Lazy refinement: only the hypotheses that could change the verdict get robust ICP."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import semloc
import semloc.search as search_module
from semloc.decision import shipped_model
from semloc.sim.layouts import layout, observe

BUILDINGS = {seed: layout(60, seed=seed, points_per_object=120) for seed in range(2)}


def _fully_refined(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every hypothesis among the `refine_top` first refined, as before lazy refinement."""
    monkeypatch.setattr(
        search_module, "verdict_refinements", lambda ranked, pending, *args: list(pending)
    )


def _verdict(result: semloc.Result) -> tuple:
    best = result.hypotheses[0] if result.hypotheses else None
    return result.status, None if best is None else sorted(best.pairs)


@settings(max_examples=25)
@given(
    building=st.sampled_from(sorted(BUILDINGS)),
    n_objects=st.integers(3, 8),
    seed=st.integers(0, 10_000),
    noise=st.sampled_from([0.02, 0.15]),
)
def test_lazily_refined_rivals_give_the_verdict_of_fully_refined_ones(
    building: int, n_objects: int, seed: int, noise: float
) -> None:
    global_map = BUILDINGS[building]
    view = observe(global_map, n_objects, seed, position_noise=noise).local_map
    lazy = semloc.localize(global_map, view)
    with pytest.MonkeyPatch.context() as monkeypatch:
        _fully_refined(monkeypatch)
        full = semloc.localize(global_map, view)
    assert _verdict(lazy) == _verdict(full)
    if lazy.hypotheses:
        best, full_best = lazy.hypotheses[0], full.hypotheses[0]
        assert best.refined or best.pose is None
        if best.pose is not None:
            np.testing.assert_allclose(best.pose, full_best.pose, atol=1e-9)


def test_an_unrefined_hypothesis_is_marked_and_refined_on_demand() -> None:
    global_map = BUILDINGS[0]
    for seed in range(40):
        result = semloc.localize(global_map, observe(global_map, 5, seed).local_map)
        unrefined = [h for h in result.hypotheses if not h.refined]
        if unrefined:
            break
    else:
        pytest.fail("no unrefined hypothesis in 40 views")
    h = unrefined[0]
    assert h.to_dict()["refined"] is False
    assert "icp" not in h.method
    fitness = h.fitness
    assert h.refine() is h
    assert h.refined and "refined" not in h.to_dict()
    assert h.fitness is not None and fitness is not None and h.fitness >= fitness
    assert h.evidence is not None


def test_the_json_reads_back_whether_a_hypothesis_was_refined() -> None:
    h = semloc.Hypothesis(rank=2, score=1.0, pairs=[("a", "b")], pose=np.eye(4), refined=False)
    data = semloc.Result(status="ambiguous", pose=np.eye(4), hypotheses=[h]).to_dict()
    back = semloc.Result.from_dict(data)
    assert back.hypotheses[0].refined is False
    assert back.hypotheses[0].refine() is back.hypotheses[0]  # nothing to refine it with


def test_the_shipped_model_rewards_fitness_and_penalises_residual() -> None:
    """The bounds of lazy refinement (`decision.verdict_refinements`) take a refined fitness
    at most 1 and a residual at least 0 as the best case: the models must weigh them so."""
    model = shipped_model()
    for weights in (model.evidence_weights, model.ranking_weights or model.evidence_weights):
        assert weights["fitness"] >= 0 >= weights["residual"]
