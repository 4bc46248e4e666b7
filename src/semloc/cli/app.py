"""The typer application every command module registers on, and the one-line error path.

`fail(message)` raises `CliError`; `semloc.cli.main` prints it as `semloc: error: ...` and
exits 2.  `choices(name, values)` builds a typer choice type from a registry, so that option
choices and help texts follow the registries (importers, descriptor kinds, methods, map kinds).
"""

from __future__ import annotations

from collections.abc import Iterable
from enum import StrEnum
from typing import Annotated

import typer
from pydantic import ValidationError
from rich.console import Console

import semloc

app = typer.Typer(
    name="semloc",
    help="Object-level relocalization: find where you are in a map of objects.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
console = Console()
err_console = Console(stderr=True)


MAX_SEED = 2**32 - 1
"""Seeds are 0 ..= this (numpy's seeding takes no negative numbers)."""


class CliError(Exception):
    """A problem with the user's input that is reported as one line and exit status 2."""


def fail(message: str) -> None:
    """Report a bad-input problem and leave with status 2."""
    raise CliError(message)


def choices(name: str, values: Iterable[str]) -> type[StrEnum]:
    """A StrEnum over registry names (typer shows and checks them as choices)."""
    return StrEnum(name, {value: value for value in values})  # type: ignore[return-value]


def with_default(text: str, value: object) -> str:
    """Help text ending in `[default: value]`, for options whose None means "the config's"."""
    return f"{text} \\[default: {value}]"  # escaped: typer reads help as rich markup


def first_error(exc: ValidationError) -> str:
    """The first problem of a pydantic validation error, as `field: message`."""
    error = exc.errors()[0]
    where = ".".join(str(p) for p in error["loc"])
    return f"{where}: {error['msg']}" if where else error["msg"]


def _print_version(value: bool) -> None:
    if value:
        console.print(f"semloc {semloc.__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: Annotated[
        bool,
        typer.Option(
            "--version", callback=_print_version, is_eager=True, help="Print the version and exit."
        ),
    ] = False,
) -> None:
    """semloc relocalizes a camera or robot against a prior map made of objects."""
