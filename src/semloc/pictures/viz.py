"""Plots (matplotlib, Agg backend): top-down maps, localization results, score curves, worlds.

Every `plot_*` function draws into a given `Axes` and returns it; `save_figure` writes a PNG
atomically (`semloc.io.write_atomic`).  Colours come from `semloc.pictures.colors` (one per label,
the same in every picture, export and recording); axes are in metres with equal aspect.  Labels,
ids and titles are user text: shown shortened and with `$` escaped (`semloc.pictures.display`).
"""

from __future__ import annotations

import io
import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.axes import Axes  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.patches import Patch, Polygon  # noqa: E402

from semloc.io import write_atomic  # noqa: E402
from semloc.maps import ObjectMap  # noqa: E402
from semloc.pictures.colors import CLASS_COLORS, label_colors  # noqa: E402, F401 (re-exported)
from semloc.pictures.display import for_matplotlib  # noqa: E402

if TYPE_CHECKING:
    from semloc.sim.world import World

LEGEND_LABELS = 30
"""Most labels listed in a legend (the rest are counted)."""
TITLE_LENGTH = 160
"""Longest title shown (user text: shortened and escaped, `semloc.pictures.display`)."""
NAME_LENGTH = 18
"""Longest object label written beside an object."""
ZOOM_MARGIN = 2.5
"""Metres of the map shown around the placed local objects (and rival places) when zoomed."""
RIVALS = 3
"""Most rival hypotheses drawn beside the best one of an ambiguous answer."""
RIVAL_COLOR = "darkorange"


def new_figure(width: float = 9.0, height: float = 7.0) -> tuple[Figure, Axes]:
    fig, ax = plt.subplots(figsize=(width, height), dpi=110)
    return fig, ax


def map_figure(xy: np.ndarray, width: float = 12.0) -> tuple[Figure, Axes]:
    """A figure whose height suits the extent of the points `xy` (N, 2) in a top-down view."""
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    span = np.ptp(xy, axis=0) + 2.0 if len(xy) else np.array([10.0, 10.0])
    height = float(np.clip((width - 3.0) * span[1] / span[0] + 1.2, 4.0, 10.0))
    return new_figure(width, height)


def save_figure(fig: Figure, path: str | os.PathLike[str]) -> Path:
    """Save `fig` as a PNG at `path` atomically (`semloc.io.write_atomic`), then close it."""
    buffer = io.BytesIO()
    try:
        fig.savefig(buffer, format="png", bbox_inches="tight")
    finally:
        plt.close(fig)
    path = Path(path)
    write_atomic(path, buffer.getvalue())
    return path


def _footprint(position: np.ndarray, size: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    half = size[:2] / 2
    corners = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]]) * np.r_[half, 0]
    return (corners @ rotation.T + position)[:, :2]


