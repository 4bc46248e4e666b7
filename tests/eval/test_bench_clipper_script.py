"""benchmarks/bench_clipper.py (and bench_speed.py --clipper) stay runnable: the cases written
once and measured, the tables, the ratios; CLIPPER's columns where a build is at hand
($SEMLOC_CLIPPER: its build's bindings/python folder)."""

from __future__ import annotations

import importlib
import os
import sys
from pathlib import Path

import pytest
from helpers import benchmark_script

from semloc.sim.layouts import layout


def _script():
    return benchmark_script("bench_clipper")


def _clipper_or_skip():
    """CLIPPER's binding: $SEMLOC_CLIPPER's build, or an installed clipperpy; else skip."""
    folder = os.environ.get("SEMLOC_CLIPPER")
    if folder:
        module, why = _script().load_clipper(Path(folder))
        if module is None:
            pytest.skip(f"CLIPPER: {why}")
        return module, folder
    try:
        module = importlib.import_module("clipperpy")
    except ImportError:
        pytest.skip("CLIPPER not built (set SEMLOC_CLIPPER to its build's bindings/python)")
    return module, str(Path(module.__file__).parents[1])


def _measured(tmp_path, clipperpy):
    script = _script()
    full = {"building": layout(60, seed=3, points_per_object=40)}
    count = script.write_cases(tmp_path, full, views=1, merges=1, merge_sizes=(15,), seed=0)
    assert count == 3 + 1  # one view per size, one merge
    return script, script.Worker(tmp_path, clipperpy, repeats=1).run()


def test_cases_are_measured_and_tabled_without_clipper(tmp_path):
    script, measured = _measured(tmp_path, None)
    assert [(m.kind, m.size) for m in measured] == [("view", 3), ("view", 5), ("view", 8),
                                                   ("merge", 15)]  # fmt: skip
    assert all(m.semloc_ms > 0 and m.file_ms > 0 and m.clipper_ms is None for m in measured)
    assert all(m.update_ms > 0 for m in measured if m.kind == "view")
    text = script.report(measured, with_clipper=False)
    assert "CLIPPER" not in text.replace("(semloc.", "")
    assert "| all | 3 |" in text and "| 15 | 1 |" in text


def test_clipper_core_and_file_to_answer_ratios(tmp_path):
    clipperpy, _ = _clipper_or_skip()
    script, measured = _measured(tmp_path, clipperpy)
    ran = [m for m in measured if m.clipper_ms is not None]
    assert ran and all(0 < m.clipper_ms < m.clipper_file_ms for m in ran)
    row = next(line for line in script.table(measured, "view", True).splitlines()
               if line.startswith("| all |"))  # fmt: skip
    assert row.count("×") == 2  # core and file-to-answer ratios


def test_paired_table_divides_this_checkout_by_the_other():
    script = _script()
    this = [script.Measured("view", 3, 4.0, 6.0, True, 2.0, 10, 0.1, 1.0, True),
            script.Measured("merge", 15, 30.0, 40.0, True, None, 80, 1.0, 5.0, True)]  # fmt: skip
    other = [script.Measured("view", 3, 8.0, 12.0, True, 4.0, 10, 0.1, 1.0, True),
             script.Measured("merge", 15, 60.0, 40.0, True, None, 80, 1.0, 5.0, True)]  # fmt: skip
    lines = script.paired_table(this, other, with_clipper=True).splitlines()
    assert lines[2] == "| view | 3 | 0.50 | 0.50 | 40.0× | 80.0× | 6.0× | 12.0× |"
    assert lines[4] == "| merge | 15 | 0.50 | 1.00 | 30.0× | 60.0× | 8.0× | 8.0× |"
    best = script.best_of_rounds([this, other])
    assert best[0].semloc_ms == 4.0 and best[1].file_ms == 40.0 and best[1].update_ms is None


def test_the_thread_count_is_said(monkeypatch):
    script = _script()
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    assert script.omp_note().startswith("OMP_NUM_THREADS=1")
    monkeypatch.delenv("OMP_NUM_THREADS")
    assert script.omp_note().startswith("WARNING: OMP_NUM_THREADS is unset")


def test_bench_speed_adds_clipper_columns():
    _, folder = _clipper_or_skip()
    speed = benchmark_script("bench_speed")
    rows = speed.measure_map("building-60", [3], 2, 0, 60, folder)
    assert all(c.clipper_ms is not None and c.clipper_ms > 0 for c in rows[0].cases)
    header, _, row = speed.speed_table(rows, with_clipper=True).splitlines()
    assert header.endswith("| CLIPPER score + solve ms | time ÷ CLIPPER | CLIPPER success |")
    assert len(row.split("|")) == len(header.split("|"))


@pytest.mark.slow
def test_against_another_checkout_pairs_the_two(capsys, monkeypatch):
    """`--against TREE` measures this checkout and TREE (here: this one again) in turn."""
    monkeypatch.setenv("SEMLOC_DATA", str(Path(sys.prefix) / "no-real-data"))
    root = Path(__file__).resolve().parents[2]
    arguments = ["--views", "1", "--merges", "1", "--merge-sizes", "15", "--repeats", "1"]
    _script().main([*arguments, "--against", str(root)])
    text = capsys.readouterr().out
    assert "## this checkout\n" in text and f"## {root}\n" in text
    assert f"## this checkout ÷ {root}" in text and "| merge | 15 |" in text
