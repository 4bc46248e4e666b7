"""Position priors: where the caller says the local frame's origin lies in the global map.

This module owns the `Prior` (its validation and JSON), the candidate gate it implies and the
test of a recovered pose against it; the Localizer applies both (numpy only).

`Prior(position=[x, y, z], radius=r)`: the local frame's origin lies within `r` metres of
`position` in the global frame.  Optional: a floor band `floor=(z_min, z_max)` for the
origin's height (the global z axis is up), and a heading `heading=deg` (the local x axis's
direction about the global z axis, counter-clockwise from global +x) within
`heading_tolerance` degrees (default `HEADING_TOLERANCE`).

A prior narrows the search; it never makes a place `localized` by itself:

1. **Candidate gate** (`Prior.gate`).  A local object at distance d from the local origin can
   only be a map object within `radius + d + slack` of `position` (and within `d + slack` of
   the floor band), where the slack allows for the bias of a partially seen centre (the
   tracking allowance: `GATE_SLACK` plus a quarter of the map object's diagonal).  It is exact
   for a prior that holds, cheap, and removes the far candidates, so a large map clusters
   fewer of them.
2. **Outside-prior hypotheses** (`Prior.admits`).  After pose recovery, a hypothesis whose
   pose puts the local origin outside the prior (beyond the radius, outside the floor band,
   off the heading, each by more than the error of a right pose, `POSE_MARGIN`) is not dropped: it stays in `hypotheses`, ranked as without a prior, with
   `outside_prior=True`, and cannot be `localized`: when it is the best, the answer is
   `ambiguous` with the reason `OUTSIDE_PRIOR` (the data point elsewhere than the caller
   said; the caller's prior or the map may be wrong).  Hypotheses within the prior carry
   `outside_prior=False`, and their confidence and rival checks are conditioned on the
   prior: a rival place outside it does not count against them (it is wrong if the prior
   holds; if the prior is wrong, so is every place within it).  Without a prior the field is
   None and nothing changes.  The gate feeds only the clustering: verification, evidence
   (supporting / conflicting objects) and tracking checks see all candidates, so a
   hypothesis's evidence is the same with and without a prior.
3. **Tracking.**  A tracked place whose followed pose leaves the prior ends the claim; the
   search resumes on the window, under the prior.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from semloc.maps import MAX_COORDINATE

GATE_SLACK = 1.0
"""Metres added to the gate's reach, besides a quarter of each map object's diagonal."""

HEADING_TOLERANCE = 30.0
"""Degrees: the heading tolerance when a heading is given without one."""

POSE_MARGIN = (0.5, 15.0)
"""Metres and degrees an estimated pose may lie beyond the prior's bounds and still be within
it: the error a right pose may have (the success criterion, 15 deg / 0.5 m)."""

OUTSIDE_PRIOR = "the best place lies outside the prior"
"""The start of the reason of an answer whose best hypothesis lies outside the prior."""


def _finite(value: Any, what: str) -> float:
    if isinstance(value, bool):
        raise ValueError(f"prior: {what} must be a number, got {value!r}")
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"prior: {what} must be a number, got {value!r}") from None
    if not math.isfinite(number):
        raise ValueError(f"prior: {what} must be finite, got {value!r}")
    return number


def _position(value: Any) -> np.ndarray:
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"prior: position must be [x, y, z], got {value!r}") from None
    if array.shape != (3,):
        raise ValueError(f"prior: position must be [x, y, z], got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"prior: position must be finite, got {array.tolist()}")
    if np.abs(array).max() > MAX_COORDINATE:
        raise ValueError(f"prior: position beyond ±{MAX_COORDINATE:g} m (the input limit)")
    return array


@dataclass(frozen=True, init=False)
class Prior:
    """The local frame's origin lies within `radius` metres of `position` (global frame);
    optionally its height within `floor` and its heading within `heading_tolerance` of
    `heading` (degrees about the global z axis).  Invalid values: `ValueError`."""

    position: np.ndarray
    radius: float
    floor: tuple[float, float] | None = None
    heading: float | None = None
    heading_tolerance: float | None = None

    def __init__(
        self,
        position: Any,
        radius: float,
        floor: tuple[float, float] | None = None,
        heading: float | None = None,
        heading_tolerance: float | None = None,
    ) -> None:
        radius = _finite(radius, "radius")
        if radius <= 0:
            raise ValueError(f"prior: radius must be > 0 (metres), got {radius:g}")
        band = None
        if floor is not None:
            if isinstance(floor, (str, bytes)) or len(floor) != 2:
                raise ValueError(f"prior: floor must be (z_min, z_max), got {floor!r}")
            band = (_finite(floor[0], "floor z_min"), _finite(floor[1], "floor z_max"))
            if max(abs(band[0]), abs(band[1])) > MAX_COORDINATE:
                raise ValueError(f"prior: floor beyond ±{MAX_COORDINATE:g} m (the input limit)")
            if band[0] > band[1]:
                raise ValueError(f"prior: floor needs z_min <= z_max, got {band}")
        if heading is None and heading_tolerance is not None:
            raise ValueError("prior: heading_tolerance needs a heading")
        tolerance = None
        if heading is not None:
            heading = _finite(heading, "heading")
            tolerance = _finite(
                HEADING_TOLERANCE if heading_tolerance is None else heading_tolerance,
                "heading_tolerance",
            )
            if not 0 < tolerance <= 180:
                raise ValueError(f"prior: heading_tolerance must be in (0, 180], got {tolerance:g}")
        object.__setattr__(self, "position", _position(position))
        object.__setattr__(self, "radius", radius)
        object.__setattr__(self, "floor", band)
        object.__setattr__(self, "heading", heading)
        object.__setattr__(self, "heading_tolerance", tolerance)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Prior) and self.to_dict() == other.to_dict()

    def __hash__(self) -> int:
        return hash(repr(self.to_dict()))

    @classmethod
    def from_dict(cls, data: Any) -> Prior:
        """A Prior from its JSON object (`to_dict`); `ValueError` when it is not one."""
        if not isinstance(data, dict) or "position" not in data or "radius" not in data:
            raise ValueError("prior: an object with 'position' [x, y, z] and 'radius' is needed")
        unknown = set(data) - {"position", "radius", "floor", "heading", "heading_tolerance"}
        if unknown:
            raise ValueError(f"prior: unknown field(s) {', '.join(sorted(unknown))}")
        return cls(**data)

    def to_dict(self) -> dict[str, Any]:
        data: dict[str, Any] = {"position": self.position.tolist(), "radius": self.radius}
        if self.floor is not None:
            data["floor"] = list(self.floor)
        if self.heading is not None:
            data["heading"] = self.heading
            data["heading_tolerance"] = self.heading_tolerance
        return data

    def gate(self, local_position: np.ndarray, global_positions: np.ndarray, slack: np.ndarray):
        """Which map objects (bool per row of `global_positions`) a local object at
        `local_position` (local frame) may be when the prior holds; `slack` per map object."""
        d = float(np.linalg.norm(local_position))
        reach = self.radius + d + slack
        near = np.linalg.norm(global_positions - self.position, axis=1) <= reach
        if self.floor is not None:
            z = global_positions[:, 2]
            near &= (z >= self.floor[0] - d - slack) & (z <= self.floor[1] + d + slack)
        return near

    def contains(self, pose: np.ndarray, metres: float = 0.0, degrees: float = 0.0) -> bool:
        """Whether `pose` (T_global_local) puts the local origin (and heading) in the prior,
        its bounds widened by `metres` and `degrees`."""
        origin = pose[:3, 3]
        if np.linalg.norm(origin - self.position) > self.radius + metres:
            return False
        if self.floor is not None and not (
            self.floor[0] - metres <= origin[2] <= self.floor[1] + metres
        ):
            return False
        if self.heading is not None:
            assert self.heading_tolerance is not None
            x_axis = pose[:3, 0]
            if math.hypot(x_axis[0], x_axis[1]) < 1e-9:  # local x along gravity: no heading
                return False
            yaw = math.degrees(math.atan2(x_axis[1], x_axis[0]))
            off = abs((yaw - self.heading + 180.0) % 360.0 - 180.0)
            if off > self.heading_tolerance + degrees:
                return False
        return True

    def admits(self, pose: np.ndarray) -> bool:
        """Whether an estimated pose may be the prior's place: `contains` with the margin of a
        right pose (`POSE_MARGIN`), so an estimate near the prior's edge is not ruled out."""
        return self.contains(pose, *POSE_MARGIN)

    def why_outside(self, pose: np.ndarray) -> str:
        """The reason of an answer whose best hypothesis (at `pose`) lies outside the prior."""
        distance = float(np.linalg.norm(pose[:3, 3] - self.position))
        return (
            f"{OUTSIDE_PRIOR}: its pose puts the local origin {distance:.2f} m from the "
            f"prior's position (radius {self.radius:g} m"
            + ("" if self.floor is None else ", floor band")
            + ("" if self.heading is None else ", heading")
            + ")"
        )


def checked_prior(prior: Any) -> Prior | None:
    """`prior` as a Prior (a Prior, its JSON object, or None); `TypeError` otherwise."""
    if prior is None or isinstance(prior, Prior):
        return prior
    if isinstance(prior, dict):
        return Prior.from_dict(prior)
    raise TypeError(f"prior must be a semloc.Prior, got {type(prior).__name__}")
