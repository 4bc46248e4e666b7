"""Library use says once on stderr that it compiles (the `semloc` logger); `semloc.warmup()`
and `semloc warmup` compile or load every inner loop ahead."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

import semloc
from semloc.cli import main
from semloc.compiling import COMPILING, LIBRARY_NOTICE

FIRST_USE = """
from semloc.digests import encode_ids, pair_digests
ids = encode_ids(["a", "b", "c"])
pair_digests(ids, [0], ids, [1])
pair_digests(ids, [2], ids, [0])
print("done")
"""


def run_python(code: str, cache: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path), "NUMBA_CACHE_DIR": cache}
    return subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                          text=True, timeout=600)  # fmt: skip


@pytest.mark.slow
def test_library_use_says_once_on_stderr_that_it_compiles(tmp_path):
    """With nothing compiled yet (an empty cache) the first compiled call says so, once, on
    stderr and without any logging set up; with the cache filled, nothing is said."""
    first = run_python(FIRST_USE, str(tmp_path))
    assert first.returncode == 0 and first.stdout == "done\n", first.stderr
    assert first.stderr.count(COMPILING) == 1, first.stderr
    assert first.stderr == LIBRARY_NOTICE + "\n" and "semloc warmup" in first.stderr
    again = run_python(FIRST_USE, str(tmp_path))
    assert again.returncode == 0 and again.stderr == "", again.stderr


def test_warmup_from_python_and_from_the_command_line(capsys):
    done = semloc.warmup()
    assert done.seconds > 0 and isinstance(done.compiled, bool)
    assert main(["warmup"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("ready: ") and " s " in out
    assert not semloc.warmup().compiled  # everything was compiled or loaded above
