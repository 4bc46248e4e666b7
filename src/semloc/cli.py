"""The `semloc` command line (typer): one function per sub-command, errors as one line + exit 2.

Every command runs inside `main()`, which turns `MapError`, `UsageError`-like problems and
`OSError`s into a single `semloc: error: ...` line on stderr and exit status 2, so that bad
input never ends in a traceback.
"""

from __future__ import annotations

import io
import json
import sys
from enum import Enum
from pathlib import Path
from typing import Annotated

import numpy as np
import typer
from pydantic import ValidationError
from rich.console import Console
from rich.table import Table

from semloc.io import load_map, write_atomic
from semloc.localizer import LocalizerConfig, Result
from semloc.localizer import localize as run_localize
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


class OutputFormat(str, Enum):
    text = "text"
    json = "json"


@app.command()
def localize(
    global_map: Annotated[Path, typer.Argument(help="Global (prior) map, semloc JSON.")],
    local_map: Annotated[
        Path, typer.Argument(help="Local map of detected objects, semloc JSON; replayed by `seen`.")
    ],
    gamma: Annotated[float, typer.Option(help="Merge threshold on the distance ratio.")] = 0.8,
    delta: Annotated[float, typer.Option(help="Descriptor distance bound for candidates.")] = 0.5,
    top_k: Annotated[int, typer.Option(help="Number of distinct hypotheses to report.")] = 10,
    tolerance: Annotated[
        float, typer.Option(help="Slack (m) on distance differences for biased centres.")
    ] = LocalizerConfig().clustering.distance_tolerance,
    config: Annotated[
        Path | None, typer.Option(help="JSON file with LocalizerConfig fields (flat or nested).")
    ] = None,
    output_format: Annotated[
        OutputFormat, typer.Option("--format", help="Text (tables) or JSON.")
    ] = OutputFormat.text,
    output: Annotated[
        Path | None, typer.Option("--output", "-o", help="Write the output to this file.")
    ] = None,
) -> None:
    """Localize LOCAL in GLOBAL: association sets, hypotheses and the pose T_global_local."""
    settings = _read_config(config)
    settings.update(gamma=gamma, delta=delta, top_k=top_k, distance_tolerance=tolerance)
    try:
        cfg = LocalizerConfig(**settings)
    except ValidationError as exc:
        fail(f"invalid settings: {_first_error(exc)}")
    result = run_localize(load_map(global_map), load_map(local_map), cfg)
    if output_format is OutputFormat.json:
        text = json.dumps(result.to_dict(), indent=1) + "\n"
        if output is None:
            sys.stdout.write(text)
        else:
            write_atomic(output, text)
        return
    if output is None:
        print_result(result, console)
    else:
        recorder = Console(record=True, width=120, file=io.StringIO())
        print_result(result, recorder)
        write_atomic(output, recorder.export_text())


def _read_config(path: Path | None) -> dict:
    if path is None:
        return {}
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        fail(f"{path}: file not found")
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        fail(f"{path}: not valid JSON ({exc})")
    if not isinstance(data, dict):
        fail(f"{path}: must hold a JSON object of settings")
    return data


def _first_error(exc: ValidationError) -> str:
    error = exc.errors()[0]
    where = ".".join(str(p) for p in error["loc"])
    return f"{where}: {error['msg']}" if where else error["msg"]


def print_result(result: Result, out: Console) -> None:
    """Rich rendering of a Result: status line, pose, top hypotheses, timing."""
    colour = {"localized": "green", "ambiguous": "yellow", "failed": "red"}[result.status]
    out.print(f"status: [bold {colour}]{result.status}[/]")
    if result.pose is not None:
        out.print("pose T_global_local:")
        for row in result.pose:
            out.print("  " + "  ".join(f"{v:9.4f}" for v in row))
    table = Table(title="hypotheses (best first)")
    for column, width in (("rank", 4), ("score", 7), ("pairs", 5), ("fitness", 7),
                          ("yaw°", 6), ("t (m)", 17)):  # fmt: skip
        table.add_column(column, justify="right", no_wrap=True, min_width=width)
    table.add_column("associations local→global", no_wrap=True, overflow="ellipsis")
    for h in result.hypotheses:
        yaw = translation = "-"
        if h.pose is not None:
            yaw = f"{np.degrees(np.arctan2(h.pose[1, 0], h.pose[0, 0])):.1f}"
            translation = " ".join(f"{v:.2f}" for v in h.pose[:3, 3])
        shown = ", ".join(f"{l}→{g}" for g, l in h.pairs[:6]) + (" …" if len(h.pairs) > 6 else "")
        fitness = "-" if h.fitness is None else f"{h.fitness:.2f}"
        table.add_row(str(h.rank), f"{h.score:.2f}", str(len(h.pairs)), fitness, yaw,
                      translation, shown)  # fmt: skip
    if result.hypotheses:
        out.print(table)
    steps = len(result.steps)
    total = result.timing_ms.get("total", 0.0)
    out.print(f"{steps} update(s), {total:.1f} ms in all")


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
    except SystemExit as exc:  # --help and typer.Exit pass through unchanged
        return int(exc.code or 0)
    except typer.Abort:
        return 130
    except Exception as exc:
        # click (vendored by typer) usage errors: one line, status 2 like click's own
        if hasattr(exc, "format_message") and hasattr(exc, "exit_code"):
            print(f"semloc: error: {exc.format_message()}", file=sys.stderr)
            return 2
        raise
    return 0


if __name__ == "__main__":
    sys.exit(main())
