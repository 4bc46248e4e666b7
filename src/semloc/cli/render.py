"""Rich rendering of what the commands print: a Result, its ground-truth check, progress.

User text (ids, labels, file names) goes through `semloc.tools.display.for_rich`: shortened and with
rich markup escaped."""

from __future__ import annotations

import json
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import numpy as np
from rich.console import Console
from rich.markup import escape
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from semloc.association import LabelResolution
from semloc.eval.success import ROTATION_TOLERANCE_DEG, TRANSLATION_TOLERANCE_M
from semloc.maps import ObjectMap
from semloc.results import Result
from semloc.tools.demo import STATUS_STYLE
from semloc.tools.display import for_rich

LONG_REPLAY = 10
"""Replays of at least this many updates show a progress bar (on a terminal)."""


def print_result(result: Result, out: Console) -> None:
    """Status line, pose, top hypotheses and timing of a Result."""
    out.print(f"status: [bold {STATUS_STYLE[result.status]}]{result.status}[/]")
    best = result.best
    if best is not None and best.confidence is not None:
        out.print(f"confidence: {best.confidence:.3f}")
    if result.reason:
        out.print(f"reason: {escape(result.reason)}")
    if result.pose is not None and result.status != "localized":
        out.print(
            "[bold yellow]warning:[/] not localized: the pose below is the best candidate's, "
            "not a trusted answer"
        )
        out.print("candidate pose T_global_local:")
    elif result.pose is not None:
        out.print("pose T_global_local:")
    if result.pose is not None:
        for row in result.pose:
            out.print("  " + "  ".join(f"{v:9.4f}" for v in row))
    table = Table(title="hypotheses (best first)")
    for column, width in (("rank", 4), ("score", 7), ("pairs", 5), ("fitness", 7),
                          ("conf.", 5), ("yaw°", 6), ("t (m)", 17)):  # fmt: skip
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
        confidence = "-" if h.confidence is None else f"{h.confidence:.2f}"
        table.add_row(str(h.rank), f"{h.score:.2f}", str(len(h.pairs)), fitness, confidence,
                      yaw, translation, escape(shown))  # fmt: skip
    if result.hypotheses:
        out.print(table)
    steps = len(result.steps)
    total = result.timing_ms.get("total", 0.0)
    out.print(f"{steps} update(s), {total:.1f} ms in all")


def print_labels(report: dict[str, LabelResolution], out: Console) -> None:
    """How each local label was read against the map's labels, one row per label."""
    table = Table(title="labels (local → map)")
    table.add_column("local label", no_wrap=True)
    table.add_column("resolved", no_wrap=True)
    table.add_column("map labels", overflow="ellipsis")
    for label, found in report.items():
        style = "yellow" if found.resolved == "unmatched" else ""
        shown = ", ".join(for_rich(x, 24) for x in found.map_labels[:6])
        shown += " …" if len(found.map_labels) > 6 else ""
        table.add_row(for_rich(label, 32), f"[{style}]{found.resolved}[/]" if style else
                      found.resolved, shown or "-")  # fmt: skip
    if report:
        out.print(table)


def labels_json(report: dict[str, LabelResolution]) -> dict[str, dict]:
    """The `labels` object of the JSON output."""
    return {label: {"resolved": found.resolved, "map_labels": list(found.map_labels)}
            for label, found in report.items()}  # fmt: skip


def warn_unmatched(report: dict[str, LabelResolution], out: Console) -> None:
    """One warning line per local label that matches no map label."""
    for label, found in report.items():
        if found.resolved == "unmatched":
            entry = escape(json.dumps({label: "<map label>"}))
            out.print(
                f"[bold yellow]warning:[/] local label {escape(json.dumps(label))} matches no "
                f"map label (its objects have no candidates); add a label map entry such as "
                f"{entry} (--label-map FILE)",
                soft_wrap=True,
            )


def print_ground_truth(report: dict, out: Console) -> None:
    """Pose error against the truth, success at 15° / 0.5 m, rank of the first right one."""
    rank = report["rank_of_first_correct"]
    ranked = "no hypothesis is right" if rank is None else f"first right hypothesis: rank {rank}"
    if report["rotation_deg"] is None:
        out.print(f"ground truth: [red]no pose estimate[/] ({ranked})")
        return
    verdict = "[green]success[/]" if report["success"] else "[red]failure[/]"
    out.print(
        f"ground truth: rotation error {report['rotation_deg']:.2f}°, translation error "
        f"{report['translation_m']:.3f} m: {verdict} at {ROTATION_TOLERANCE_DEG:g}° / "
        f"{TRANSLATION_TOLERANCE_M:g} m ({ranked})"
    )


@contextmanager
def replay_progress(
    out: Console, local_map: ObjectMap
) -> Iterator[Callable[[int, int], None] | None]:
    """A `progress(done, total)` callback drawing a bar on `out` for long replays on a
    terminal (None otherwise); the bar disappears when the replay ends."""
    updates = len(set(local_map.seen.tolist()))
    if not out.is_terminal or updates < LONG_REPLAY:
        yield None
        return
    columns = (TextColumn("replaying updates"), BarColumn(), MofNCompleteColumn(),
               TimeElapsedColumn())  # fmt: skip
    with Progress(*columns, console=out, transient=True) as bar:
        task = bar.add_task("replay", total=updates)
        yield lambda done, total: bar.update(task, completed=done, total=total)
