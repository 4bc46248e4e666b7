"""A Result is written as JSON by `Result.to_json` (one writer, NaN refused) and read back by
`Result.from_dict` and `semloc.results.saved_result` (every field checked by the answer schema,
a shorter or older document read too)."""

from __future__ import annotations

import json
import re

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
    [(lambda d: d.update(status="lost"), "'status' must be 'localized', 'ambiguous' or 'failed'"),
     (lambda d: d["hypotheses"][1].update(pairs=[{"global": "g"}]),
      "'hypotheses[1].pairs[0].local' is required"),
     (lambda d: d.update(changes=[]), "'changes' must be an object"),
     (lambda d: d.update(pose=[[1, 0, 0, 2e6], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]),
      "'pose': the translation is beyond")],
)  # fmt: skip
def test_a_field_of_the_wrong_shape_is_named(change, message):
    document = json.loads(result().to_json())
    change(document)
    with pytest.raises(ValueError, match=message.replace("[", r"\[").replace("(", r"\(")):
        saved_result(document)


def test_a_shorter_document_is_read_and_a_ground_truth_gives_a_pose():
    short = {"status": "ambiguous", "hypotheses": [{"pairs": [{"global": 1, "local": "a"}]},
                                                    {"pairs": []}]}  # fmt: skip
    saved = saved_result(short)
    assert saved.pose is None and saved.pairs == [("1", "a")] and saved.hypotheses[1] == (None, [])
    assert [h.rank for h in Result.from_dict(short).hypotheses] == [1, 2]
    truth = saved_result({"T_global_local": yaw_pose(0.2, [1, 0, 0]).tolist()})
    np.testing.assert_allclose(truth.pose, yaw_pose(0.2, [1, 0, 0]))
    with pytest.raises(ValueError, match="T_global_local"):
        saved_result({"T_global_local": [[1, 0], [0, 1]]})


def test_from_dict_is_the_inverse_of_to_dict():
    from semloc.changes import Changes, Moved
    from semloc.results import Step

    original = result()
    original.steps.append(Step(0, 3, 12, [4.0, 2.0], 1.25, "localized"))
    original.explain = lambda: Changes([Moved("g7", "l7", 1.25)], ["l9"], ["g8"])
    document = json.loads(original.to_json())
    back = Result.from_dict(document)
    assert back.to_dict() == document
    assert back.changes.moved == [Moved("g7", "l7", 1.25)] and back.changes.new == ["l9"]
    assert back.best.confidence == 0.95 and back.hypotheses[1].pose is None


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"status": "maybe"}, "'status' must be 'localized', 'ambiguous' or 'failed'"),
        (
            {"hypotheses": [{"rank": 1, "pairs": [], "pose": None, "score": "high"}]},
            "'hypotheses[0].score' must be a valid number",
        ),
        ({"changes": {"moved": [{"global": "g"}]}}, "'changes.moved[0].local' is required"),
        ({"changes": {"moved": [], "new": 3}}, "'changes.new' must be a valid list"),
        ({"steps": [{"when": 1}]}, "'steps[0].step' is required"),
        ({"pose": [[1, 0, 0, 2e6], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]},
         "'pose': the translation is beyond"),
        ({"pose": [[2, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]},
         "'pose': pose: the rotation part is not a proper rotation"),
    ],
)  # fmt: skip
def test_from_dict_names_what_is_wrong(change, message):
    document = {**json.loads(result().to_json()), **change}
    with pytest.raises(ValueError, match=re.escape(message)):
        Result.from_dict(document)
