"""The `semloc` command line (typer): one module per command group, errors as one line + exit 2.

`app.py` holds the typer app and `fail`; each command module registers its commands on it when
imported below; `render.py` prints Results, `files.py` reads settings / pose / result files,
`options.py` holds the options several commands share.  Every command runs inside `main()`,
which turns `MapError`, usage problems and `OSError`s into a single `semloc: error: ...` line on
stderr and exit status 2, so that bad input never ends in a traceback.
"""

from __future__ import annotations

import os
import re
import signal
import sys
import threading
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType

import numpy as np
import typer

from semloc.cli.app import CliError, app

# isort: off
# Importing a command module registers its commands; this order is the order of `--help`.
from semloc.cli import simulation, localize, update, align, datasets  # noqa: F401, E402
from semloc.cli import export, bag, bench, descriptors, config, warmup, serve  # noqa: F401, E402
from semloc.cli import ros2  # noqa: F401, E402

# isort: on
from semloc.cli.app import document_exit_statuses  # noqa: E402
from semloc.io.interrupts import interrupts_wait
from semloc.maps import MapError
from semloc.pictures.display import printable

document_exit_statuses(app)


class Interrupted(BaseException):
    """SIGINT or SIGTERM arrived; raised in the main thread by the handlers `main` installs."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum


def _raise_interrupted(signum: int, frame: FrameType | None) -> None:
    if _inside_numba(frame) or interrupts_wait():
        _Resend.later(signum)  # raised there it could crash or leave a half-built thing
        return
    raise Interrupted(signum)


def _inside_numba(frame: FrameType | None) -> bool:
    """Whether the signal landed in numba's or llvmlite's own Python code: compiling, loading
    compiled code, or turning a compiled function's results into Python objects (it unpickles
    their types there).  An exception raised in there is not cleaned up after (a returned
    tuple left half-built crashed the process), so the interrupt waits until they are done."""
    roots = tuple(
        os.path.dirname(module.__file__) + os.sep
        for module in map(sys.modules.get, ("numba", "llvmlite"))
        if module is not None and module.__file__
    )
    while frame is not None:
        if frame.f_code.co_filename.startswith(roots):
            return True
        frame = frame.f_back
    return False


class _Resend:
    """A signal held back, sent to the process again a moment later from a thread, but only
    while the handlers that raise `Interrupted` are installed: sent after the command, it would
    land in Python's shutdown (a KeyboardInterrupt traceback there)."""

    lock = threading.RLock()  # re-entrant: a second signal can land while the first is held
    armed = False
    pending: int | None = None

    @classmethod
    def later(cls, signum: int) -> None:
        with cls.lock:
            cls.pending = signum
        again = threading.Timer(0.01, cls._deliver)
        again.daemon = True
        again.start()

    @classmethod
    def _deliver(cls) -> None:
        with cls.lock:
            if cls.armed and cls.pending is not None:
                os.kill(os.getpid(), cls.pending)
            cls.pending = None

    @classmethod
    def arm(cls, armed: bool) -> None:
        """While armed, held signals are sent again; disarming drops one still held (the
        command is done: it keeps its status and its complete outputs)."""
        with cls.lock:
            cls.armed, cls.pending = armed, None


