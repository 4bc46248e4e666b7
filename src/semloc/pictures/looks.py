"""Where an ambiguous answer's "look there next" suggestions (`Result.next_look`) point, in the
map frame: what the live views draw (`/semloc/markers` of `semloc.ros.answers`, the Foxglove
view of `semloc.pictures.live`).

A suggestion gives, for each top hypothesis (rank), where a map object lies in the local
(odometry) frame if that hypothesis is right; it tells apart the ranks it `separates`.  For each
separated rank r, `look_arrows` draws an arrow from where rank r puts the sensor now (its pose
applied to the sensor's odometry pose; the local frame's origin without one) to that spot,
placed in the map with rank r's pose: "if you are where #r says, look there".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from semloc.results import Result

LOOK_RGB = (0.0, 0.85, 0.95)
"""The colour of the suggestions in the live views."""


@dataclass(frozen=True)
class LookArrow:
    """One suggestion for one rank: the arrow's ends in the map frame and its label."""

    order: int  # 1: the best suggestion
    rank: int
    start: np.ndarray
    end: np.ndarray
    text: str


def look_arrows(result: Result, T_odom_sensor: np.ndarray | None = None) -> list[LookArrow]:
    """The arrows of `result.next_look` (empty unless the answer is ambiguous), best first."""
    poses = {h.rank: h.pose for h in result.hypotheses if h.pose is not None}
    sensor = np.zeros(3) if T_odom_sensor is None else np.asarray(T_odom_sensor)[:3, 3]
    arrows = []
    for order, look in enumerate(result.next_look, start=1):
        for rank in look.separates:
            pose = poses.get(rank)
            if pose is None or rank not in look.where:
                continue
            start = pose[:3, :3] @ sensor + pose[:3, 3]
            end = pose[:3, :3] @ np.asarray(look.where[rank], dtype=float) + pose[:3, 3]
            text = f"look {order}: {look.label} {look.global_id} for #{rank} ({look.gain:.2f} bit)"
            arrows.append(LookArrow(order, rank, start, end, text))
    return arrows
