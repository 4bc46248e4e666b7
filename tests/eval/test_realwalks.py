"""The paper's protocol on walks through real scans (semloc.eval.realwalks)."""

from __future__ import annotations

import pytest

from semloc.eval.protocol import BenchConfig
from semloc.eval.realwalks import (
    SCENES,
    plan,
    real_walk_data,
    run_walk_attempts,
    walk_seed,
    walk_sequence,
)
from semloc.eval.recall import RESULT_COLUMNS, read_rows


def test_plan_covers_every_scene_walk_start_kind_and_method():
    config = BenchConfig(real_walks=True, real_walk_count=2, real_walk_starts=3,
                         methods=["semloc", "clipper"])  # fmt: skip
    jobs = plan(config)
    # scene0000_00: reconstruction, scene0470_00: + cad; 2 walks x 3 starts x 2 methods (object
    # methods: their night rows are copies of their reconstruction rows, not run again)
    assert len(jobs) == (1 + 2) * 2 * 3 * 2
    assert {(s, k) for s, _, _, k, _ in jobs} == {(s, k) for s, (_, ks) in SCENES.items()
                                                  for k in ks}  # fmt: skip
    with_sift = plan(config.model_copy(update={"methods": ["semloc", "sift"]}))
    assert {(s, k) for s, _, _, k, m in with_sift if m == "sift"} == {
        (s, k) for s in SCENES for k in ("reconstruction", "night")}  # fmt: skip
    no_night = plan(config.model_copy(update={"night": False, "methods": ["semloc", "sift"]}))
    assert all(k != "night" for _, _, _, k, _ in no_night)
    assert all(0 <= start < config.real_walk_keyframes - 35 for _, _, start, _, _ in jobs)
    assert len({(s, w, st) for s, w, st, _, _ in jobs}) == 2 * 2 * 3  # distinct starts per walk
    assert BenchConfig.quick().real_walks is False


@pytest.mark.slow
def test_real_walks_run_writes_rows_like_the_serial_protocol(tmp_path):
    try:
        data = real_walk_data()
    except ValueError as exc:
        pytest.skip(str(exc))
    from dask.distributed import Client

    from semloc.eval.realwalks import run_real_walks, write_outputs

    config = BenchConfig(real_walks=True, real_walk_count=1, real_walk_starts=1, night=False,
                         real_walk_keyframes=40, methods=["semloc"], seed=2)  # fmt: skip
    with Client(processes=False, n_workers=1, threads_per_worker=1, dashboard_address=None) as c:
        output = run_real_walks(c, config, progress=False)
    write_outputs(tmp_path, config, output["rows"], output["hypotheses"], output["traces"])
    rows = read_rows(tmp_path / "real_walks.csv", RESULT_COLUMNS)
    assert {r["map_kind"] for r in rows} == {"real reconstruction", "real cad"}
    for name in ("real_walks.png", "real_walks_scores.png", "real_walks.md"):
        assert (tmp_path / name).exists()
    assert "| semloc |" in (tmp_path / "real_walks.md").read_text()
    # the same attempts computed serially
    seq = walk_sequence(str(data), "scene0470_00", walk_seed(config, 0), 40)
    start = next(st for s, _, st, _, _ in plan(config) if s == "scene0470_00")
    serial, _ = run_walk_attempts(seq, "scene0470_00", 0, start, "cad", "semloc")
    assert {r["sequence"] for r in serial} == {"scene0470_00/walk0"}
    mine = [r for r in output["rows"] if r["map_kind"] == "real cad"]
    assert mine and [r["rank_of_first_correct"] for r in mine] == [r["rank_of_first_correct"]
                                                          for r in serial]  # fmt: skip
    assert [r["n_local"] for r in mine] == [r["n_local"] for r in serial]


def test_missing_real_scans_fail_before_the_run(tmp_path, monkeypatch, capsys):
    from semloc.cli import main

    monkeypatch.setenv("SEMLOC_DATA", str(tmp_path))
    assert main(["bench", "--real-walks", "--sequences", "0", "--out", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("semloc: error: --real-walks needs the real scans") and "\n" not in err
    assert not (tmp_path / "b").exists()


def test_report_of_real_rows_only_has_no_comparison_figure(tmp_path):
    from semloc.eval.report import write_outputs

    rows = [dict(method="semloc", map_kind="real", sequence="pair", start=0, offset=0, n_local=5,
                 rank_of_first_correct=1, rot_err_deg=1.0, trans_err_m=0.1, ms=3.0)]  # fmt: skip
    files = write_outputs(tmp_path, BenchConfig(sequences=0), rows, [], [], 1.0)
    assert {f.name for f in files} == {"results.csv", "hypotheses.csv", "ablation.csv",
                                       "report.md", "config.json"}  # fmt: skip
    assert "| semloc | 1.00 / 1.00 |" in (tmp_path / "report.md").read_text()
