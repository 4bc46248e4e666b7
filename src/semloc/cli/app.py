"""The typer application every command module registers on, and the one-line error path.

`fail(message)` raises `CliError`; `semloc.cli.main` prints it as `semloc: error: ...` and
exits 2.  `choices(name, values)` builds a typer choice type from a registry, so that option
choices and help texts follow the registries (importers, descriptor kinds, methods, map kinds).
"""

from __future__ import annotations

from collections.abc import Iterable
from enum import StrEnum
from typing import Annotated, Any

import typer
from pydantic import ValidationError
from rich.console import Console
from typer.core import TyperArgument, TyperOption

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


def _flags_without_metavar() -> None:
    """typer (0.29) shows a type beside every option in `--help`, `<bool>` also beside a flag
    (`--help`, `--quick`, `--progress / --no-progress`), which takes no value: none there."""
    shown = TyperOption.display_type_rich

    def display_type_rich(self: TyperOption, ctx: object) -> str | None:
        return None if self.is_flag else shown(self, ctx)

    TyperOption.display_type_rich = display_type_rich  # type: ignore[method-assign]


_flags_without_metavar()


def _arguments_in_capitals() -> None:
    """One placeholder style: every argument is named in capitals in usage lines and messages
    (`{GLOBAL_MAP}`, `Missing argument 'OUT'`), whether or not it sets a metavar."""

    def display_name_raw(self: TyperArgument) -> str:
        return self.metavar or (self.name or "").upper()

    TyperArgument.display_name_raw = property(display_name_raw)  # type: ignore[method-assign,assignment]


_arguments_in_capitals()


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
    message = error["msg"]
    if error["type"] == "value_error" and "error" in error.get("ctx", {}):
        message = str(error["ctx"]["error"])  # a validator's own words, without "Value error, "
    return f"{where}: {message}" if where else message


EXIT_STATUSES = {
    0: "done",
    1: "nothing written: the answer is not localized",
    2: "bad input or usage, also an output that would overwrite an input or another output "
    "(nothing written), or a command group without its command (its help is printed)",
    130: "interrupted by Ctrl-C (143: by SIGTERM), no half-written output",
}
"""The exit statuses of the commands; 1 only where a command promises an output that needs
a localized answer (`update-map`)."""


def exit_statuses(done: str = EXIT_STATUSES[0], not_localized: bool = False) -> str:
    """The `--help` epilog that lists a command's exit statuses (`done`: what 0 means)."""
    meaning = {**EXIT_STATUSES, 0: done}
    codes = [code for code in meaning if not_localized or code != 1]
    return "Exit status: " + "; ".join(f"{code} {meaning[code]}" for code in codes) + "."


def document_exit_statuses(application: typer.Typer) -> None:
    """Give every registered command without an epilog of its own the list of exit statuses."""
    for info in application.registered_commands:
        if info.epilog is None:
            info.epilog = exit_statuses()


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


FOXGLOVE_HELP = "Stream the answers live to Foxglove on this port (8765 when given alone)."


def foxglove_option(help_text: str = FOXGLOVE_HELP) -> Any:
    """The `--foxglove [PORT]` option of the commands that stream to Foxglove."""
    return Annotated[
        int | None,
        typer.Option("--foxglove", min=0, max=65535, metavar="[PORT]", help=help_text),
    ]


OPTIONAL_VALUES = {"--foxglove": "8765"}
RENAMED = {"--out": "--output"}
"""Old option names still accepted (not shown in `--help`): `--out` of demo, bench,
train-descriptor and descriptors-eval is `-o/--output` now."""
"""Options whose value may be left out (`--foxglove` alone is `--foxglove 8765`): click needs
a value after an option that takes one, so the command line gets the default inserted."""


def with_optional_values(args: list[str]) -> list[str]:
    """`args` with the default value after each option of `OPTIONAL_VALUES` given alone (last,
    or followed by another option; a negative number is a value, which click then checks),
    and the old names of `RENAMED` under their new ones."""
    out: list[str] = []
    for i, arg in enumerate(args):
        name, equals, value = arg.partition("=")
        if name in RENAMED:
            arg = RENAMED[name] + equals + value
        out.append(arg)
        following = args[i + 1] if i + 1 < len(args) else None
        alone = following is None or (
            following.startswith("-") and not following[1:].replace(".", "", 1).isdigit()
        )
        if arg in OPTIONAL_VALUES and alone:
            out.append(OPTIONAL_VALUES[arg])
    return out
