"""benchmarks/bench_speed.py --profile stays runnable: its table on a small generated building."""

from __future__ import annotations

import pytest
from helpers import benchmark_script


def _script():
    return benchmark_script("bench_speed")


def test_profile_lists_the_kernels_per_localization():
    text = _script().profile_map("building-60", view=4, trials=2, seed=0, points=60, top=1000)
    header, _, table = text.partition("\n\n")
    assert header.startswith("cProfile of 2 localizations of 4 objects on building-60:")
    rows = table.splitlines()[2:]
    assert 30 < len(rows) <= 1000
    names = [row.split(" | ")[0] for row in rows]
    assert any("merges_of_frontier" in name for name in names)
    calls = {row.split(" | ")[0]: float(row.split(" | ")[1]) for row in rows}
    update = next(name for name in calls if "localizer.py" in name and "(_update)" in name)
    assert calls[update] == 4.0  # one update per observed object (`add` or `update`)


@pytest.mark.slow
def test_against_another_checkout_times_both_in_turn():
    """`--against TREE` runs each map in this checkout and in TREE (here: this one again),
    in turn, and prints per-round medians and their ratio."""
    import argparse
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    args = argparse.Namespace(
        against=str(root), rounds=2, trials=1, views=[3], seed=0, points=60, cpu=-1
    )
    text = _script().compare(["building-60"], args)
    row = next(line for line in text.splitlines() if line.startswith("| building-60 |"))
    cells = [cell.strip() for cell in row.strip("|").split("|")]
    assert cells[1] == "3" and len(cells[2].split(" / ")) == len(cells[3].split(" / ")) == 2
    assert all(float(x) > 0 for x in cells[2].split(" / ") + cells[3].split(" / "))
    assert float(cells[4]) > 0 and "2 rounds" in text
