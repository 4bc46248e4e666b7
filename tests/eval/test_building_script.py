"""benchmarks/building.py's look-alike table: where the right hypothesis ranks, and whether an
answer that lost it says the search was cut."""

from __future__ import annotations

import numpy as np
from helpers import benchmark_script

from semloc import Hypothesis, Result
from semloc.decision import SEARCH_CUT
from semloc.transforms import yaw_pose


def _result(status: str, reason: str, poses: list[np.ndarray]) -> Result:
    hypotheses = [Hypothesis(rank=k, score=1.0, pairs=[], pose=p) for k, p in enumerate(poses, 1)]
    return Result(status=status, pose=None, hypotheses=hypotheses, reason=reason)


def test_the_rank_of_the_right_hypothesis_and_a_cut_search():
    building = benchmark_script("building")
    truth, elsewhere = np.eye(4), yaw_pose(0.0, [20.0, 0.0, 0.0])
    second = building._answer(_result("ambiguous", "a rival", [elsewhere, truth]), truth, "")
    assert second["rank"] == 2 and second["ambiguous"] and not second["cut"]
    lost = _result("ambiguous", f"{SEARCH_CUT}: ...", [elsewhere, elsewhere])
    assert building._answer(lost, truth, "p_") == {
        "p_rank": 0, "p_ambiguous": True, "p_look": False, "p_cut": True,
    }  # fmt: skip
    rows = [
        {"rank": 1, "prior_rank": 0, "prior_cut": True, "wrong": False, "prior_wrong": False},
        {"rank": 0, "prior_rank": 7, "wrong": False, "prior_wrong": True},
    ]
    table = building.rank_table([{"base": "rooms", "objects": 870, "rows": rows}])
    none, prior = table.splitlines()[2:]
    assert none == "| rooms | 870 | none | 1 | 0 | 0 | 1 | 1 | 0 | 0 | 0 | 0 |"
    assert prior == "| rooms | 870 | 10 m | 0 | 0 | 1 | 1 | 0 | 0 | 0 | 1 | 1 |"
