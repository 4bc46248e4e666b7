"""The `semloc` command line (typer): one module per command group, errors as one line + exit 2.

`app.py` holds the typer app and `fail`; each command module registers its commands on it when
imported below; `render.py` prints Results, `files.py` reads settings / pose / result files,
`options.py` holds the options several commands share.  Every command runs inside `main()`,
which turns `MapError`, usage problems and `OSError`s into a single `semloc: error: ...` line on
stderr and exit status 2, so that bad input never ends in a traceback.
"""

from __future__ import annotations

import io
import os
import re
import signal
import sys
import warnings
from collections.abc import Iterator
from contextlib import contextmanager, suppress

import numpy as np
import typer

from semloc.cli.app import CliError, app, with_optional_values

# isort: off
# Importing a command module registers its commands; this order is the order of `--help`.
from semloc.cli import simulation, localize, update, align, datasets  # noqa: F401, E402
from semloc.cli import export, bag, bench, descriptors, config, warmup, serve, maps  # noqa: F401, E402
from semloc.cli import ros2, tokens, sessions  # noqa: F401, E402

# isort: on
from semloc.cli.app import document_exit_statuses  # noqa: E402
from semloc.io.interrupts import MESSAGE, Interrupted, interrupt_behind, interrupts_raise
from semloc.maps import MapError
from semloc.pictures.display import printable

document_exit_statuses(app)


def main(argv: list[str] | None = None, early: list[int] | None = None) -> int:
    """Entry point of the `semloc` command: runs the app and maps errors to exit status 2.

    Without `argv` (the script) the arguments come from `sys.argv` and the process is taken to
    end with the command; with `argv` (called from Python) signal handlers are restored.
    `early`: signals that arrived while the script imported the command (`semloc_entry`).

    SIGINT (Ctrl-C) and SIGTERM end the command with `semloc: interrupted` and status 128 +
    the signal number (130, 143); outputs are then complete or absent (`semloc.io.write_files`,
    `staged_folder`), see `semloc.io.interrupts`.  Numerical warnings are not printed: results
    are checked to be finite.
    """
    try:
        with (
            interrupts_raise(script=argv is None, early=early),
            quiet_when_stdout_closes(),
            warnings.catch_warnings(),
            np.errstate(all="ignore"),
        ):
            warnings.simplefilter("ignore", RuntimeWarning)
            args = with_optional_values(sys.argv[1:] if argv is None else list(argv))
            code = app(args=args, standalone_mode=False)
    except (MapError, CliError) as exc:
        return _error(str(exc))
    except OSError as exc:
        return _interrupted(exc) or _error(str(exc))
    except (Interrupted, KeyboardInterrupt, typer.Abort) as exc:
        return _interrupted(exc) or _interrupted(Interrupted(signal.SIGINT))
    except SystemExit as exc:  # --help and typer.Exit pass through unchanged
        return exc.code if isinstance(exc.code, int) else 0 if exc.code is None else 1
    except Exception as exc:
        if type(exc).__name__ == "NoArgsIsHelpError":  # a group without its command: help shown
            return _error(f"a command is needed: {_command_path(exc)} COMMAND (listed above)")
        # click (vendored by typer) usage errors: one line, status 2 like click's own
        if hasattr(exc, "format_message") and hasattr(exc, "exit_code"):
            return _error(_usage_message(exc))
        status = _interrupted(exc)  # e.g. an extension module's import turned it into another
        if status:
            return status
        raise
    if code == 130:  # typer turns a KeyboardInterrupt it sees into Exit(130)
        print(MESSAGE, file=sys.stderr)
    return code if isinstance(code, int) else 0


class _QuietStdout(io.RawIOBase):
    """File descriptor 1 that takes every write, also once its reader went away (`| head -1`):
    from then on what is written is dropped, so the command finishes its work."""

    def __init__(self) -> None:
        super().__init__()
        self.closed_reader = False

    def writable(self) -> bool:
        return True

    def fileno(self) -> int:
        return 1

    def isatty(self) -> bool:
        return os.isatty(1)

    def write(self, data) -> int:  # type: ignore[override]
        if not self.closed_reader:
            try:
                return os.write(1, data)
            except BrokenPipeError:
                self.closed_reader = True
        return len(data)


@contextmanager
def quiet_when_stdout_closes() -> Iterator[None]:
    """While the command runs, a standard output whose reader closed it (`semloc ... | head -1`)
    is not an error: the rest of the output is dropped, the command ends as it would have, with
    its own exit status and no word about it.  Only for the process's own stdout (not one a
    caller such as pytest put in its place)."""
    real = sys.stdout
    if real is None or real is not sys.__stdout__ or not _is_fd(real, 1):
        yield
        return
    with suppress(BrokenPipeError):
        real.flush()
    quiet = io.TextIOWrapper(io.BufferedWriter(_QuietStdout()), encoding=real.encoding,
                             errors=real.errors, line_buffering=real.line_buffering)  # fmt: skip
    sys.stdout = quiet
    try:
        yield
    finally:
        quiet.flush()
        sys.stdout = real


def _command_path(exc: Exception) -> str:
    """`semloc ros2` for an error in that group (whatever the program was called)."""
    names, ctx = [], getattr(exc, "ctx", None)
    while ctx is not None and ctx.parent is not None:
        names.append(ctx.info_name)
        ctx = ctx.parent
    return " ".join(["semloc", *reversed(names)])


def _is_fd(stream: object, fd: int) -> bool:
    try:
        return stream.fileno() == fd  # type: ignore[attr-defined]
    except (AttributeError, OSError, ValueError):
        return False


def _interrupted(exc: BaseException) -> int:
    """For an exception an interrupt caused: print the one line and return the exit status;
    else 0."""
    cause = interrupt_behind(exc)
    if cause is None:
        return 0
    print(MESSAGE, file=sys.stderr)
    return cause.status


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


def _error(message: str) -> int:
    """Print one line `semloc: error: ...` (shortened, printable) and return status 2."""
    line = " ".join(message.split())
    if len(line) > 600:
        line = line[:600] + "..."
    sys.stderr.write(f"semloc: error: {printable(line)}\n")
    return 2


if __name__ == "__main__":
    sys.exit(main())
