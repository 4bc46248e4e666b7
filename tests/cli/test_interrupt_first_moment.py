"""Ctrl-C from the first moment of the `semloc` script (`semloc_entry`), as a terminal sends it:
SIGINT to the whole process group.  Exit status 130, the one line `semloc: interrupted` on
stderr, no traceback, no half-written output, no process left behind; `bench` also while Dask
starts its workers (a worker cut while it started failed the cluster: "Nanny failed to start"
and ~150 lines of tracebacks; one cut while its interpreter started printed a traceback).

Bounded: a few moments per command.  `benchmarks/interrupts.py` repeats them many times.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from semloc.io.interrupts import MESSAGE

# What pip writes as the `semloc` script (console_scripts entry `semloc_entry:main`).
SCRIPT = """import re
import sys
from semloc_entry import main
if __name__ == "__main__":
    sys.argv[0] = re.sub(r"(-script\\.pyw|\\.exe)?$", "", sys.argv[0])
{patch}    sys.exit(main())
"""
# `bench --quick` shrunk to one tiny sequence (seconds), through the same script.
TINY = """    import semloc_entry

    semloc_entry.hold_signals()  # as main() does first, before this patch's imports
    from semloc.eval import protocol
    from semloc.cli import bench

    class Tiny(protocol.BenchConfig):
        @classmethod
        def quick(cls, **overrides):
            tiny = dict(size="tiny", keyframes=40, map_kinds=["cad"], ablation_starts=0,
                        real=False)
            return protocol.BenchConfig.quick(**{**tiny, **overrides})

    bench.BenchConfig = Tiny
"""
BENCH = ["bench", "--quick", "--sequences", "1", "--starts", "1", "--workers", "2",
         "--methods", "semloc", "--no-progress", "--out", "out"]  # fmt: skip
NOTICE = "compiling semloc's inner loops"  # the first use of a fresh cache says so


def run_and_interrupt(
    tmp_path: Path, argv: list[str], at: float, patch: str = "", module: bool = False
) -> tuple:
    """Start the script (or `python -m semloc`) in its own process group, SIGINT the group
    after `at` s; (status, stderr lines without the compile notice)."""
    script = tmp_path / "semloc"
    script.write_text(SCRIPT.format(patch=patch))
    command = ["-m", "semloc"] if module else [str(script)]
    proc = subprocess.Popen([sys.executable, *command, *argv], cwd=tmp_path, env=_env(tmp_path),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)  # fmt: skip
    time.sleep(at)
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGINT)  # what a terminal's Ctrl-C does
    _, err = proc.communicate(timeout=120)
    assert_group_ends(proc.pid)
    lines = [line for line in err.splitlines() if line.strip() and NOTICE not in line]
    return proc.returncode, lines


def _env(tmp_path: Path) -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path), "OMP_NUM_THREADS": "1",
            "MPLCONFIGDIR": str(tmp_path / ".mpl")}  # fmt: skip


def assert_group_ends(group: int) -> None:
    deadline = time.monotonic() + 15
    while time.monotonic() < deadline:
        try:
            os.killpg(group, 0)
        except ProcessLookupError:
            return
        time.sleep(0.1)
    os.killpg(group, signal.SIGKILL)
    raise AssertionError("processes of the interrupted command are still running")


@pytest.mark.parametrize("at", [0.05, 0.3, 1.0])
@pytest.mark.parametrize("module", [False, True], ids=["script", "python -m semloc"])
def test_ctrl_c_while_the_demo_starts(tmp_path, at, module):
    """From the script's first line on (the interpreter's own start-up takes a few tens of
    milliseconds, Python's handler there), through the import of the command (most of the
    first second) and its start: the command's answer.  `python -m semloc` imports the package
    first: it holds the signals from there on."""
    argv = ["demo", "--keyframes", "6", "--out", "d"]
    code, lines = run_and_interrupt(tmp_path, argv, at, module=module)
    assert (code, lines) == (130, [MESSAGE])
    assert not (tmp_path / "d").exists()


def test_other_programs_keep_their_ctrl_c(tmp_path):
    """Only `python -m semloc` holds the signals while it imports: a program that imports
    semloc (run as a file or with -m) keeps Python's KeyboardInterrupt."""
    (tmp_path / "other.py").write_text(
        "import signal\nimport semloc\nprint(signal.getsignal(signal.SIGINT).__name__)\n"
    )
    for command in (["-m", "other"], ["other.py"], ["-c", "import other"]):
        done = subprocess.run([sys.executable, *command], cwd=tmp_path, env=_env(tmp_path),
                              capture_output=True, text=True, timeout=120)  # fmt: skip
        assert (done.returncode, done.stdout.strip()) == (0, "default_int_handler"), done.stderr


@pytest.mark.slow
@pytest.mark.parametrize("at", [0.05, 0.3, 1.0, 2.0, 3.0])  # ~1 s: the workers start
def test_ctrl_c_while_dask_starts_its_workers(tmp_path, at):
    code, lines = run_and_interrupt(tmp_path, BENCH, at, TINY)
    assert not any("Traceback" in line or "Nanny" in line for line in lines), lines
    if code == 0:  # finished first: the whole output
        assert (tmp_path / "out" / "report.md").exists()
    else:
        assert (code, lines) == (130, [MESSAGE])
        assert not (tmp_path / "out").exists()