def plot_objects(
    ax: Axes,
    objmap: ObjectMap,
    colors: dict[str, str],
    *,
    T: np.ndarray | None = None,
    hollow: bool = False,
    points: bool = True,
    marker: str = "o",
    ids: bool = False,
    names: bool = False,
) -> Axes:
    """Draw a map's objects from above: oriented boxes where known, points, and centres.

    `T` (4x4) moves the objects first (e.g. local objects placed by an estimated pose);
    `hollow` draws outlines only (used for local objects over a global map); `names` writes
    each object's label beside it (those outside the axes' limits are not drawn).
    """
    if T is not None:
        objmap = objmap.transformed(T)
    for obj in objmap:
        color = colors.get(obj.label, "#444444")
        if points and obj.points is not None and len(obj.points):
            pts = obj.points[:: max(1, len(obj.points) // 300)]
            ax.scatter(
                pts[:, 0], pts[:, 1], s=1.0, color=color, alpha=0.25 if not hollow else 0.5, lw=0
            )
        if obj.size is not None and not hollow:
            rot = obj.rotation if obj.rotation is not None else np.eye(3)
            poly = Polygon(
                _footprint(obj.position, obj.size, rot),
                closed=True,
                fc=color,
                ec=color,
                alpha=0.35,
                lw=1,
            )
            ax.add_patch(poly)
        ax.scatter(
            *obj.position[:2],
            s=42 if hollow else 18,
            marker=marker,
            facecolors=color,
            edgecolors="k" if hollow else color,
            lw=1.0,
            alpha=0.9,
            zorder=4 if not hollow else 6,
        )
        if ids or names:
            text = " ".join(t for t, on in ((obj.label, names), (obj.id, ids)) if on)
            ax.annotate(
                for_matplotlib(text, NAME_LENGTH), obj.position[:2], fontsize=6, xytext=(3, 3),
                textcoords="offset points", color="#222", zorder=7, annotation_clip=True,
            )  # fmt: skip
    return ax


def _finish_map_axes(
    ax: Axes, colors: dict[str, str], extra: list[Any] | None = None, title: str = ""
) -> None:
    shown = list(colors.items())[:LEGEND_LABELS]
    handles: list[Any] = [Patch(fc=c, ec=c, alpha=0.6, label=for_matplotlib(label))
                          for label, c in shown]  # fmt: skip
    if len(colors) > LEGEND_LABELS:
        handles.append(Patch(fc="none", ec="none", label=f"… {len(colors) - LEGEND_LABELS} more"))
    handles += extra or []
    ax.legend(
        handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False
    )
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(True, lw=0.3, alpha=0.5)
    if title:  # one line at a time: a line break is kept, other control characters shown
        lines = (for_matplotlib(line, TITLE_LENGTH) for line in title.split("\n"))
        ax.set_title("\n".join(lines), fontsize=11)


def plot_localization(
    ax: Axes,
    global_map: ObjectMap,
    local_map: ObjectMap | None = None,
    pose: np.ndarray | None = None,
    pairs: Sequence[tuple[str, str]] = (),
    *,
    true_pose: np.ndarray | None = None,
    title: str = "",
    map_role: str = "global",
    rivals: Sequence[tuple[np.ndarray | None, Sequence[tuple[str, str]]]] = (),
    names: bool = False,
    zoom: bool = False,
    moved: Sequence[tuple[str, str]] = (),
) -> Axes:
    """Global map, local objects placed by `pose`, association lines (global centre to local).

    With `true_pose`, the local objects' true places are drawn as small grey crosses and the
    true local frame in grey.  `map_role` names the first map's objects in the legend
    ("global object", or "local object" when a local map is drawn on its own).  `rivals`
    (pose, pairs) of other hypotheses (an ambiguous answer's) are drawn in orange, up to
    `RIVALS`; `names` writes the labels beside the map's objects; `zoom` limits the view to
    the placed local objects, their true places and the rivals, with `ZOOM_MARGIN` around.
    `moved` (global id, local id) pairs of objects that moved since the map was made
    (`Result.changes`) are arrows from the map's place to the observed one.
    """
    labels = list(global_map.labels) + ([] if local_map is None else list(local_map.labels))
    colors = label_colors(labels)
    plot_objects(ax, global_map, colors, names=names)
    extra: list[Any] = [
        Line2D([], [], ls="none", marker="o", mfc="#999", mec="#999", label=f"{map_role} object")
    ]
    if local_map is not None and len(local_map) and pose is not None:
        placed = local_map.transformed(pose)
        plot_objects(ax, placed, colors, hollow=True, marker="D")
        extra.append(
            Line2D(
                [],
                [],
                ls="none",
                marker="D",
                mfc="#bbb",
                mec="k",
                label="local object (estimated pose)",
            )
        )
        for gid, lid in pairs:
            if gid in global_map and lid in placed:
                a, b = global_map.get(gid).position, placed.get(lid).position
                ax.plot([a[0], b[0]], [a[1], b[1]], color="k", lw=1.2, alpha=0.8, zorder=5)
        if pairs:
            extra.append(Line2D([], [], color="k", lw=1.2, label="association"))
    elif pairs:
        for gid, _ in pairs:
            if gid in global_map:
                p = global_map.get(gid).position
                ax.scatter(p[0], p[1], s=90, facecolors="none", edgecolors="k", lw=1.5, zorder=5)
        extra.append(
            Line2D([], [], ls="none", marker="o", mfc="none", mec="k", ms=9, label="associated")
        )
    if moved and local_map is not None and pose is not None:
        _plot_moved(ax, global_map, local_map.transformed(pose), moved, extra)
    if true_pose is not None and local_map is not None and len(local_map):
        truth = local_map.transformed(true_pose).positions
        ax.scatter(truth[:, 0], truth[:, 1], marker="x", s=22, color="#555", lw=1, zorder=6)
        extra.append(
            Line2D([], [], ls="none", marker="x", color="#555", label="local object (true pose)")
        )
    if true_pose is not None:
        _draw_frame(ax, true_pose, "local frame (true)", color="#555")
    if pose is not None:
        _draw_frame(ax, pose, "local frame (estimated)")
    shown = _plot_rivals(ax, global_map, local_map, rivals[:RIVALS], extra)
    _finish_map_axes(ax, colors, extra, title)
    if zoom:
        places = [local_map.transformed(T).positions for T in (pose, true_pose)
                  if T is not None and local_map is not None] + shown  # fmt: skip
        _zoom(ax, np.concatenate(places)[:, :2] if places else np.zeros((0, 2)))
    return ax


def _plot_rivals(
    ax: Axes,
    global_map: ObjectMap,
    local_map: ObjectMap | None,
    rivals: Sequence[tuple[np.ndarray | None, Sequence[tuple[str, str]]]],
    extra: list[Any],
) -> list[np.ndarray]:
    """Each rival's place: the local objects placed by its pose (or, without a local map,
    its global objects ringed) and its frame labelled by rank; returns the points drawn."""
    drawn = []
    for rank, (pose, pairs) in enumerate(rivals, start=2):
        if local_map is not None and len(local_map) and pose is not None:
            xy = local_map.transformed(pose).positions
            ax.scatter(xy[:, 0], xy[:, 1], marker="s", s=30, facecolors="none",
                       edgecolors=RIVAL_COLOR, lw=1.2, zorder=6)  # fmt: skip
        else:
            xy = np.array([global_map.get(g).position for g, _ in pairs if g in global_map])
            xy = xy.reshape(-1, 3)
            ax.scatter(xy[:, 0], xy[:, 1], s=90, facecolors="none", edgecolors=RIVAL_COLOR,
                       lw=1.2, ls="--", zorder=6)  # fmt: skip
        if pose is not None:
            _draw_frame(ax, pose, f"rival (rank {rank})", color=RIVAL_COLOR)
        drawn.append(xy)
    if rivals:
        extra.append(Line2D([], [], ls="none", marker="s", mfc="none", mec=RIVAL_COLOR,
                            label="rival place (another hypothesis)"))  # fmt: skip
    return drawn


MOVED_COLOR = "#1f77b4"


def _plot_moved(ax: Axes, global_map: ObjectMap, placed: ObjectMap, moved, extra: list) -> None:
    """An arrow per moved object, from its place in the map to where it was observed."""
    for gid, lid in moved:
        if gid in global_map and lid in placed:
            a, b = global_map.get(gid).position, placed.get(lid).position
            ax.annotate("", xy=(b[0], b[1]), xytext=(a[0], a[1]), zorder=7,
                        arrowprops=dict(arrowstyle="->", color=MOVED_COLOR, lw=1.8))  # fmt: skip
    extra.append(Line2D([], [], color=MOVED_COLOR, lw=1.8, label="moved since the map (→ now)"))


def _zoom(ax: Axes, xy: np.ndarray) -> None:
    """Limit the view to the points `xy` with `ZOOM_MARGIN` around (unchanged without any)."""
    if not len(xy):
        return
    low, high = xy.min(axis=0) - ZOOM_MARGIN, xy.max(axis=0) + ZOOM_MARGIN
    ax.set_xlim(low[0], high[0])
    ax.set_ylim(low[1], high[1])


def _draw_frame(ax: Axes, T: np.ndarray, label: str, color: str = "crimson") -> None:
    """The frame's origin and x axis, labelled on a white box above everything else."""
    o, x = T[:2, 3], T[:2, 0]
    n = np.linalg.norm(x)
    if n > 1e-9:
        x = x / n * 0.8
        ax.annotate(
            "", xy=o + x, xytext=o, arrowprops={"arrowstyle": "->", "color": color, "lw": 2},
            zorder=9,
        )  # fmt: skip
    ax.scatter(*o, color=color, s=25, zorder=9, label=None)
    ax.annotate(
        label, o, fontsize=7, color=color, xytext=(4, -10), textcoords="offset points", zorder=10,
        bbox={"fc": "white", "ec": "none", "alpha": 0.8, "pad": 1},
    )  # fmt: skip


def plot_scores(
    ax: Axes,
    steps: Sequence[Any],
    *,
    statuses: Sequence[str] | None = None,
    title: str = "",
    x_label: str = "update",
) -> Axes:
    """Top-1 and top-2 association-set scores after each update (the paper's incremental plot)."""
    x = [int(getattr(s, "step", i)) for i, s in enumerate(steps)]
    top = [list(getattr(s, "top_scores", []) or []) for s in steps]
    first = np.array([t[0] if len(t) > 0 else np.nan for t in top], dtype=float)
    second = np.array([t[1] if len(t) > 1 else np.nan for t in top], dtype=float)
    ax.plot(x, first, "-o", ms=3.5, color="#1f77b4", label="best association set")
    ax.plot(x, second, "-s", ms=3.0, color="#ff7f0e", label="second best (another pose)")
    lower = np.where(np.isfinite(second), second, first)
    ax.fill_between(x, lower, first, color="#1f77b4", alpha=0.12, label="margin")
    positive = first[np.isfinite(first) & (first > 0)]
    if len(positive) and positive.max() > 100 * positive.min():
        ax.set_yscale("log")
    if statuses is not None:
        done = [xi for xi, s in zip(x, statuses, strict=False) if s == "localized"]
        if done:
            label = f"first 'localized' ({x_label} {done[0]})"
            ax.axvline(done[0], color="green", ls="--", lw=1, label=label)
    ax.set_xlabel(x_label)
    ax.set_ylabel("association-set score")
    ax.grid(True, lw=0.3, alpha=0.5)
    ax.legend(fontsize=8, loc="upper left")
    if title:
        ax.set_title(for_matplotlib(title, TITLE_LENGTH), fontsize=11)
    return ax


def plot_world(
    ax: Axes, world: World, *, trajectory: np.ndarray | None = None, title: str = ""
) -> Axes:
    """A world from above: walls, rooms by kind, object footprints by class, a camera path."""
    colors = label_colors([o.label for o in world.objects])
    for mesh in world.background[1:]:
        lo, hi = mesh.bounds
        ax.add_patch(
            Polygon(
                [[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]],
                fc="#333",
                ec="#333",
            )
        )
    for room in world.rooms:
        ax.text(
            room.center[0], room.center[1], f"{room.index}: {room.kind}", ha="center", va="center",
            fontsize=9, color="#222", zorder=8, bbox={"fc": "white", "ec": "none", "alpha": 0.7},
        )  # fmt: skip
    for obj in world.objects:
        lo, hi = obj.model.mesh.bounds
        corners = np.array(
            [[lo[0], lo[1], 0, 1], [hi[0], lo[1], 0, 1], [hi[0], hi[1], 0, 1], [lo[0], hi[1], 0, 1]]
        )
        xy = (corners @ obj.pose.T)[:, :2]
        color = colors[obj.label]
        ax.add_patch(
            Polygon(
                xy, closed=True, fc=color, ec="k", alpha=0.7, lw=0.5, zorder=3 if obj.support else 2
            )
        )
        front = obj.pose[:2, 1] * 0.25
        c = obj.pose[:2, 3]
        ax.plot([c[0], c[0] + front[0]], [c[1], c[1] + front[1]], color="k", lw=0.5, zorder=4)
    extra: list[Any] = []
    if trajectory is not None and len(trajectory):
        ax.plot(trajectory[:, 0], trajectory[:, 1], "-", color="crimson", lw=1.2, zorder=6)
        ax.scatter(trajectory[:, 0], trajectory[:, 1], s=6, color="crimson", zorder=6)
        extra.append(Line2D([], [], color="crimson", marker="o", ms=3, label="camera keyframes"))
    _finish_map_axes(ax, colors, extra, title)
    return ax
