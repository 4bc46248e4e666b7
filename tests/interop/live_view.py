"""docs/img/live_view.png: the live view as a viewer that joins late receives it, drawn from the
messages Foxglove's own client library decodes (`foxglove_viewer.viewer`), seen from above.

    python tests/interop/live_view.py docs/img/live_view.png   (after `make interop-deps`)

No Foxglove-protocol viewer could be run headless here (the npm registry has Lichtblick's and
Foxglove's extension APIs, not a built app), so this draws the decoded `foxglove.SceneUpdate`,
`PoseInFrame` and `Log` messages itself, top-down, as a 3D panel looking down on `map` would:
cubes, spheres, lines, arrows and texts of the scene entities; the status log as the title.
"""

from __future__ import annotations

import sys
import textwrap
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.axes import Axes  # noqa: E402
from matplotlib.patches import Circle, Polygon  # noqa: E402
from scipy.spatial.transform import Rotation  # noqa: E402

sys.path.insert(0, str(Path(__file__).parent))

from foxglove_viewer import viewer, walk_answers  # noqa: E402

from semloc.pictures.live import TOPICS, FoxgloveView  # noqa: E402

BACKGROUND = "#15151f"
SCENES = ("/semloc/map", "/semloc/local", "/semloc/hypotheses")


def _xy(vector: dict) -> np.ndarray:
    return np.array([vector["x"], vector["y"]])


def _rotation(pose: dict) -> Rotation:
    q = pose["orientation"]
    return Rotation.from_quat([q["x"], q["y"], q["z"], q["w"]])


def _rgba(color: dict) -> tuple[float, float, float, float]:
    return color["r"], color["g"], color["b"], color["a"]


def draw_entity(ax: Axes, entity: dict) -> list[np.ndarray]:
    """One `foxglove.SceneEntity`, seen from above; the points of its arrows and texts (which
    matplotlib leaves out of the axes' limits)."""
    points = []
    for cube in entity["cubes"]:
        half = np.array([cube["size"]["x"], cube["size"]["y"], 0.0]) / 2
        corners = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]]) * half
        xy = _rotation(cube["pose"]).apply(corners)[:, :2] + _xy(cube["pose"]["position"])
        ax.add_patch(Polygon(xy, closed=True, facecolor=_rgba(cube["color"]), edgecolor="none"))
    for sphere in entity["spheres"]:
        ax.add_patch(Circle(_xy(sphere["pose"]["position"]), sphere["size"]["x"] / 2,
                            color=_rgba(sphere["color"]), zorder=3))  # fmt: skip
    for line in entity["lines"]:
        pairs = np.array([_xy(p) for p in line["points"]]).reshape(-1, 2, 2)
        for a, b in pairs:
            ax.plot([a[0], b[0]], [a[1], b[1]], color=_rgba(line["color"]), lw=0.8, zorder=2)
    for arrow in entity["arrows"]:
        start = _xy(arrow["pose"]["position"])
        along = _rotation(arrow["pose"]).apply([1.0, 0.0, 0.0])[:2]
        length = arrow["shaft_length"] + arrow["head_length"]
        points += [start, start + length * along]
        ax.annotate("", xy=start + length * along, xytext=start, zorder=4,
                    arrowprops={"arrowstyle": "-|>", "color": _rgba(arrow["color"]), "lw": 1.6})  # fmt: skip
    for text in entity["texts"]:
        points.append(_xy(text["pose"]["position"]))
        ax.text(*points[-1], text["text"], color=_rgba(text["color"]), ha="center", va="bottom",
                fontsize=5 if entity["id"].startswith("map/") else 7, zorder=5)  # fmt: skip
    return points


def draw_view(ax: Axes, messages: dict[str, dict], title: str) -> None:
    """The scene channels and the pose of one late joiner's messages."""
    ax.set_facecolor(BACKGROUND)
    points = []
    for topic in SCENES:
        for entity in messages[topic]["message"]["entities"]:
            points += draw_entity(ax, entity)
    ax.update_datalim(np.array(points))
    if "/semloc/pose" in messages:
        pose = messages["/semloc/pose"]["message"]["pose"]
        start, along = _xy(pose["position"]), _rotation(pose).apply([1.0, 0.0, 0.0])[:2]
        ax.annotate("", xy=start + 1.5 * along, xytext=start, zorder=6,
                    arrowprops={"arrowstyle": "-|>", "color": "white", "lw": 2.0})  # fmt: skip
    status = messages["/semloc/status"]["message"]["message"]
    ax.set_title(f"{title}\n/semloc/status: {textwrap.fill(status, 120)}", fontsize=8, loc="left")
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.tick_params(labelsize=6)


def late_joiner(answers: list, building, until: int) -> dict[str, dict]:
    """What Foxglove's client decodes when it joins after answers[: until + 1]."""
    view = FoxgloveView(building, port=0)
    try:
        for answer in answers[: until + 1]:
            view.update(*answer)
        topics = [t for t in TOPICS if t not in ("/semloc/pose", "/tf")]
        if any(a[1].pose_is_answer for a in answers[: until + 1]):
            topics = list(TOPICS)
        return viewer(view.port, "foxglove.websocket.v1", topics)[2]
    finally:
        view.close()


def render(panels: list[tuple[str, dict[str, dict]]], out: Path) -> None:
    """Panels of (title, decoded messages), one above the other, into `out`."""
    fig, axes = plt.subplots(len(panels), 1, figsize=(11, 5.2 * len(panels)), squeeze=False)
    for ax, (title, messages) in zip(axes[:, 0], panels, strict=True):
        draw_view(ax, messages, title)
    fig.tight_layout()
    fig.savefig(out, dpi=130)
    plt.close(fig)


def main(out: Path) -> None:
    building, answers = walk_answers()
    ambiguous = max(i for i, a in enumerate(answers) if a[1].next_look)
    panels = [
        (f"answer {ambiguous + 1}: ambiguous, cyan arrows: where to look next, per rank",
         late_joiner(answers, building, ambiguous)),
        (f"answer {len(answers)}: localized, white arrow: /semloc/pose",
         late_joiner(answers, building, len(answers) - 1)),
    ]  # fmt: skip
    render(panels, out)


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path("docs/img/live_view.png"))
