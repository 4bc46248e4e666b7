"""Shared test set-up: the tests folder on `sys.path` (for the helper modules below) and the
fixtures several test packages use.

numba compiles into a folder named after a hash of the package's sources (`numba_cache.py`:
numba's own cache check misses changes in other modules a cached kernel calls).

DDS (Cyclone DDS, `tests/ros2`) is confined to loopback for every test (`CYCLONEDDS_URI`).

Property tests draw the same examples on every run (Hypothesis's `derandomize`, no example
database) and no example has a deadline (the suite runs with both cores busy: a slow example
is no failure): it passes or fails the same way on every machine.  To search for new
counterexamples, run with `SEMLOC_HYPOTHESIS=explore` (random examples, remembered in
`.hypothesis/`); a counterexample found becomes an `@example` of its test once fixed.

Helper modules: `format_fixtures.py` writes small dataset files in each importer's format;
`helpers.py` holds small functions (real-data lookup that skips with a reason).  Yaw rotations
and poses come from `semloc.transforms` (`yaw_rotation`, `yaw_pose`, `rigid`).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest
from hypothesis import settings

sys.path.insert(0, str(Path(__file__).parent))

settings.register_profile("suite", derandomize=True, database=None, deadline=None)
settings.register_profile("explore", deadline=None)
settings.load_profile(os.environ.get("SEMLOC_HYPOTHESIS", "suite"))

from numba_cache import use_fresh_cache  # noqa: E402

NUMBA_CACHE = use_fresh_cache()  # before anything imports semloc (and so numba)

from helpers import real_sample_or_skip  # noqa: E402

LOOPBACK_DDS = (
    '<CycloneDDS><Domain><General><Interfaces><NetworkInterface name="lo"/></Interfaces>'
    "<AllowMulticast>false</AllowMulticast></General><Discovery><Peers>"
    '<Peer address="127.0.0.1"/></Peers><ParticipantIndex>auto</ParticipantIndex>'
    "<MaxAutoParticipantIndex>40</MaxAutoParticipantIndex></Discovery></Domain></CycloneDDS>"
)
os.environ["CYCLONEDDS_URI"] = LOOPBACK_DDS  # DDS stays on loopback (tests/ros2)


@pytest.fixture
def real_sample():
    """`real_sample(*parts)`: a path under the real data folder, or skip the test."""
    return real_sample_or_skip
