"""One document for a localization answer: `semloc localize --format json`, the service's
answers and the lines of `semloc bag localize --jsonl` are `semloc.io.answers.answer_document`
of the same result (only what each writer adds differs: `warm_up_ms`, `map_version`, ...)."""

from __future__ import annotations

import json
from pathlib import Path

from semloc.association import CandidateIndex, label_report
from semloc.cli import main
from semloc.io import load_map, map_to_dict
from semloc.io.answers import answer_document, answer_text
from semloc.localizer import LocalizerConfig, localize
from semloc.serve.service import Service
from semloc.serve.store import open_store

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
TIMED = {"timing_ms", "steps", "warm_up_ms"}  # milliseconds differ from run to run


def _untimed(document: dict) -> dict:
    return {key: value for key, value in document.items() if key not in TIMED}


def _in_process() -> dict:
    global_map, local_map = load_map(EXAMPLES / "global.json"), load_map(EXAMPLES / "local.json")
    result = localize(global_map, local_map)
    labels = label_report(CandidateIndex(global_map, LocalizerConfig().association), local_map)
    return answer_document(result, labels)


def test_the_cli_json_is_the_answer_document(tmp_path, capsys):
    out = tmp_path / "answer.json"
    args = ["localize", str(EXAMPLES / "global.json"), str(EXAMPLES / "local.json")]
    assert main([*args, "--format", "json", "-o", str(out)]) == 0
    written = json.loads(out.read_text())
    expected = _in_process()
    assert list(written) == [*expected, "warm_up_ms"]  # the same keys, in the same order
    assert _untimed(written) == _untimed(expected)
    assert len(written["steps"]) == len(expected["steps"])


def test_the_service_answer_is_the_answer_document(tmp_path):
    service = Service(open_store(tmp_path))
    service.put_map("office", map_to_dict(load_map(EXAMPLES / "global.json")))
    served = service.localize("office", map_to_dict(load_map(EXAMPLES / "local.json")))
    expected = _in_process()
    assert list(served) == [*expected, "map_version", "prior", "localization_id"]
    assert _untimed(served) == {**_untimed(expected), "map_version": 1, "prior": None,
                                "localization_id": served["localization_id"]}  # fmt: skip


def test_a_stream_keeps_the_latest_steps_only_and_the_text_refuses_nan():
    document = _in_process()
    result_steps = len(document["steps"])
    global_map, local_map = load_map(EXAMPLES / "global.json"), load_map(EXAMPLES / "local.json")
    result = localize(global_map, local_map)
    line = answer_document(result, {}, last_steps=1)
    assert result_steps > 1 and len(line["steps"]) == 1
    assert line["steps"][0]["step"] == document["steps"][-1]["step"]
    assert json.loads(answer_text(document)) == json.loads(json.dumps(document))
    try:
        answer_text({"x": float("nan")})
    except ValueError:
        pass
    else:
        raise AssertionError("NaN was written")
