"""The `semloc` command line (typer): one function per sub-command, errors as one line + exit 2.

Every command runs inside `main()`, which turns `MapError`, `UsageError`-like problems and
`OSError`s into a single `semloc: error: ...` line on stderr and exit status 2, so that bad
input never ends in a traceback.
"""

from __future__ import annotations

import sys

import typer
from rich.console import Console

from semloc.maps import MapError

app = typer.Typer(
    name="semloc",
    help="Object-level relocalization: find where you are in a map of objects.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
console = Console()
err_console = Console(stderr=True)


class CliError(Exception):
    """A problem with the user's input that is reported as one line and exit status 2."""


def fail(message: str) -> None:
    """Report a bad-input problem and leave with status 2."""
    raise CliError(message)


@app.callback()
def _root() -> None:
    """semloc relocalizes a camera or robot against a prior map made of objects."""


# Commands are defined below this line (and registered by the modules that own them). -------


def main(argv: list[str] | None = None) -> int:
    """Entry point of the `semloc` script: runs the app and maps errors to exit status 2."""
    try:
        app(args=argv, standalone_mode=False)
    except (MapError, CliError) as exc:
        print(f"semloc: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"semloc: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("semloc: interrupted", file=sys.stderr)
        return 130
    except SystemExit as exc:  # typer's own exits (e.g. --help) pass through unchanged
        return int(exc.code or 0)
    except Exception as exc:  # click usage errors
        import click

        if isinstance(exc, click.exceptions.ClickException):
            print(f"semloc: error: {exc.format_message()}", file=sys.stderr)
            return 2
        if isinstance(exc, click.exceptions.Abort):
            return 130
        raise
    return 0


if __name__ == "__main__":
    sys.exit(main())
