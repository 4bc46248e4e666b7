"""One answer schema (`semloc.schema`): every writer's JSON is exactly its model, a result
read back is the result written, and a count is never named like a list.

The writers checked here: `semloc localize --format json`, `semloc align --result`, the demo's
`result.json` and `Result.to_json` itself.  The others are checked beside their own tests:
the service's answers and `localize --server` (tests/serve/test_answer_schema_serve.py), the
lines of `bag localize --jsonl` and `/semloc/status` (tests/ros/test_bag_cli.py), the live
node's status (tests/ros2/test_live_node.py) and the scan demo (tests/sim/test_scandemo.py).
"""

from __future__ import annotations

import json
import types
import typing
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pydantic import BaseModel

import semloc
from semloc import schema
from semloc.association import LabelResolution
from semloc.changes import Changes, Moved
from semloc.cli import main
from semloc.priors import Prior
from semloc.results import Hypothesis, Look, Result, Step, Support
from semloc.transforms import yaw_pose

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def _models() -> list[type[BaseModel]]:
    return [m for m in vars(schema).values()
            if isinstance(m, type) and issubclass(m, schema.Part) and m is not schema.Part]  # fmt: skip


def _kind(annotation: object) -> str:
    """'count' for an integer field, 'list' for a list, else 'other' (None aside)."""
    arguments = [a for a in typing.get_args(annotation) if a is not type(None)]
    if typing.get_origin(annotation) in (typing.Union, types.UnionType):
        kinds = {_kind(a) for a in arguments}
        return kinds.pop() if len(kinds) == 1 else "other"
    if typing.get_origin(annotation) is typing.Annotated:
        return _kind(arguments[0])
    if annotation is int:
        return "count"
    return "list" if typing.get_origin(annotation) is list else "other"


def test_a_count_is_never_named_like_a_list():
    kinds: dict[str, set[str]] = {}
    for model in _models():
        for name, info in model.model_fields.items():
            kinds.setdefault(info.alias or name, set()).add(_kind(info.annotation))
    both = sorted(name for name, found in kinds.items() if {"count", "list"} <= found)
    assert both == []
    assert kinds["pairs"] == {"list"} and kinds["n_pairs"] == {"count"}
    assert kinds["missing"] == {"list"} and kinds["n_missing"] == {"count"}


def test_the_cli_localize_json_is_exactly_an_answer(tmp_path):
    out = tmp_path / "answer.json"
    argv = ["localize", str(EXAMPLES / "global.json"), str(EXAMPLES / "local.json"), "--format",
            "json", "--gt", str(EXAMPLES / "local.gt.json"), "--near", "0", "0", "0",
            "--radius", "50", "-o", str(out)]  # fmt: skip
    assert main(argv) == 0
    document = json.loads(out.read_text())
    assert schema.problems(document) == []
    assert document["labels"] and document["prior"] == {"position": [0.0, 0.0, 0.0], "radius": 50.0}
    assert document["ground_truth"]["success"] and document["warm_up_ms"] >= 0
    # the keys the CLI contract names (docs/contracts.md)
    contract = {"status", "pose", "hypotheses", "steps", "timing_ms", "labels", "changes",
                "next_look", "ground_truth"}  # fmt: skip
    assert contract <= set(document)
    assert {"rank", "score", "pairs", "pose", "fitness"} <= set(document["hypotheses"][0])
    assert {"step", "n_local", "n_sets", "top_scores", "ms"} <= set(document["steps"][0])


def test_the_labels_are_the_localizers_own():
    """The label report is the Result's, read by the Localizer's candidate index (one index,
    with its descriptor gate), not by a second one built for the report."""
    global_map = semloc.load_map(EXAMPLES / "global.json")
    local_map = semloc.load_map(EXAMPLES / "local.json")
    result = semloc.localize(global_map, local_map)
    assert set(result.labels) == set(local_map.labels)
    assert all(isinstance(found, LabelResolution) for found in result.labels.values())
    assert result.to_dict()["labels"] == {
        label: {"resolved": found.resolved, "map_labels": list(found.map_labels)}
        for label, found in result.labels.items()
    }


def test_align_writes_an_answer(tmp_path):
    out = tmp_path / "result.json"
    argv = [
        "align",
        str(EXAMPLES / "global.json"),
        str(EXAMPLES / "local.json"),
        "--result",
        str(out),
    ]
    assert main(argv) == 0
    document = json.loads(out.read_text())
    assert schema.problems(document) == [] and document["labels"]


def test_the_demo_writes_an_answer(tmp_path):
    from rich.console import Console

    from semloc.tools.demo import DemoConfig, run_demo

    config = DemoConfig(size="tiny", keyframes=8, resolution=(80, 60), out=tmp_path / "demo")
    with open(tmp_path / "log.txt", "w") as log:
        run_demo(config, Console(file=log, width=100))
    document = json.loads((tmp_path / "demo" / "result.json").read_text())
    assert schema.problems(document) == [] and document["labels"]


def test_problems_names_what_is_not_the_schema():
    document = json.loads(_result().to_json())
    assert schema.problems(document) == []
    stray = json.loads(json.dumps(document))
    stray["support"]["pairs"] = 3
    assert schema.problems(stray) == ["unknown key 'support.pairs'"]
    absent = {k: v for k, v in document.items() if k != "labels"}
    assert schema.problems(absent) == ["missing key 'labels'"]
    unrounded = {**document, "timing_ms": {"total": 1.23456}}
    assert schema.problems(unrounded) == ["not written as the schema writes it"]
    assert schema.problems({**document, "status": "lost"})[0].startswith("'status' must be")


