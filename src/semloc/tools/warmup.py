"""Loading the compiled inner loops before timed work, and saying so when they compile.

The inner loops (numba, `cache=True`) are compiled on their first use after an install or
upgrade (a minute or more on 2 cores) and loaded from the on-disk cache on the first use in
every later process (a few hundred milliseconds).
`warm_up(notice)` runs two small localizations (gravity-aligned 4-DoF and 6-DoF, objects with
points, so that association, clustering, verification, ICP and fitness all run) and calls
`notice(COMPILING)` when numba starts compiling (not when it loads from its cache): the CLI
prints it, and reports the warm-up apart from the time per update.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np
from numba.core import event

from semloc.io.geometry import sample_box_surface
from semloc.localizer import localize
from semloc.maps import ObjectMap, SemanticObject
from semloc.transforms import yaw_pose

COMPILING = (
    "compiling semloc's inner loops: once after installing or upgrading (a minute or more); "
    "later runs load them in under a second"
)
_LABELS = ("chair", "table", "cabinet", "lamp")


class _CompileNotice(event.Listener):
    """Calls `notice(COMPILING)` when numba starts its first compilation (a load from the
    on-disk cache is not one)."""

    def __init__(self, notice: Callable[[str], None]) -> None:
        self.notice, self.shown = notice, False

    def on_start(self, ev: event.Event) -> None:
        if not self.shown:
            self.shown = True
            self.notice(COMPILING)

    def on_end(self, ev: event.Event) -> None:
        pass


@dataclass(frozen=True)
class WarmUp:
    """How long the warm-up took and whether it compiled (else it loaded compiled code)."""

    seconds: float
    compiled: bool

    def describe(self) -> str:
        what = "loading the compiled code (once per process)"
        if self.compiled:
            what = "compiling the inner loops (once after install)"
        return f"{self.seconds:.2f} s {what}"


def warm_up(notice: Callable[[str], None] | None = None) -> WarmUp:
    """Load (or compile) the compiled code a localization uses, timed.

    `notice(COMPILING)` is called once when numba starts compiling (see module doc)."""
    begin = time.perf_counter()
    with compile_notice(notice or (lambda text: None)) as listener:
        for up in ([0.0, 0.0, 1.0], None):
            localize(*warm_up_maps(up))
    return WarmUp(time.perf_counter() - begin, listener.shown)


@contextmanager
def compile_notice(notice: Callable[[str], None]) -> Iterator[_CompileNotice]:
    """Within the block, numba's first compilation calls `notice(COMPILING)`, once; the
    listener yielded says (`.shown`) whether one happened."""
    listener = _CompileNotice(notice)
    with event.install_listener("numba:compile", listener):
        yield listener


def warm_up_maps(up: list[float] | None, seed: int = 0) -> tuple[ObjectMap, ObjectMap]:
    """A small global map (12 boxes with surface points) and 6 of its objects, moved into a
    local frame and seen one per update."""
    rng = np.random.default_rng(seed)
    objects = []
    for i in range(12):
        centre = np.array([1.7 * (i % 4), 2.1 * (i // 4), 0.5]) + rng.uniform(-0.3, 0.3, 3)
        size = np.array([0.6, 0.5, 0.9]) * rng.uniform(0.7, 1.3)
        points = sample_box_surface(centre, size, np.eye(3), 400, rng)
        objects.append(SemanticObject(str(i), _LABELS[i % 4], centre, size=size, points=points))
    global_map = ObjectMap(objects, up=up)
    to_local = np.linalg.inv(yaw_pose(0.7, [1.0, -2.0, 0.1]))
    seen = [obj.transformed(to_local).replace(seen=k) for k, obj in enumerate(objects[:6])]
    return global_map, ObjectMap(seen, up=up)
