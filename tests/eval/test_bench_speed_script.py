"""benchmarks/bench_speed.py --profile stays runnable: its table on a small generated building."""

from __future__ import annotations

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
    assert any("_merges_of_frontier" in name for name in names)
    calls = {row.split(" | ")[0]: float(row.split(" | ")[1]) for row in rows}
    update = next(name for name in calls if "localizer.py" in name and "(update)" in name)
    assert calls[update] == 4.0  # one update per observed object
