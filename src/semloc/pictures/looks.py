"""Where an ambiguous answer's "look there next" suggestions (`Result.next_look`) point, in the
map frame: what the live views draw (`/semloc/markers` of `semloc.ros.answers`, the Foxglove
view of `semloc.pictures.live`).

A suggestion gives, for each top hypothesis (rank r), the spot `where[r]` of the local
(odometry) frame at which a map object lies if r is right; looking there tells apart the ranks
it `separates`.  The views draw the robot as the best hypothesis places it, so the spots are
placed with the best hypothesis's pose too: for each separated rank r, an arrow from the
sensor (its odometry pose, placed by the best hypothesis; the local frame's origin without one)
to spot r, labelled `look N: LABEL ID if #r`: "look there: a LABEL there means #r".  (Placed
with rank r's own pose every spot of a suggestion would land on the same map object, which
cannot show the ranks apart.)
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
    """The arrows of `result.next_look` (empty unless the answer is ambiguous and its best
    hypothesis has a pose), best suggestion first."""
    best = result.best
    if best is None or best.pose is None:
        return []
    R, t = best.pose[:3, :3], best.pose[:3, 3]
    sensor = np.zeros(3) if T_odom_sensor is None else np.asarray(T_odom_sensor)[:3, 3]
    start = R @ sensor + t
    arrows = []
    for order, look in enumerate(result.next_look, start=1):
        for rank in look.separates:
            if rank in look.where:
                end = R @ np.asarray(look.where[rank], dtype=float) + t
                text = f"look {order}: {look.label} {look.global_id} if #{rank}"
                arrows.append(LookArrow(order, rank, start, end, text))
    return arrows
