"""Rich rendering of what the commands print: a Result, its ground-truth check, progress.

User text (ids, labels, file names) goes through `semloc.pictures.display.for_rich`: shortened and with
rich markup escaped."""

from __future__ import annotations

import json
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import numpy as np
from rich import box
from rich.console import Console
from rich.markup import escape
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from semloc.association import LabelResolution
from semloc.changes import Changes
from semloc.compiling import WarmUp
from semloc.eval.success import ROTATION_TOLERANCE_DEG, TRANSLATION_TOLERANCE_M
from semloc.maps import ObjectMap
from semloc.pictures.display import for_rich, shorten
from semloc.results import Hypothesis, Result
from semloc.tools.demo import STATUS_STYLE

LONG_REPLAY = 10
"""Replays of at least this many updates show a progress bar (on a terminal)."""


def print_result(
    result: Result,
    out: Console,
    warm: WarmUp | None = None,
    frames: tuple[str, str] = ("global", "local"),
) -> None:
    """Status line, pose, top hypotheses and timing of a Result (and of the warm-up before
    it, which loaded the compiled code: `semloc.compiling`).  `frames`: the names of the
    two maps (`align`: A and B), as the pose `T_<first>_<second>` and the pairs name them."""
    out.print(f"status: [bold {STATUS_STYLE[result.status]}]{result.status}[/]")
    best = result.best
    if best is not None and best.confidence is not None:
        out.print(f"confidence: {best.confidence:.3f}")
    if result.reason:
        out.print(f"reason: {escape(result.reason)}")
    looks = support_line(result)
    if looks:
        out.print(looks)
    pose_name = f"T_{frames[0]}_{frames[1]}"
    if result.pose is not None and result.status != "localized":
        out.print(
            "[bold yellow]warning:[/] not localized: the pose below is the best candidate's, "
            "not a trusted answer"
        )
        out.print(f"candidate pose {pose_name}:")
    elif result.pose is not None:
        out.print(f"pose {pose_name}:")
    if result.pose is not None:
        for row in result.pose:
            out.print("  " + "  ".join(f"{v:9.4f}" for v in row))
    if result.hypotheses:
        out.print(_hypotheses_table(result, out.width, frames))
    if result.next_look:
        out.print(_next_look_table(result, frames))
    print_changes(result.changes, out)
    out.print(timing_line(result, warm))


PAIRS_SHOWN = 6
"""Pairs shown per hypothesis (then `…`)."""
COLUMNS = (("rank", 4), ("score", 5), ("pairs", 5), ("fit", 4), ("conf.", 5), ("yaw°", 6),
           ("t (m)", 14))  # fmt: skip
"""The numeric columns of the hypotheses table and their least widths."""
OUTSIDE_MARK = "*"
"""Beside the rank of a hypothesis whose pose lies outside the position prior (`--near`)."""
TABLE_FRAME = 22
"""Characters of the hypotheses table that are not column content (padding, edges)."""


