"""`semloc align` end to end: the outputs, all or none, and one-line errors."""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers import T_A_B, room, second_session

import semloc
from semloc.cli import main
from semloc.io.g2o import parse_edge
from semloc.maps import ObjectMap
from semloc.transforms import pose_error


@pytest.fixture()
def sessions(tmp_path):
    a = room(30)
    semloc.save_map(a, tmp_path / "a.json")
    semloc.save_map(second_session(a, slice(5, 30)), tmp_path / "b.json")
    return tmp_path


def test_align_writes_b_in_a_the_merged_map_the_edge_and_the_result(sessions, capsys):
    out = sessions
    code = main(["align", str(out / "a.json"), str(out / "b.json"), "-o", str(out / "b_in_a.json"),
                 "--merged", str(out / "m.json"), "--g2o", str(out / "e.g2o"),
                 "--result", str(out / "r.json")])  # fmt: skip
    assert code == 0
    assert "localized" in capsys.readouterr().out
    a, b_in_a = semloc.load_map(out / "a.json"), semloc.load_map(out / "b_in_a.json")
    for obj in b_in_a:
        np.testing.assert_allclose(
            obj.position, a.get(obj.id.replace("b", "a")).position, atol=1e-5
        )
    merged = semloc.load_map(out / "m.json")
    assert len(merged) == 30
    assert sum(o.extra["provenance"]["from"] == "both" for o in merged) == 25
    _, _, pose, _ = parse_edge((out / "e.g2o").read_text())
    assert max(pose_error(pose, T_A_B)) < 1e-4
    result = json.loads((out / "r.json").read_text())
    assert result["status"] == "localized" and len(result["hypotheses"][0]["pairs"]) == 25


def test_a_map_that_shares_nothing_writes_no_transform(sessions, capsys):
    out = sessions
    other = ObjectMap([o.replace(label="unknown") for o in semloc.load_map(out / "b.json")])
    semloc.save_map(other, out / "other.json")
    code = main(["align", str(out / "a.json"), str(out / "other.json"), "-o",
                 str(out / "x.json"), "--g2o", str(out / "x.g2o")])  # fmt: skip
    assert code == 0
    text = capsys.readouterr().out
    assert "failed" in text and "not written" in text
    assert not (out / "x.json").exists() and not (out / "x.g2o").exists()


def test_bad_input_is_one_line_and_exit_2(sessions, capsys):
    out = sessions
    assert main(["align", str(out / "a.json"), str(out / "missing.json")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("semloc: error:") and "missing.json" in err and "\n" not in err
    same = str(out / "same.json")
    assert (
        main(["align", str(out / "a.json"), str(out / "b.json"), "-o", same, "--merged", same]) == 2
    )
    assert "different files" in capsys.readouterr().err
    assert not (out / "same.json").exists()


def test_align_settings_are_checked_in_one_line(sessions, capsys):
    out = sessions
    for value in ("5", "-1", "nan"):
        assert main(["align", str(out / "a.json"), str(out / "b.json"), "--gamma", value]) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("semloc: error:") and "gamma" in err and "\n" not in err
