"""The messages of issue 44's item 8: empty maps say so, labels in any script are shown as
written, an output's suffix says what is written, align names its frames and its files, the
hypotheses table says how it is ranked, and ids are never cut at 80 columns."""

from __future__ import annotations

import re

import numpy as np
import pytest
from helpers import T_A_B, room, second_session
from rich.console import Console

import semloc
from semloc.cli import main
from semloc.cli.render import print_result
from semloc.maps import ObjectMap, SemanticObject
from semloc.results import Hypothesis, Result
from semloc.transforms import yaw_pose


@pytest.fixture()
def maps(tmp_path):
    a = room(12)
    semloc.save_map(a, tmp_path / "a.json")
    semloc.save_map(second_session(a, slice(0, 8)), tmp_path / "b.json")
    semloc.save_map(ObjectMap([]), tmp_path / "empty.json")
    return tmp_path


def test_an_empty_global_map_is_the_reason_and_no_label_is_warned_about(maps, capsys):
    assert main(["localize", str(maps / "empty.json"), str(maps / "b.json")]) == 0
    captured = capsys.readouterr()
    assert "reason: the global map has no objects" in captured.out
    assert "matches no map label" not in captured.err
    assert semloc.localize(ObjectMap([]), semloc.load_map(maps / "b.json")).reason == (
        "the global map has no objects"
    )


def test_an_empty_local_map_is_the_reason(maps, capsys):
    assert main(["localize", str(maps / "a.json"), str(maps / "empty.json")]) == 0
    assert "reason: the local map has no objects" in capsys.readouterr().out
    result = semloc.localize(semloc.load_map(maps / "a.json"), ObjectMap([]))
    assert result.status == "failed" and result.reason == "the local map has no objects"


def test_a_label_in_any_script_is_warned_about_as_written(maps, capsys):
    local = ObjectMap([SemanticObject("l1", "canapé", [0, 0, 0]),
                       SemanticObject("l2", "вешалка", [1, 0, 0])])  # fmt: skip
    semloc.save_map(local, maps / "unicode.json")
    assert main(["localize", str(maps / "a.json"), str(maps / "unicode.json")]) == 0
    err = capsys.readouterr().err
    assert 'local label "canapé" matches no map label' in err
    assert '{"вешалка": "<map label>"}' in " ".join(err.split())
    assert "\\u" not in err


@pytest.mark.parametrize(
    ("argv", "message"),
    [(["view", "a.json", "-o", "x.txt"], "x.txt: --output writes a PNG picture; give a file "
      "name ending in .png"),
     (["view", "a.json", "--rrd", "x.png"], "x.png: --rrd writes a Rerun recording"),
     (["export", "a.json", "-o", "x.png"], "x.png: --output writes a PLY point cloud")],
)  # fmt: skip
def test_an_output_suffix_of_another_format_is_refused(maps, capsys, monkeypatch, argv, message):
    monkeypatch.chdir(maps)
    assert main(argv) == 2
    assert message in capsys.readouterr().err
    assert not (maps / argv[-1]).exists()


def test_align_names_the_pose_t_a_b_and_lists_the_files_it_wrote(maps, capsys):
    out = maps / "b_in_a.json"
    argv = ["align", str(maps / "a.json"), str(maps / "b.json"), "-o", str(out),
            "--result", str(maps / "r.json")]  # fmt: skip
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "pose T_A_B:" in text and "T_global_local" not in text
    assert "B→A" in text and "local→global" not in text
    assert f"wrote {out}" in text and f"wrote {maps / 'r.json'}" in text
    np.testing.assert_allclose(semloc.align(semloc.load_map(maps / "a.json"),
                                            semloc.load_map(maps / "b.json")).pose, T_A_B,
                               atol=1e-3)  # fmt: skip


def test_the_hypotheses_table_says_how_it_is_ranked():
    ranked = [Hypothesis(1, 5.0, [("a", "1"), ("b", "2"), ("c", "3")], yaw_pose(0.1), 0.9, 0.8),
              Hypothesis(2, 9.0, [("a", "2"), ("b", "1")], yaw_pose(1.1), 0.5, 0.1)]  # fmt: skip
    out = Console(width=80, record=True)
    print_result(Result.of("ambiguous", ranked, [], {}, "rival"), out)
    text = " ".join(out.export_text().split())
    assert "ranked by evidence (pairs, fit, confidence), not by score" in text


@pytest.mark.parametrize("width", [80, 100, 120])
def test_at_any_width_an_id_in_the_pairs_is_whole_or_shortened_never_cut(width):
    local = [f"detection number {i}" for i in range(8)]
    mapped = [f"scene0000_00/object_{i:03d}" for i in range(8)]
    h = Hypothesis(1, 12.0, list(zip(mapped, local, strict=True)), yaw_pose(0.3, [-12.5, 103.2, 1]),
                   confidence=0.4)  # fmt: skip
    out = Console(width=width, record=True)
    print_result(Result.of("ambiguous", [h], [], {}, "thin"), out)
    text = out.export_text().replace("\u00a0", " ")
    rows = text[text.index("───") : text.index("ranked by evidence")].splitlines()[1:]
    cells = [re.split(r"\s{2,}", line.strip())[-1].removesuffix(" …") for line in rows]
    pairs = [pair.split("→") for cell in cells for pair in re.split(r",\s*", cell)
             if "→" in pair]  # fmt: skip
    assert len(pairs) == 6, text
    for left, right in pairs:
        left, right = left.strip(), right.strip()
        assert left in local or (left.endswith("…") and local[0].startswith(left[:-1])), text
        assert right in mapped or (right.endswith("…") and mapped[0].startswith(right[:-1])), text
