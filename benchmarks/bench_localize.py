"""Speed of the incremental Localizer: time per update on one core.

For global maps of 50 / 200 / 1000 objects (synthetic buildings full of repeated objects) and
local maps of 3 / 8 / 20 objects (one new object per update, 0.1-0.4 m centre bias, one
spurious detection), it replays each observation and prints, per configuration, the median
and 90th-percentile time of an update over all updates and trials, the time of the last
update (the largest local map) and the number of association sets kept.

    python benchmarks/bench_localize.py [--trials 5] [--globals 50 200 1000] [--locals 3 8 20]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # one core, as the targets are stated

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from rich.console import Console  # noqa: E402
from rich.table import Table  # noqa: E402

from semloc import Localizer  # noqa: E402
from semloc.sim.layouts import layout, observe  # noqa: E402


def time_replay(global_map, local_map) -> tuple[list[float], int]:
    """Milliseconds of each update of one replay, and the sets kept at the end."""
    localizer = Localizer(global_map, local_up=local_map.up)
    times = []
    for keyframe in sorted(set(local_map.seen.tolist())):
        objects = [o for o in local_map if o.seen == keyframe]
        start = time.perf_counter()
        localizer.update(objects)
        times.append((time.perf_counter() - start) * 1e3)
    return times, localizer.n_sets


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=5)
    parser.add_argument("--globals", type=int, nargs="+", default=[50, 200, 1000])
    parser.add_argument("--locals", type=int, nargs="+", default=[3, 8, 20])
    args = parser.parse_args()
    table = Table(title="Localizer.update time, one core (ms)")
    for column in ("global", "local", "median", "p90", "last update", "sets"):
        table.add_column(column, justify="right")
    console = Console()
    for n_global in args.globals:
        global_map = layout(n_global, seed=n_global)
        for n_local in args.locals:
            all_times, last, sets = [], [], []
            for trial in range(args.trials):
                obs = observe(global_map, n_local - 1, seed=trial)  # + 1 spurious
                times, n_sets = time_replay(global_map, obs.local_map)
                all_times += times
                last.append(times[-1])
                sets.append(n_sets)
            table.add_row(
                str(n_global),
                str(n_local),
                f"{np.median(all_times):.1f}",
                f"{np.percentile(all_times, 90):.1f}",
                f"{np.median(last):.1f}",
                f"{int(np.median(sets))}",
            )
            console.print(f"done {n_global} x {n_local}", style="dim")
    console.print(table)


if __name__ == "__main__":
    main()