def test_a_writer_field_the_model_lacks_is_refused():
    with pytest.raises(TypeError, match="map_version"):
        _result().to_dict(map_version=3)
    assert _result().to_dict(schema.ServiceAnswer, map_version=3)["map_version"] == 3


def _result(**changes: object) -> Result:
    hypotheses = [Hypothesis(1, 4.0, [("g1", "l1"), ("g2", "l2"), ("g3", "l3")], yaw_pose(0.4, [1, 2, 0]),
                             fitness=0.9, confidence=0.95, outside_prior=False, n_missing=1,
                             n_expected=4),
                  Hypothesis(2, 2.0, [("g4", "l1"), ("g5", "l2")], None)]  # fmt: skip
    result = Result.of("ambiguous", hypotheses, [Step(0, 3, 12, [4.0, 2.0], 1.25, "ambiguous")],
                       {"total": 1.5}, "twins")  # fmt: skip
    result.support = Support(3, (0, 2), 1, 0.5, True, 1, 0, 1, 4, ("g9",))
    result.prior = Prior(position=[1, 2, 0], radius=5, heading=30)
    result.explain = lambda: Changes([Moved("g7", "l7", 1.25, 2, 5)], ["l9"], ["g8"],
                                     evidence={"new": {"l9": 2}, "missing": {"g8": 3}})  # fmt: skip
    looks = [Look("chair", "g5", {1: np.array([1.0, 2, 0]), 2: np.array([3.0, 1, 0])}, [1, 2], 0.7)]
    result.suggest = lambda: looks
    result.read_labels = lambda: {"chair": LabelResolution("exact", ("chair",))}
    for name, value in changes.items():
        setattr(result, name, value)
    return result


def test_from_dict_is_the_inverse_of_to_dict_for_every_part():
    original = _result()
    document = json.loads(original.to_json())
    back = Result.from_dict(document)
    assert back.to_dict() == document
    assert back.support == original.support and back.prior == original.prior
    assert back.changes.moved == [Moved("g7", "l7", 1.25, 2, 5)] and back.labels == original.labels
    assert back.hypotheses[0].n_missing == 1 and back.hypotheses[0].outside_prior is False
    assert "n_missing" not in document["hypotheses"][1]  # (left out when it does not apply)


finite = st.floats(-1e3, 1e3, allow_nan=False)
ids = st.text("abcxyz019", min_size=1, max_size=4)


@st.composite
def hypotheses(draw, rank: int) -> Hypothesis:
    pairs = draw(st.lists(st.tuples(ids, ids), max_size=5))
    pose = draw(st.none() | st.builds(lambda yaw, x, y: yaw_pose(yaw, [x, y, 0.0]),
                                      st.floats(-3, 3), finite, finite))  # fmt: skip
    optional = st.none() | st.floats(0, 1)
    return Hypothesis(rank, draw(finite), pairs, pose, draw(optional), draw(optional),
                      draw(optional), draw(st.sampled_from(["", "icp"])), draw(optional),
                      draw(st.none() | finite), draw(st.none() | st.dictionaries(ids, finite, max_size=3)),
                      draw(st.lists(st.tuples(ids, ids), max_size=2)), draw(st.none() | st.booleans()),
                      *draw(st.none().map(lambda _: (None, None)) | st.tuples(st.integers(0, 9), st.integers(0, 9))))  # fmt: skip


@st.composite
def results(draw) -> Result:
    n = draw(st.integers(0, 3))
    status = draw(st.sampled_from(["localized", "ambiguous", "failed"]))
    found = [draw(hypotheses(rank)) for rank in range(1, n + 1)]
    steps = [Step(i, draw(st.integers(0, 50)), draw(st.integers(0, 500)),
                  draw(st.lists(finite, max_size=3)), draw(st.floats(0, 1e4)),
                  draw(st.sampled_from([None, "localized", "ambiguous", "failed"])))
             for i in range(draw(st.integers(0, 3)))]  # fmt: skip
    result = Result.of(
        status, found, steps, {"total": draw(st.floats(0, 1e4))}, draw(st.text(max_size=8))
    )
    if draw(st.booleans()):
        result.support = Support(
            draw(st.integers(0, 9)), (0, draw(st.integers(0, 9))), 0, draw(st.floats(0, 1e3))
        )
    changes = Changes(draw(st.lists(st.builds(Moved, ids, ids, st.floats(0, 3)), max_size=2)),
                      draw(st.lists(ids, max_size=2)), draw(st.lists(ids, max_size=2)))  # fmt: skip
    result.explain = lambda: changes
    return result


@settings(max_examples=60, suppress_health_check=[HealthCheck.too_slow])
@given(result=results())
def test_any_result_round_trips_through_its_json(result):
    document = json.loads(result.to_json())
    assert schema.problems(document) == []
    back = Result.from_dict(document)
    assert back.to_dict() == document
    assert [h.pairs for h in back.hypotheses] == [h.pairs for h in result.hypotheses]
    assert back.status == result.status and back.reason == result.reason
