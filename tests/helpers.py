"""Small helpers shared by the test packages."""

from __future__ import annotations

from pathlib import Path

import pytest

from semloc.eval.datasets import real_sample


def real_sample_or_skip(*parts: str) -> Path:
    """A path inside the real data folder ($SEMLOC_DATA or ../shared/data/real), or skip."""
    path = real_sample(*parts)
    if path is None:
        pytest.skip(f"real data sample {'/'.join(parts)} not found (set SEMLOC_DATA)")
    return path
