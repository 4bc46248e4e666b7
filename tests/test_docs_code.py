"""Every Python block of the README and of docs/ runs as written from the checkout's root,
and the example maps they read are what `examples/make_example_maps.py` writes."""

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


@pytest.mark.slow  # a subprocess per block: minutes in all
@pytest.mark.parametrize("code", [code for _, code in BLOCKS], ids=[w for w, _ in BLOCKS])
def test_a_python_block_runs_as_written(code, tmp_path):
    if "semloc.sim" in code and importlib.util.find_spec("open3d") is None:
        pytest.skip("the simulator needs the sim extra (open3d)")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path), "MPLCONFIGDIR": str(tmp_path)}
    run = subprocess.run([sys.executable, "-"], input=code, cwd=ROOT, env=env, text=True,
                         capture_output=True, timeout=600)  # fmt: skip
    assert run.returncode == 0, run.stderr[-3000:]


def test_the_example_maps_are_the_generated_ones(tmp_path):
    spec = importlib.util.spec_from_file_location("make_example_maps", ROOT / "examples" /
                                                  "make_example_maps.py")  # fmt: skip
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    for path in module.main(tmp_path):
        shipped = ROOT / "examples" / path.name
        assert json.loads(path.read_text()) == json.loads(shipped.read_text()), path.name
