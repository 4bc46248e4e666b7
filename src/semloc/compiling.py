"""The compiled inner loops: compiling them ahead, loading them before timed work, saying once
when they compile.

The inner loops (numba, `cache=True`) are compiled on their first use after an install or
upgrade (about 80 s of CPU: a minute and a half on 2 cores, longer on a busy machine) and
loaded from the on-disk cache on the first use in every later process (a few hundred
milliseconds).  The first compilation of one of
semloc's loops in a process is announced once on stderr: through the `semloc` logger
(a warning: Python prints it without any logging set up), or through the `notice` of a
`compile_notice` block (the CLI prints it its way).
`warm_up(notice)` runs two small localizations (gravity-aligned 4-DoF and 6-DoF, objects with
points, so that association, clustering, verification, ICP and fitness all run), timed;
`warmup()` (`semloc.warmup`, `semloc warmup`) also runs a map-to-map alignment, so that every
compiled path is ready: before timed work, or in a Dockerfile.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np
from numba.core import event

from semloc.alignment import align
from semloc.localizer import LocalizerConfig, localize
from semloc.maps import ObjectMap, SemanticObject
from semloc.pointsets import sample_box_surface
from semloc.transforms import yaw_pose

COMPILING = (
    "compiling semloc's inner loops: once after installing or upgrading (about a minute and a "
    "half; longer on a busy machine); later runs load them in under a second"
)
LIBRARY_NOTICE = (
    f"semloc: {COMPILING}. semloc.warmup() or `semloc warmup` compiles them ahead "
    "(e.g. in a Dockerfile)"
)
_LABELS = ("chair", "table", "cabinet", "lamp")
_RETRIEVING = LocalizerConfig(retrieval={"above": 0})
log = logging.getLogger("semloc")


class _CompileNotice(event.Listener):
    """Counts numba's compilations of semloc's functions (a load from the on-disk cache is
    not one) and says `COMPILING` once per process: by `say`, the `semloc` logger's warning
    unless a `compile_notice` block says it its way."""

    def __init__(self) -> None:
        self.say: Callable[[str], None] = lambda text: log.warning(LIBRARY_NOTICE)
        self.shown = False
        self.compiled = 0

    def on_start(self, ev: event.Event) -> None:
        dispatcher = (ev.data or {}).get("dispatcher")
        module = getattr(getattr(dispatcher, "py_func", None), "__module__", "") or ""
        if module.split(".")[0] != "semloc":
            return
        self.compiled += 1
        if not self.shown:
            self.shown = True
            self.say(COMPILING)

    def on_end(self, ev: event.Event) -> None:
        pass


_NOTICE = _CompileNotice()
event.register("numba:compile", _NOTICE)


@dataclass
class Compiled:
    """Whether numba compiled one of semloc's functions within a `compile_notice` block."""

    before: int

    @property
    def shown(self) -> bool:
        return _NOTICE.compiled > self.before


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

    `notice(COMPILING)` is called if numba starts compiling and has not said so yet in this
    process (see module doc); without `notice`, the `semloc` logger says it."""
    begin = time.perf_counter()
    with compile_notice(notice) as compiled:
        for up in ([0.0, 0.0, 1.0], None):
            localize(*warm_up_maps(up))
        localize(*warm_up_maps([0.0, 0.0, 1.0]), config=_RETRIEVING)  # large maps' path
    return WarmUp(time.perf_counter() - begin, compiled.shown)


def warmup(notice: Callable[[str], None] | None = None) -> WarmUp:
    """Compile (after an install) or load every inner loop of localization and alignment, so
    that later calls start at once; `semloc.warmup()`.  Returns how long it took and whether
    it compiled.  Run it once where the package is installed, e.g. in a Dockerfile: the
    compiled code is cached beside the sources (or in `NUMBA_CACHE_DIR`)."""
    begin = time.perf_counter()
    with compile_notice(notice) as compiled:
        warm_up(notice)
        align(*warm_up_maps([0.0, 0.0, 1.0]))
    return WarmUp(time.perf_counter() - begin, compiled.shown)


@contextmanager
def compile_notice(notice: Callable[[str], None] | None) -> Iterator[Compiled]:
    """Within the block, numba's first compilation of semloc's code in this process calls
    `notice(COMPILING)` (None: the `semloc` logger says it); the object yielded says
    (`.shown`) whether semloc's code compiled within the block."""
    previous = _NOTICE.say
    if notice is not None:
        _NOTICE.say = notice
    try:
        yield Compiled(_NOTICE.compiled)
    finally:
        _NOTICE.say = previous


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
