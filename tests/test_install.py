"""A plain `pip install .` in a fresh virtual environment: a light core that localizes.

Needs the network (PyPI): marked `install`, left out of `make test`, run by `make test-install`
and `.ci/run`.  The versions are those of constraints.txt, as in CI.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
MAX_PACKAGES = 20
HEAVY = {"open3d", "open3d-cpu", "dask", "distributed", "scikit-learn", "matplotlib", "torch",
         "rerun-sdk"}  # fmt: skip


def _run(*args: str | Path, **kwargs) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    return subprocess.run([str(a) for a in args], capture_output=True, text=True, env=env,
                          timeout=900, **kwargs)  # fmt: skip


def _packages(python: Path) -> set[str]:
    listed = _run(python, "-m", "pip", "list", "--format=json")
    assert listed.returncode == 0, listed.stderr
    return {p["name"].lower().replace("_", "-") for p in json.loads(listed.stdout)}


@pytest.mark.install
def test_core_install_is_light_and_localizes(tmp_path):
    venv = tmp_path / "venv"
    assert _run(sys.executable, "-m", "venv", venv).returncode == 0
    python, semloc = venv / "bin" / "python", venv / "bin" / "semloc"
    before = _packages(python)
    installed = _run(python, "-m", "pip", "install", "--quiet", "-c", ROOT / "constraints.txt",
                     ROOT, cwd=tmp_path)  # fmt: skip
    assert installed.returncode == 0, installed.stderr[-2000:]
    new = _packages(python) - before
    site = next((venv / "lib").glob("python3*/site-packages"))
    size = sum(f.stat().st_size for f in site.rglob("*") if f.is_file()) / 1e6
    print(f"core install: {len(new)} packages, {size:.0f} MB: {sorted(new)}")
    assert "semloc" in new and len(new) <= MAX_PACKAGES, sorted(new)
    assert not new & HEAVY, sorted(new & HEAVY)

    make_maps = (
        "import semloc; from semloc.sim.layouts import layout, observe; "
        "g = layout(40, seed=1); o = observe(g, 10, seed=2, spurious=0, wrong_label_rate=0.0); "
        "semloc.save_map(g, 'g.json'); semloc.save_map(o.local_map, 'l.json'); "
        "import json; json.dump({'T_global_local': o.T_global_local.tolist()}, open('gt.json', 'w'))"
    )
    assert _run(python, "-c", make_maps, cwd=tmp_path).returncode == 0
    located = _run(semloc, "localize", "g.json", "l.json", "--gt", "gt.json", "--format", "json",
                   cwd=tmp_path)  # fmt: skip
    assert located.returncode == 0, located.stderr
    result = json.loads(located.stdout)
    assert result["status"] == "localized" and result["ground_truth"]["success"] is True

    demo = _run(semloc, "demo", cwd=tmp_path)
    assert demo.returncode == 2
    assert demo.stderr.strip().splitlines() == [
        "semloc: error: semloc demo needs the 'sim' extra (open3d is not installed): "
        "pip install 'semloc[sim]'"
    ]
