"""A Result is written as JSON by `Result.to_json` (one writer, NaN refused) and read back by
`semloc.results.saved_result` (every field checked)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from semloc.results import Hypothesis, Result, saved_result
from semloc.transforms import yaw_pose


def result() -> Result:
    hypotheses = [Hypothesis(1, 4.0, [("g1", "l1"), ("g2", "l2"), ("g3", "l3")], yaw_pose(0.4, [1, 2, 0]),
                             fitness=0.9, confidence=0.95),
                  Hypothesis(2, 2.0, [("g4", "l1"), ("g5", "l2")], None)]  # fmt: skip
    return Result.of("localized", hypotheses, [], {"total": 1.5})


def test_a_result_written_is_read_back():
    text = result().to_json(warm_up_ms=3.0)
    document = json.loads(text)
    assert document["warm_up_ms"] == 3.0 and text.endswith("\n")
    saved = saved_result(document)
    assert saved.status == "localized" and saved.pairs == [("g1", "l1"), ("g2", "l2"), ("g3", "l3")]
    np.testing.assert_allclose(saved.pose, yaw_pose(0.4, [1, 2, 0]), atol=1e-9)
    assert saved.hypotheses[1] == (None, [("g4", "l1"), ("g5", "l2")])


def test_a_non_finite_number_is_not_written():
    bad = result()
    bad.hypotheses[0].score = float("nan")
    with pytest.raises(ValueError):
        bad.to_json()


@pytest.mark.parametrize(
    ("change", "message"),
    [(lambda d: d.update(status="lost"), "'status' must be one of localized, ambiguous, failed"),
     (lambda d: d["hypotheses"][1].update(pairs=[{"global": "g"}]), "'hypotheses[1].pairs[0]' must be"),
     (lambda d: d.update(changes=[]), "'changes' must be an object"),
     (lambda d: d.update(pose=[[1, 0, 0, 2e6], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]),
      "pose has a translation beyond")],
)  # fmt: skip
def test_a_field_of_the_wrong_shape_is_named(change, message):
    document = json.loads(result().to_json())
    change(document)
    with pytest.raises(ValueError, match=message.replace("[", r"\[").replace("(", r"\(")):
        saved_result(document)
