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
    """The folder of real samples, or None when it does not exist.

    `$SEMLOC_DATA` when set; else `../shared/data/real` beside the project (the source tree
    this module lives in, or the current folder for an installed package)."""
    configured = os.environ.get("SEMLOC_DATA")
    if configured:
        return Path(configured) if Path(configured).is_dir() else None
    for root in (PROJECT_ROOT, Path.cwd()):
        folder = root.parent / "shared" / "data" / "real"
        if folder.is_dir():
            return folder
    return None


def real_sample(*parts: str) -> Path | None:
    """A path inside the real data folder, or None when the folder or the path is missing."""
    folder = real_data_dir()
    if folder is None:
        return None
    path = folder.joinpath(*parts)
    return path if path.exists() else None
