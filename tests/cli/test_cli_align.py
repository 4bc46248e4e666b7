"""`semloc align` end to end: the outputs, all or none, and one-line errors."""

from __future__ import annotations

import json
import os

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


@pytest.mark.slow
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


def _with_points(objmap: ObjectMap) -> ObjectMap:
    """`objmap` with a small cloud of 4 points around every object's centre."""
    offsets = np.array([[0.1, 0, 0], [-0.1, 0, 0], [0, 0.1, 0], [0, -0.1, 0.2]])
    return ObjectMap([o.replace(points=o.position + offsets) for o in objmap], up=objmap.up)


@pytest.mark.parametrize(
    ("options", "named", "why"),
    [
        (["-o", "a.json"], "a.json", "would overwrite map A, an input"),
        (["--merged", "b.json"], "b.json", "would overwrite map B, an input"),
        (["-o", "x.json", "--g2o", "./a.json"], "a.json", "would overwrite map A, an input"),
        # a map written to `a` puts its points in a.points.npz, the points file A names
        (["-o", "a"], "a.points.npz", "would overwrite the points file of map A, an input"),
        (["-o", "x.json", "--merged", "x.points.npz"], "x.points.npz", "would both write it"),
        (["-o", "x.json", "--g2o", "x.points.npz"], "x.points.npz", "would both write it"),
        (["-o", "x.json", "--result", "x.json"], "x.json", "would both write it"),
        (["--config", "c.json", "--result", "c.json"], "c.json", "would overwrite the --config"),
    ],
)
def test_an_output_over_an_input_or_another_outputs_file_is_refused(
    tmp_path, capsys, options, named, why
):
    a = _with_points(room(30))
    semloc.save_map(a, tmp_path / "a.json", points="file")
    semloc.save_map(_with_points(second_session(a, slice(5, 30))), tmp_path / "b.json")
    (tmp_path / "c.json").write_text("{}")
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    argv = [str(tmp_path / o) if o.endswith(("json", "npz", "a")) else o for o in options]
    assert main(["align", str(tmp_path / "a.json"), str(tmp_path / "b.json"), *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("semloc: error:") and "\n" not in err
    assert f"{named}:" in err and why in err
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before  # nothing written


@pytest.mark.slow
@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="no /dev/full")
def test_one_output_that_cannot_be_written_leaves_no_other(sessions, capsys):
    out = sessions
    argv = ["align", str(out / "a.json"), str(out / "b.json"), "-o", str(out / "b_in_a.json"),
            "--merged", str(out / "m.json"), "--g2o", "/dev/full"]  # fmt: skip
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err == "semloc: error: /dev/full: cannot write (No space left on device)"
    assert not (out / "b_in_a.json").exists() and not (out / "m.json").exists()


@pytest.mark.parametrize("keep", [slice(0, 0), slice(0, 1)])
def test_an_empty_b_or_one_with_one_object_fails_and_writes_nothing(sessions, capsys, keep):
    out = sessions
    semloc.save_map(second_session(room(30), keep), out / "small.json")
    argv = ["align", str(out / "a.json"), str(out / "small.json"), "-o", str(out / "x.json")]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "status: failed" in text and "too few local objects" in text and "not written" in text
    assert not (out / "x.json").exists()


def test_a_b_with_another_up_is_written_in_as_frame(sessions):
    out = sessions
    z_to_y = np.array([[1.0, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, 0], [0, 0, 0, 1]])
    b = semloc.load_map(out / "b.json").transformed(z_to_y)  # B's frame with y up
    np.testing.assert_allclose(b.up, [0, 1, 0], atol=1e-12)
    semloc.save_map(b, out / "b_y.json")
    argv = ["align", str(out / "a.json"), str(out / "b_y.json"), "-o", str(out / "b_in_a.json")]
    assert main(argv) == 0
    a, b_in_a = semloc.load_map(out / "a.json"), semloc.load_map(out / "b_in_a.json")
    np.testing.assert_allclose(b_in_a.up, a.up, atol=1e-6)
    for obj in b_in_a:
        np.testing.assert_allclose(
            obj.position, a.get(obj.id.replace("b", "a")).position, atol=1e-5
        )
