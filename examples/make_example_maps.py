"""Writes the small example maps the README's and the docs' code blocks read.

    python examples/make_example_maps.py

`examples/global.json`: a furnished room of 10 objects (oriented boxes with points on their
surfaces), the prior map.  `examples/local.json`: 6 of them seen again in another frame (the frame of an
odometry that started elsewhere), with other points on their surfaces and one object per
keyframe (`seen`), as a robot would have mapped them.  `examples/local.gt.json`: the true
`T_global_local`.  The files are generated, not measured: rerunning this script rewrites them
identically.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

import semloc

HERE = Path(__file__).resolve().parent

ROOM = [
    ("table", (3.0, 2.0, 0.38), (1.6, 0.9, 0.76)), ("chair", (2.4, 1.2, 0.45), (0.5, 0.5, 0.9)),
    ("chair", (3.6, 1.2, 0.45), (0.5, 0.5, 0.9)), ("chair", (3.0, 2.9, 0.45), (0.5, 0.5, 0.9)),
    ("sofa", (0.7, 3.6, 0.4), (2.0, 0.9, 0.8)), ("lamp", (0.3, 0.4, 0.8), (0.35, 0.35, 1.6)),
    ("cabinet", (5.6, 3.5, 0.9), (0.6, 1.2, 1.8)), ("plant", (5.5, 0.4, 0.5), (0.5, 0.5, 1.0)),
    ("tv", (2.9, 4.4, 1.2), (1.2, 0.1, 0.7)), ("bookshelf", (0.2, 2.0, 1.0), (0.35, 1.0, 2.0)),
]  # fmt: skip
"""The room: (label, centre, size) of each object, in the map's frame (z up, metres)."""

SEEN = [0, 1, 2, 3, 8, 9]
"""The objects of the room the local map holds, in the order they were seen."""

YAW, SHIFT = np.radians(35.0), (1.5, -0.8, 0.0)
"""The local frame in the map's: a turn about up, then a shift (T_global_local)."""


def box_points(rng: np.random.Generator, centre, size, n: int) -> np.ndarray:
    """`n` points on the surface of an axis-aligned box (a stand-in for a scanned object)."""
    points = rng.uniform(-0.5, 0.5, size=(n, 3))
    face = rng.integers(0, 3, size=n)
    points[np.arange(n), face] = np.sign(points[np.arange(n), face]) * 0.5
    return points * np.asarray(size) + np.asarray(centre)


def t_global_local() -> np.ndarray:
    """The true pose of the local frame in the map's frame."""
    pose = np.eye(4)
    c, s = np.cos(YAW), np.sin(YAW)
    pose[:3, :3] = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    pose[:3, 3] = SHIFT
    return pose


def example_maps(points_per_object: int = 100) -> tuple[semloc.ObjectMap, semloc.ObjectMap]:
    """The global map and the local map (in its own frame), reproducibly."""
    rng = np.random.default_rng(0)
    objects = [
        semloc.SemanticObject(f"g{i}", label, c, size=s, rotation=np.eye(3),
                              points=box_points(rng, c, s, points_per_object))
        for i, (label, c, s) in enumerate(ROOM)
    ]  # fmt: skip
    global_map = semloc.ObjectMap(objects, up=[0, 0, 1], name="example room")
    to_local = np.linalg.inv(t_global_local())
    seen = []
    for keyframe, index in enumerate(SEEN):
        label, centre, size = ROOM[index]
        again = semloc.SemanticObject(
            f"l{keyframe}", label, centre, size=size, rotation=np.eye(3),
            points=box_points(rng, centre, size, points_per_object), seen=keyframe,
        )  # fmt: skip
        seen.append(again.transformed(to_local))
    local_map = semloc.ObjectMap(seen, up=[0, 0, 1], name="example local view")
    return global_map, local_map


def main(folder: Path = HERE) -> list[Path]:
    """Write global.json, local.json and local.gt.json into `folder`."""
    global_map, local_map = example_maps()
    truth = {"T_global_local": np.round(t_global_local(), 9).tolist()}
    written = [
        semloc.save_map(global_map, folder / "global.json", points="inline"),
        semloc.save_map(local_map, folder / "local.json", points="inline"),
    ]
    (folder / "local.gt.json").write_text(json.dumps(truth, indent=1) + "\n")
    return [*written, folder / "local.gt.json"]


if __name__ == "__main__":
    for path in main():
        print(f"wrote {path}")
