"""The bounded local map of a long run: which local objects the search works on.

The paper's clustering assumes one rigid local map, but a robot's odometry drifts and a day of
detections is not one view.  `LocalWindow` keeps the latest version of each local object in
the order it was last detected, with the odometry distance travelled at that moment, and
retires the oldest ones beyond two bounds (`WindowConfig`): a number of objects and metres
of travel.  An id sent again replaces its object and counts as detected now.

Choices where the method is silent:
* Travel is the path length of the robot positions given to `advance` (the odometry frame);
  updates that give none leave it unchanged, so without positions only the count bound acts.
* When a bound is exceeded, objects are retired down to `RETIRE_TO` of it (a quarter of
  headroom): the search rebuilds its association sets when objects retire, and the headroom
  makes that happen once every few updates instead of at every one.
* Defaults suit a walking robot that sends a few objects per half metre: 80 objects and 20 m
  keep about 15-20 m of a walk, over which 1 %/m of odometry drift stays below the clustering's
  distance tolerance (0.4 m).
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from semloc.maps import SemanticObject

RETIRE_TO = 0.75
"""When a bound is exceeded, the window is cut to this share of it."""


class WindowConfig(BaseModel):
    """How much of a long run the search works on, and how much history an answer carries."""

    model_config = ConfigDict(extra="forbid")

    objects: int | None = Field(
        80, ge=3, description="Most local objects the search works on (None: every object)."
    )
    distance: float | None = Field(
        20.0,
        gt=0,
        description="Metres of odometry travel the search works on: objects last detected "
        "longer ago are retired (needs robot positions; None: no distance bound).",
    )
    steps: int | None = Field(
        10, ge=1, description="Result.steps keeps the last this many updates (None: all)."
    )

    @classmethod
    def unbounded(cls) -> WindowConfig:
        """Every object, every step: one local map, as the paper's method has it."""
        return cls(objects=None, distance=None, steps=None)


@dataclass(frozen=True)
class Arrival:
    """When a window object was last detected: the update number and the travel (m)."""

    update: int
    travel: float


class LocalWindow:
    """The local objects of the window, oldest detection first."""

    def __init__(self, config: WindowConfig | None = None) -> None:
        self.config = config or WindowConfig()
        self.travel = 0.0
        self.updates = 0
        self._position: np.ndarray | None = None
        self._objects: OrderedDict[str, SemanticObject] = OrderedDict()
        self._arrival: dict[str, Arrival] = {}

    def __len__(self) -> int:
        return len(self._objects)

    def __contains__(self, object_id: str) -> bool:
        return object_id in self._objects

    @property
    def objects(self) -> list[SemanticObject]:
        """The window's objects, oldest detection first."""
        return list(self._objects.values())

    def arrival(self, object_id: str) -> Arrival:
        return self._arrival[object_id]

    def advance(self, position: np.ndarray | None) -> None:
        """A new update; `position` (the robot in the odometry frame) adds to the travel."""
        self.updates += 1
        if position is None:
            return
        if self._position is not None:
            self.travel += float(np.linalg.norm(position - self._position))
        self._position = position

    def add(self, objects: Iterable[SemanticObject]) -> None:
        """New objects, or new versions of known ones (they count as detected now)."""
        now = Arrival(self.updates, self.travel)
        for obj in objects:
            self._objects.pop(obj.id, None)
            self._objects[obj.id] = obj
            self._arrival[obj.id] = now

    def retire(self) -> list[str]:
        """Retire the oldest objects when a bound is exceeded; the ids retired (oldest first)."""
        count, distance = self.config.objects, self.config.distance
        over_count = count is not None and len(self._objects) > count
        over_distance = (
            distance is not None
            and bool(self._objects)
            and self.travel - self._arrival[next(iter(self._objects))].travel > distance
        )
        if not (over_count or over_distance):
            return []
        keep_count = len(self._objects) if count is None else int(count * RETIRE_TO)
        horizon = -np.inf if distance is None else self.travel - distance * RETIRE_TO
        retired = []
        for object_id in list(self._objects):
            if len(self._objects) <= keep_count and self._arrival[object_id].travel >= horizon:
                break
            retired.append(object_id)
            del self._objects[object_id], self._arrival[object_id]
        return retired

    def keep_only(self, object_ids: Iterable[str]) -> list[str]:
        """A fresh window of these objects (the others are retired); the ids retired."""
        keep = set(object_ids)
        retired = [i for i in self._objects if i not in keep]
        for object_id in retired:
            del self._objects[object_id], self._arrival[object_id]
        return retired

    def state(self) -> dict[str, Any]:
        """What rebuilds this window besides its objects (JSON types)."""
        return {
            "updates": self.updates,
            "travel": self.travel,
            "position": None if self._position is None else self._position.tolist(),
            "arrivals": [
                [i, a.update, a.travel] for i, a in self._arrival.items() if i in self._objects
            ],  # fmt: skip
            "order": list(self._objects),
        }

    @classmethod
    def restored(
        cls, config: WindowConfig, state: dict[str, Any], objects: Iterable[SemanticObject]
    ) -> LocalWindow:
        """The window of `state` (from `state()`) holding `objects` (its ids' latest versions);
        `ValueError` when they do not match."""
        window = cls(config)
        window.updates, window.travel = int(state["updates"]), float(state["travel"])
        position = state["position"]
        window._position = None if position is None else np.asarray(position, dtype=float)
        by_id = {o.id: o for o in objects}
        arrivals = {str(i): Arrival(int(u), float(t)) for i, u, t in state["arrivals"]}
        order = [str(i) for i in state["order"]]
        if set(order) != set(by_id) or set(order) != set(arrivals):
            raise ValueError("the window's objects are not those of its state")
        for object_id in order:
            window._objects[object_id] = by_id[object_id]
        window._arrival = arrivals  # (in the state's order: `since` lists ids in it)
        return window

    def since(self, update: int) -> list[str]:
        """Ids of the objects last detected at or after `update`."""
        return [i for i, a in self._arrival.items() if a.update >= update]
