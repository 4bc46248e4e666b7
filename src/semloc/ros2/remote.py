"""Localizing through `semloc serve` instead of in-process: a `Localizer` stand-in for the node.

`RemoteLocalizer(session)` takes the node's fused objects like `Localizer.update` and sends
them as one update of a service session (`semloc.client.Session`, with the device's position
and, when given, what the sensor covered),
returning the service's answer as a `Result`; `set_prior` sets the session's position prior
from the next update on (sent with it) and `prior` is the one in effect; `local_map` holds the latest version of the
objects it sent (at most `window` of them, newest kept), for the markers.
"""

from __future__ import annotations

import time
from collections import OrderedDict
from collections.abc import Iterable
from typing import Any

import numpy as np

from semloc.coverage import Coverage
from semloc.maps import ObjectMap, SemanticObject
from semloc.priors import Prior
from semloc.results import Result


class RemoteLocalizer:
    """Updates of a service session in place of a Localizer (see the module docstring)."""

    def __init__(
        self, session: Any, global_map: ObjectMap, window: int = 80, up: Any = (0.0, 0.0, 1.0)
    ) -> None:
        self.session, self.global_map, self.window, self.up = session, global_map, window, up
        self._local: OrderedDict[str, SemanticObject] = OrderedDict()
        self._prior_set = False  # a prior change to send with the next update: _prior
        self._prior: Prior | None = None
        self._in_effect: Prior | None = None  # as the latest answer echoed it

    @property
    def prior(self) -> Prior | None:
        """The prior in effect: one set for the next update, else the one the session's
        latest answer echoed (None: none)."""
        return self._prior if self._prior_set else self._in_effect

    def set_prior(self, prior: Prior | None) -> None:
        """The session's prior from the next update on (None: none)."""
        self._prior_set, self._prior = True, prior

    def update(
        self,
        objects: Iterable[SemanticObject],
        *,
        position: Any = None,
        coverage: Coverage | None = None,
    ) -> Result:
        objects = list(objects)
        for obj in objects:
            self._local.pop(obj.id, None)
            self._local[obj.id] = obj
        while len(self._local) > self.window:
            self._local.popitem(last=False)
        at = None
        if position is not None:
            array = np.asarray(position, dtype=float)
            at = (array[:3, 3] if array.shape == (4, 4) else array.reshape(3)).tolist()
        prior, clear = self._prior, self._prior_set and self._prior is None
        answer = self.session.update(
            objects,
            stamp=time.time(),
            position=at,
            prior=prior,
            clear_prior=clear,
            coverage=coverage,
        )
        self._prior_set, self._prior = False, None
        result = Result.from_dict(answer)
        self._in_effect = result.prior  # the server's prior in effect, echoed
        return result

    @property
    def local_map(self) -> ObjectMap:
        return ObjectMap(self._local.values(), up=self.up, name="local")
