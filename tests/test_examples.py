"""The README's examples run as a user runs them, and find the pose."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def test_use_with_your_detector_finds_the_odometry_frame():
    run = subprocess.run([sys.executable, str(EXAMPLES / "use_with_your_detector.py")],
                         capture_output=True, text=True, timeout=300)  # fmt: skip
    assert run.returncode == 0, run.stderr
    last = run.stdout.strip().splitlines()[-1]
    found = re.fullmatch(r"T_global_odom found: localized, error ([\d.]+) deg / ([\d.]+) m", last)
    assert found, last
    assert float(found[1]) < 2.0 and float(found[2]) < 0.1
    assert "frame  4: 3 local objects" in run.stdout  # the local map grows frame by frame
