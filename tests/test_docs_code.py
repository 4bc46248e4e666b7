"""Every Python block of the README and of docs/ runs as written from the checkout's root
and does what its words say (`CLAIMS`: the answers a block promises), the detector block runs
from any folder, and the example maps they read are what `examples/make_example_maps.py`
writes."""

from __future__ import annotations

import importlib.util
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
FENCE = re.compile(r"^```python\n(.*?)^```", re.S | re.M)


def python_blocks() -> list[tuple[str, str]]:
    """(page:line, code) of each ```python block."""
    blocks = []
    for page in PAGES:
        text = page.read_text()
        for match in FENCE.finditer(text):
            line = text.count("\n", 0, match.start()) + 1
            blocks.append((f"{page.relative_to(ROOT)}:{line}", match.group(1)))
    return blocks


BLOCKS = python_blocks()


def test_the_pages_have_python_blocks():
    assert len(BLOCKS) >= 7  # the README's two, and the docs'


def run_block(code: str, cwd: Path, tmp_path: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path), "MPLCONFIGDIR": str(tmp_path)}
    return subprocess.run([sys.executable, "-"], input=code, cwd=cwd, env=env, text=True,
                          capture_output=True, timeout=600)  # fmt: skip


def two_places_fit(out: str) -> None:
    """The building of a room and its copy 40 m away without the lamp: `ambiguous`, the two
    top places are the room and the copy, and the lamp (only in the room) is where to look."""
    lines = out.splitlines()
    assert lines[0].startswith("ambiguous"), out
    origins = sorted(line.split("at ")[1] for line in lines[1:3])
    assert [line.split(":")[0] for line in lines[1:3]] == ["rank 1", "rank 2"], out
    assert origins == ["[ 1.5 -0.8  0. ]", "[41.5 -0.8  0. ]"], out
    room_rank = next(line.split(":")[0][5:] for line in lines[1:3] if "[ 1.5" in line)
    assert any(line.startswith("look for the lamp") and line.endswith(f"rank {room_rank}?")
               for line in lines[3:]), out  # fmt: skip


def quickstart_localizes(out: str) -> None:
    """The README's first block: the example's local map is `localized`, both ways."""
    lines = out.splitlines()
    assert lines[-4].startswith("localized [[") and lines[-1].endswith("1.00000000e+00]]"), out


CLAIMS = {"# two places fit": two_places_fit, "r = semloc.localize(g, l)": quickstart_localizes}
"""A block holding the key makes the claims its function checks on the block's output."""


def test_the_claims_are_checked_on_their_blocks():
    checked = [where for where, code in BLOCKS if any(key in code for key in CLAIMS)]
    assert {"README.md", "docs/buildings.md"} <= {where.split(":")[0] for where in checked}
    assert len(checked) >= 3, checked


@pytest.mark.slow  # a subprocess per block: minutes in all
@pytest.mark.parametrize("code", [code for _, code in BLOCKS], ids=[w for w, _ in BLOCKS])
def test_a_python_block_runs_as_written(code, tmp_path):
    if "semloc.sim" in code and importlib.util.find_spec("open3d") is None:
        pytest.skip("the simulator needs the sim extra (open3d)")
    run = run_block(code, ROOT, tmp_path)
    assert run.returncode == 0, run.stderr[-3000:]
    for key, check in CLAIMS.items():
        if key in code:
            check(run.stdout)


def test_the_detector_block_runs_from_any_folder(tmp_path):
    """Its stand-ins and map ship with semloc (`semloc.tools.standins`): no checkout needed."""
    [code] = [code for _, code in BLOCKS if "semloc.tools.standins" in code]
    code += "print(result.status, T_global_odom[:3, 3].round(1) + 0.0)\n"
    run = run_block(code, tmp_path, tmp_path)
    assert run.returncode == 0, run.stderr[-3000:]
    assert run.stdout == "localized [ 1.5 -0.8  0. ]\n", run.stdout


def test_the_example_maps_are_the_generated_ones(tmp_path):
    spec = importlib.util.spec_from_file_location("make_example_maps", ROOT / "examples" /
                                                  "make_example_maps.py")  # fmt: skip
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    for path in module.main(tmp_path):
        shipped = ROOT / "examples" / path.name
        assert json.loads(path.read_text()) == json.loads(shipped.read_text()), path.name
    packaged = ROOT / "src" / "semloc" / "tools" / "example_room.json"  # the stand-ins' room
    assert packaged.read_text() == (ROOT / "examples" / "global.json").read_text()
