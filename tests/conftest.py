"""Shared test set-up: the tests folder on `sys.path` (for the helper modules below) and the
fixtures several test packages use.

Helper modules: `format_fixtures.py` writes small dataset files in each importer's format;
`helpers.py` holds small functions (real-data lookup that skips with a reason).  Yaw rotations
and poses come from `semloc.transforms` (`yaw_rotation`, `yaw_pose`, `rigid`).
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))

from helpers import real_sample_or_skip  # noqa: E402


@pytest.fixture
def real_sample():
    """`real_sample(*parts)`: a path under the real data folder, or skip the test."""
    return real_sample_or_skip
