"""Ctrl-C from the first moment of the `semloc` script (`semloc_entry`), as a terminal sends it:
SIGINT to the whole process group.  Exit status 130, the one line `semloc: interrupted` on
stderr, no traceback, no half-written output, no process left behind; `bench` also while Dask
starts its workers (a worker cut while it started failed the cluster: "Nanny failed to start"
and ~150 lines of tracebacks; one cut while its interpreter started printed a traceback).

Bounded: a few moments per command.  `benchmarks/interrupts.py` repeats them many times.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

import semloc
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


def _default_sigint() -> None:
    """In the child before it runs Python: SIGINT as a terminal leaves it.  A suite started in
    the background of a shell (`cmd &`) inherits SIGINT ignored, and Python then installs no
    handler of its own: what this test compares against would not be Python's default."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _env(tmp_path: Path) -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path), "OMP_NUM_THREADS": "1",
            "MPLCONFIGDIR": str(tmp_path / ".mpl")}  # fmt: skip


def assert_group_ends(group: int) -> None:
    deadline = time.monotonic() + 60  # a hang guard: ends as soon as the group is gone
    while time.monotonic() < deadline:
        try:
            os.killpg(group, 0)
        except ProcessLookupError:
            return
        time.sleep(0.1)
    os.killpg(group, signal.SIGKILL)
    raise AssertionError("processes of the interrupted command are still running")


PACKAGE = Path(semloc.__file__).parent
INIT_LINES = (PACKAGE / "__init__.py").read_text().splitlines()
HOLD_LINE = 1 + next(i for i, line in enumerate(INIT_LINES) if "hold_signals_for_module()" in line)
"""The line of `semloc/__init__` from which `python -m semloc` holds the signals."""
FRAME = re.compile(r'File "([^"]+)", line (\d+), in (\S+)')


def pythons_own_answer(code: int, err: str) -> bool:
    """Whether the run ended as Python ends a SIGINT that came before semloc held the signals:
    killed by SIGINT (before Python's handler, silently; after it, a KeyboardInterrupt
    traceback) or status 1 (in the import of `site`: "Fatal Python error: init_import_site"
    and the traceback), with no frame of the traceback past that point: not in
    `semloc_entry.main` (whose first line holds them), not in the `semloc` package beyond the
    top lines of its `__init__` (`python -m semloc`)."""
    if code not in (-signal.SIGINT, 1):
        return False
    if not err.strip():
        return code == -signal.SIGINT
    if not err.rstrip().splitlines()[-1].startswith("KeyboardInterrupt"):
        return False
    return not any(_past_the_hold(Path(path), int(line), function)
                   for path, line, function in FRAME.findall(err))  # fmt: skip


def _past_the_hold(path: Path, line: int, function: str) -> bool:
    """Whether a traceback's frame ran after semloc held the signals."""
    if path.name == "semloc_entry.py" and function == "main":
        return True
    return path.is_relative_to(PACKAGE) and (path != PACKAGE / "__init__.py" or line > HOLD_LINE)


def test_pythons_own_answer_is_only_a_signal_before_semloc_held_them():
    entry = str(PACKAGE.parent / "semloc_entry.py")
    before = (
        f'  File "/tmp/x/semloc", line 3, in <module>\n  File "{entry}", line 20, in <module>\n'
    )
    in_main = f'  File "/tmp/x/semloc", line 6, in <module>\n  File "{entry}", line 70, in main\n'
    top = f'  File "{PACKAGE / "__init__.py"}", line {HOLD_LINE}, in <module>\n'
    below = f'  File "{PACKAGE / "__init__.py"}", line {HOLD_LINE + 1}, in <module>\n'
    traceback = "Traceback (most recent call last):\n{}KeyboardInterrupt"
    assert pythons_own_answer(-signal.SIGINT, "")  # before Python's own handler
    assert pythons_own_answer(-signal.SIGINT, traceback.format(before))
    assert pythons_own_answer(-signal.SIGINT, traceback.format(top))
    assert not pythons_own_answer(-signal.SIGINT, traceback.format(in_main))
    assert not pythons_own_answer(-signal.SIGINT, traceback.format(below))
    site = '  File "<frozen site>", line 599, in main\n'  # site's `main`, not semloc_entry's
    fatal = "Fatal Python error: init_import_site: Failed to import the site module\n"
    assert pythons_own_answer(1, fatal + traceback.format(site))
    loader = "python: failed to set __main__.__loader__\n" + traceback.format("") + ": "
    assert pythons_own_answer(1, loader)  # "KeyboardInterrupt: ", the script's own import
    assert not pythons_own_answer(130, MESSAGE) and not pythons_own_answer(1, "")


@pytest.mark.parametrize("at", [0.05, 0.3, 1.0])
@pytest.mark.parametrize("module", [False, True], ids=["script", "python -m semloc"])
def test_ctrl_c_while_the_demo_starts(tmp_path, at, module):
    """From the script's first line on (the interpreter's own start-up takes a few tens of
    milliseconds, Python's handler there), through the import of the command (most of the
    first second) and its start: the command's answer.  `python -m semloc` imports the package
    first: it holds the signals from there on.

    The signal is sent at a fixed moment, so on a busy machine it can land in the interpreter's
    start-up, before semloc's first line ran: that window is Python's, and Python's own answer
    (`pythons_own_answer`: killed by SIGINT, a KeyboardInterrupt traceback that never reached
    semloc's code) is accepted there; from semloc's first line on, only semloc's."""
    argv = ["demo", "--keyframes", "6", "--out", "d"]
    code, lines = run_and_interrupt(tmp_path, argv, at, module=module)
    if not pythons_own_answer(code, "\n".join(lines)):
        assert (code, lines) == (130, [MESSAGE])
    assert not (tmp_path / "d").exists()


@pytest.mark.slow
def test_other_programs_keep_their_ctrl_c(tmp_path):
    """Only `python -m semloc` holds the signals while it imports: a program that imports
    semloc (run as a file or with -m) keeps Python's KeyboardInterrupt."""
    (tmp_path / "other.py").write_text(
        "import signal\nimport semloc\nprint(signal.getsignal(signal.SIGINT).__name__)\n"
    )
    for command in (["-m", "other"], ["other.py"], ["-c", "import other"]):
        done = subprocess.run([sys.executable, *command], cwd=tmp_path, env=_env(tmp_path),
                              capture_output=True, text=True, timeout=120,
                              preexec_fn=_default_sigint)  # fmt: skip
        assert (done.returncode, done.stdout.strip()) == (0, "default_int_handler"), done.stderr


@pytest.mark.slow
@pytest.mark.parametrize("at", [0.05, 0.3, 1.0, 2.0, 3.0])  # ~1 s: the workers start
def test_ctrl_c_while_dask_starts_its_workers(tmp_path, at):
    code, lines = run_and_interrupt(tmp_path, BENCH, at, TINY)
    if pythons_own_answer(code, "\n".join(lines)):  # before the script's first line
        return
    assert not any("Traceback" in line or "Nanny" in line for line in lines), lines
    if code == 0:  # finished first: the whole output
        assert (tmp_path / "out" / "report.md").exists()
    else:
        assert (code, lines) == (130, [MESSAGE])
        assert not (tmp_path / "out").exists()
