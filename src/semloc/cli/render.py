"""Rich rendering of what the commands print: a Result's status, pose and hypotheses.

User text (ids, labels, file names) goes through `semloc.display.for_rich`: shortened and with
rich markup escaped."""

from __future__ import annotations

import numpy as np
from rich.console import Console
from rich.table import Table

from semloc.display import for_rich
from semloc.results import Result

STATUS_STYLE = {"localized": "green", "ambiguous": "yellow", "failed": "red"}
"""The colour of each status wherever one is printed (CLI, demo)."""


def print_result(result: Result, out: Console) -> None:
    """Status line, pose, top hypotheses and timing of a Result."""
    out.print(f"status: [bold {STATUS_STYLE[result.status]}]{result.status}[/]")
    if result.pose is not None:
        out.print("pose T_global_local:")
        for row in result.pose:
            out.print("  " + "  ".join(f"{v:9.4f}" for v in row))
    table = Table(title="hypotheses (best first)")
    for column, width in (("rank", 4), ("score", 7), ("pairs", 5), ("fitness", 7),
                          ("yaw°", 6), ("t (m)", 17)):  # fmt: skip
        table.add_column(column, justify="right", no_wrap=True, min_width=width)
    table.add_column("associations local→global", no_wrap=True, overflow="ellipsis")
    for h in result.hypotheses:
        yaw = translation = "-"
        if h.pose is not None:
            yaw = f"{np.degrees(np.arctan2(h.pose[1, 0], h.pose[0, 0])):.1f}"
            translation = " ".join(f"{v:.2f}" for v in h.pose[:3, 3])
        shown = ", ".join(f"{for_rich(l, 24)}→{for_rich(g, 24)}" for g, l in h.pairs[:6])
        shown += " …" if len(h.pairs) > 6 else ""
        fitness = "-" if h.fitness is None else f"{h.fitness:.2f}"
        table.add_row(str(h.rank), f"{h.score:.2f}", str(len(h.pairs)), fitness, yaw,
                      translation, shown)  # fmt: skip
    if result.hypotheses:
        out.print(table)
    steps = len(result.steps)
    total = result.timing_ms.get("total", 0.0)
    out.print(f"{steps} update(s), {total:.1f} ms in all")
