"""benchmarks/bench_align.py: the CLIPPER-style baseline's bounded runs and how its cells read."""

from __future__ import annotations

import numpy as np
from helpers import benchmark_script

from semloc.sim.layouts import layout


def _script():
    return benchmark_script("bench_align")


def _outcome(script, ms, run):
    outcome = script.Outcome("building-0", 60, "clean", True, True, "localized", 1.0, 1.0, ms)
    outcome.clipper = run
    return outcome


def test_cells_say_what_ran_and_bound_what_did_not_finish():
    script = _script()
    finished = [
        _outcome(script, 100.0, script.ClipperRun(400.0, True, 50.0)),
        _outcome(script, 100.0, script.ClipperRun(600.0, False, 70.0)),
        _outcome(script, 50.0, None),  # not run: not counted
    ]
    assert script._versus(finished) == "50% (2) | 500 | 60 | 0.2"
    over_time = [_outcome(script, 100.0, script.ClipperRun(120_000.0, over="time"))]
    assert script._versus(over_time) == "- (0 of 1 finished) | > 120000 | - | < 0.00083"
    mixed = over_time + [_outcome(script, 100.0, script.ClipperRun(400.0, True, 50.0))] * 2
    assert script._versus(mixed) == "100% (2 of 3 finished) | 400 | 50 | 0.25"
    over_memory = script.ClipperRun(9.0, peak_mb=5000.0, over="memory", bound_mb=6144.0)
    cells = script._versus([_outcome(script, 100.0, over_memory)])
    assert cells == "- (0 of 1 finished) | out of memory | > 6144 | -"
    assert script._versus([_outcome(script, 100.0, None)]) == "- | - | - | -"


def test_the_baseline_runs_in_a_bounded_process():
    script = _script()
    full = layout(200, seed=0, points_per_object=8)
    script.warm_clipper(full)
    small = script.second_session(full, 10, "clean", np.random.default_rng(0))
    run = script.run_clipper(small, script.Bound(60, 2000))
    assert run.over is None and 0 < run.ms < 60_000 and run.peak_mb >= 0
    large = script.second_session(full, 40, "clean", np.random.default_rng(0))
    stopped = script.run_clipper(large, script.Bound(60, 20))  # its consistency graph: > 20 MB
    assert stopped.over == "memory" and stopped.bound_mb == 20
