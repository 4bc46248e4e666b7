"""Where the real data samples live: `$SEMLOC_DATA`, else `<project root>/../shared/data/real`.

The samples are third-party research data (ScanNet, Scan2CAD, Replica, 3RScan) that are never
copied into the repository; tests and benchmarks find them through `real_data_dir()` and skip
when it returns None.
"""

from __future__ import annotations

import os
from pathlib import Path

PROJECT_ROOT = Path(__file__).resolve().parents[3]


def real_data_dir() -> Path | None:
    """The folder of real samples, or None when it does not exist."""
    configured = os.environ.get("SEMLOC_DATA")
    folder = Path(configured) if configured else PROJECT_ROOT.parent / "shared" / "data" / "real"
    return folder if folder.is_dir() else None


def real_sample(*parts: str) -> Path | None:
    """A path inside the real data folder, or None when the folder or the path is missing."""
    folder = real_data_dir()
    if folder is None:
        return None
    path = folder.joinpath(*parts)
    return path if path.exists() else None