@contextmanager
def _interrupts_raise(script: bool) -> Iterator[None]:
    """SIGINT and SIGTERM raise `Interrupted` during the block (main thread only).

    Afterwards the previous handlers come back, except for the `script` (the process ends with
    the command): there a late signal is ignored, so that a finished command keeps its status."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    signals = (signal.SIGINT, signal.SIGTERM)
    previous = {s: signal.signal(s, _raise_interrupted) for s in signals}
    previous_hook = sys.unraisablehook
    sys.unraisablehook = _redeliver(previous_hook)
    _Resend.arm(True)
    try:
        yield
    finally:
        _Resend.arm(False)
        for signum, handler in previous.items():
            signal.signal(signum, signal.SIG_IGN if script else handler)
        sys.unraisablehook = previous_hook


def _redeliver(previous_hook):
    """An unraisable-exception hook that sends an `Interrupted` swallowed where exceptions
    cannot propagate (a weakref callback, `__del__`: Python would print "Exception ignored" and
    go on) to the process again, so the handler raises it where the command can stop.  It is
    sent a moment later from a thread: raised at once, it would land in the hook itself.  On a
    busy machine the one sent may still land in the hook (while it waits for the sending
    thread to start): swallowed there too, so it is sent once more."""

    def hook(unraisable) -> None:
        if not isinstance(unraisable.exc_value, Interrupted):
            previous_hook(unraisable)
            return
        signum = unraisable.exc_value.signum
        while True:
            try:
                _Resend.later(signum)
                return
            except Interrupted as again:
                signum = again.signum

    return hook


def main(argv: list[str] | None = None) -> int:
    """Entry point of the `semloc` script: runs the app and maps errors to exit status 2.

    Without `argv` (the script) the arguments come from `sys.argv` and the process is taken to
    end with the command; with `argv` (called from Python) signal handlers are restored.

    SIGINT (Ctrl-C) and SIGTERM end the command with `semloc: interrupted` and status 128 +
    the signal number (130, 143); outputs are then complete or absent (`semloc.io.write_files`,
    `staged_folder`).  Numerical warnings are not printed: results are checked to be finite.
    """
    try:
        with (
            _interrupts_raise(script=argv is None),
            warnings.catch_warnings(),
            np.errstate(all="ignore"),
        ):
            warnings.simplefilter("ignore", RuntimeWarning)
            code = app(args=argv, standalone_mode=False)
    except (MapError, CliError) as exc:
        return _error(str(exc))
    except OSError as exc:
        return _error(str(exc))
    except (Interrupted, KeyboardInterrupt) as exc:
        print("semloc: interrupted", file=sys.stderr)
        return 128 + (exc.signum if isinstance(exc, Interrupted) else signal.SIGINT)
    except SystemExit as exc:  # --help and typer.Exit pass through unchanged
        return exc.code if isinstance(exc.code, int) else 0 if exc.code is None else 1
    except typer.Abort:
        print("semloc: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:
        # click (vendored by typer) usage errors: one line, status 2 like click's own
        if hasattr(exc, "format_message") and hasattr(exc, "exit_code"):
            return _error(_usage_message(exc))
        cause = _interrupt_behind(exc)
        if cause is not None:  # e.g. an extension module's import turned it into ImportError
            print("semloc: interrupted", file=sys.stderr)
            return 128 + cause.signum
        raise
    if code == 130:  # typer turns a KeyboardInterrupt it sees into Exit(130)
        print("semloc: interrupted", file=sys.stderr)
    return code if isinstance(code, int) else 0


def _usage_message(exc: Exception) -> str:
    """click's message for a usage error, except for an option of several numbers given the
    wrong count or a non-number (`--center 1 2`): that says how many it needs."""
    message = exc.format_message()
    param, name = getattr(exc, "param", None), getattr(exc, "option_name", None)
    if param is not None and getattr(param, "nargs", 1) > 1 and param.opts:
        return f"Invalid value for '{param.opts[0]}': needs {param.nargs} numbers"
    count = re.fullmatch(r"Option '.*' requires (\d+) arguments\.", message)
    if name and count:  # too few values at the end of the command line
        return f"Invalid value for '{name}': needs {count.group(1)} numbers"
    return message


def _interrupt_behind(exc: BaseException) -> Interrupted | None:
    """The `Interrupted` that caused `exc` (through its cause / context chain), if any."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, Interrupted):
            return exc
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return None


def _error(message: str) -> int:
    """Print one line `semloc: error: ...` (shortened, printable) and return status 2."""
    line = " ".join(message.split())
    if len(line) > 600:
        line = line[:600] + "..."
    sys.stderr.write(f"semloc: error: {printable(line)}\n")
    return 2


if __name__ == "__main__":
    sys.exit(main())
