"""The `semloc` script: SIGINT and SIGTERM are honoured from its first moment.

Importing the command (numpy, scipy, numba, typer and semloc itself) takes a good part of a
second; a Ctrl-C in there would end in a KeyboardInterrupt traceback, or cut an extension
module's initialisation.  So this module, which imports nothing heavy and sits outside the
`semloc` package (importing any of it runs `semloc/__init__`), keeps the signals that arrive
while the command is imported, and `semloc.cli.main` raises the first of them as soon as its
own handlers are installed (`semloc.io.interrupts`): status 130 / 143, `semloc: interrupted`.
`python -m semloc` gets the same from the top of `semloc/__init__` (`hold_signals_for_module`).

A process that `multiprocessing` spawns from the script (the Dask workers of `semloc bench`)
runs the script again as its `__mp_main__` before anything else: imported there, this module
makes it ignore SIGINT from its first moment (the command closes its workers itself; a
terminal's Ctrl-C reaches the whole process group, and a worker cut while it started made the
cluster fail with "Nanny failed to start" and a hundred lines of tracebacks).
"""

from __future__ import annotations

import signal
import sys

_EARLY: list[int] = []


def _keep(signum: int, frame: object) -> None:
    _EARLY.append(signum)


def _spawned_by_multiprocessing() -> bool:
    """Whether this process is a `multiprocessing` child still being prepared (it imports its
    parent's main script before the work it was started for)."""
    process = sys.modules.get("multiprocessing.process")
    return process is not None and bool(getattr(process.current_process(), "_inheriting", False))


def hold_signals() -> None:
    """From now until the command's own handlers take over, keep SIGINT and SIGTERM."""
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, _keep)


def hold_signals_for_module() -> None:
    """`python -m semloc ...` (or `-m semloc.cli`) imports the package before its `__main__`
    runs: called at the top of `semloc/__init__`, keep SIGINT and SIGTERM from then on, as the
    script does (its `__main__` then runs `main`).  Nothing for any other module run with -m
    that imports semloc, nor for a program that imports it."""
    if sys.argv[:1] == ["-m"] and _module_run() in ("semloc", "semloc.cli"):
        hold_signals()


def _module_run() -> str | None:
    """While `python [options] -m MODULE args` locates its module (`sys.argv` is then `-m` and
    the args): MODULE, read from the interpreter's own command line."""
    first = len(sys.orig_argv) - len(sys.argv)  # where MODULE is: the args follow it
    if first < 2:
        return None
    before, name = sys.orig_argv[first - 1], sys.orig_argv[first]
    if before.startswith("-") and not before.startswith("--") and before.endswith("m"):
        return name  # -m semloc, -Im semloc
    if name.startswith("-") and not name.startswith("--") and "m" in name:
        return name.split("m", 1)[1]  # -msemloc
    return None


def main() -> int:
    """Run the `semloc` command with the arguments of `sys.argv`."""
    hold_signals()
    from semloc.cli import main as command  # the heavy import, signals kept meanwhile

    return command(early=_EARLY)


if _spawned_by_multiprocessing():
    signal.signal(signal.SIGINT, signal.SIG_IGN)