def _hypotheses_table(result: Result, width: int, frames: tuple[str, str]) -> Table:
    """The ranked places: the rank weighs all of a place's evidence (its confidence), so a
    set's clustering score need not fall with the rank; the caption says so.  Ids are
    shortened (with …) so that a pair fits the width left for the pairs: the column wraps
    between pairs, never inside an id."""
    rows = [_numbers(h) for h in result.hypotheses]
    used = TABLE_FRAME + sum(max(size, len(name), *(len(row[i]) for row in rows))
                             for i, (name, size) in enumerate(COLUMNS))  # fmt: skip
    limit = max(4, min(24, (width - used - 2) // 2))
    caption = "ranked by evidence (pairs, fit, confidence), not by score"
    if any(h.outside_prior for h in result.hypotheses):
        caption += f"; {OUTSIDE_MARK} outside the position prior"
    table = Table(title="hypotheses, best first", caption=caption, box=box.SIMPLE_HEAD,
                  padding=(0, 1))  # fmt: skip
    for name, size in COLUMNS:
        table.add_column(name, justify="right", no_wrap=True, min_width=size)
    table.add_column(f"associations {frames[1]}→{frames[0]}", min_width=2 * limit + 2,
                     overflow="fold")  # fmt: skip
    for h, row in zip(result.hypotheses, rows, strict=True):
        pairs = [f"{shorten(l, limit)}→{shorten(g, limit)}" for g, l in h.pairs[:PAIRS_SHOWN]]
        shown = ", ".join(p.replace(" ", "\u00a0") for p in pairs)  # no break inside an id
        shown += " …" if len(h.pairs) > PAIRS_SHOWN else ""
        table.add_row(*row, escape(shown))
    return table


def _next_look_table(result: Result, frames: tuple[str, str]) -> Table:
    """Where to look to tell the places apart: a map object, the spot (local frame) where
    each hypothesis it separates expects it, and the expected gain."""
    table = Table(title="look there next, best first",
                  caption=f"spots in the {frames[1]} frame; seeing the object at a rank's spot "
                          "confirms that rank, not seeing it rules it out",
                  box=box.SIMPLE_HEAD, padding=(0, 1))  # fmt: skip
    for name in ("label", f"{frames[0]} id", "rank: spot x y z (m)", "gain (bits)"):
        table.add_column(name, overflow="fold")
    for look in result.next_look:
        spots = "; ".join(
            f"{rank}: " + " ".join(f"{v:.2f}" for v in look.where[rank]) for rank in look.separates
        )
        table.add_row(for_rich(look.label), for_rich(look.global_id), spots,
                      f"{look.gain:.2f}")  # fmt: skip
    return table


def _numbers(h: Hypothesis) -> tuple[str, ...]:
    """The numeric cells of a hypothesis' row: rank (marked when outside the prior), score,
    pairs, fit, confidence, yaw, t."""
    yaw = translation = "-"
    if h.pose is not None:
        yaw = f"{np.degrees(np.arctan2(h.pose[1, 0], h.pose[0, 0])):.1f}"
        translation = " ".join(f"{v:.2f}" for v in h.pose[:3, 3])
    fitness = "-" if h.fitness is None else f"{h.fitness:.2f}"
    confidence = "-" if h.confidence is None else f"{h.confidence:.2f}"
    rank = f"{h.rank}{OUTSIDE_MARK}" if h.outside_prior else str(h.rank)
    return (rank, f"{h.score:.2f}", str(len(h.pairs)), fitness, confidence, yaw,
            translation)  # fmt: skip


MISSING_SHOWN = 8
"""Ids of missing map objects the support line names (then `…`)."""


def support_line(result: Result) -> str:
    """`support: N pairs; M of E map objects in view missing: ids` when the updates said what
    the sensor covered (empty otherwise: without coverage there is no negative evidence)."""
    support = result.support
    if support is None or support.n_expected is None or support.n_missing is None:
        return ""
    line = (f"support: {support.n_pairs} pairs; {support.n_missing} of {support.n_expected} map "
            "objects in view missing")  # fmt: skip
    ids = list(support.missing_ids or ())
    if ids:
        line += ": " + ", ".join(for_rich(i, 24) for i in ids[:MISSING_SHOWN])
        line += " …" if support.n_missing > MISSING_SHOWN else ""
    return line


def timing_line(result: Result, warm: WarmUp | None = None) -> str:
    """`N updates: T ms in all, M ms per update (median)`, and the warm-up apart."""
    times = [step.ms for step in result.steps]
    total = result.timing_ms.get("total", 0.0)
    line = f"{len(times)} update{'' if len(times) == 1 else 's'}: {total:.1f} ms in all"
    if times:
        line += f", {float(np.median(times)):.1f} ms per update (median)"
    if warm is not None:
        line += f"; before them, {warm.describe()}"
    return line


def print_changes(changes: Changes, out: Console) -> None:
    """What the best hypothesis says changed in the map (nothing printed when nothing did)."""
    if not (changes.moved or changes.new or changes.missing):
        return
    moved = ", ".join(f"{for_rich(m.global_id, 24)} (local {for_rich(m.local_id, 24)}, "
                      f"{m.offset_m:.2f} m)" for m in changes.moved)  # fmt: skip
    for name, text in (("moved", moved), ("new", ", ".join(for_rich(i, 24) for i in changes.new)),
                       ("missing", ", ".join(for_rich(i, 24) for i in changes.missing))):  # fmt: skip
        if text:
            out.print(f"changes, {name}: {text}")


def print_centres_only(local: ObjectMap, changes: Changes, out: Console) -> None:
    """When `new` objects are reported and some local objects have neither points nor a box,
    say what a change report needs: a centre alone does not show that a map object's place
    was in view, so such an object that moved reads as new, and nothing near it as missing."""
    bare = sum(o.points is None and o.size is None for o in local)
    if changes.new and bare:
        out.print(
            f"note: {bare} of {len(local)} local objects have neither points nor a box: such "
            "an object that moved reads as new (points or boxes show what was in view)"
        )


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


def warn_unmatched(report: dict[str, LabelResolution], out: Console) -> None:
    """One warning line per local label that matches no map label (labels as written, in
    any script)."""
    for label, found in report.items():
        if found.resolved == "unmatched":
            entry = for_rich(json.dumps({label: "<map label>"}, ensure_ascii=False), None)
            shown = for_rich(json.dumps(label, ensure_ascii=False), None)
            out.print(
                f"[bold yellow]warning:[/] local label {shown} matches no "
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
