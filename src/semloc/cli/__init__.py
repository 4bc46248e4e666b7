"""The `semloc` command line (typer): one module per command group, errors as one line + exit 2.

`app.py` holds the typer app and `fail`; each command module registers its commands on it when
imported below; `render.py` prints Results, `files.py` reads settings / pose / result files,
`options.py` holds the options several commands share.  Every command runs inside `main()`,
which turns `MapError`, usage problems and `OSError`s into a single `semloc: error: ...` line on
stderr and exit status 2, so that bad input never ends in a traceback.
"""

from __future__ import annotations

import sys

import typer

from semloc.cli.app import CliError, app

# isort: off
# Importing a command module registers its commands; this order is the order of `--help`.
from semloc.cli import simulation, localize, datasets, export, bench, descriptors, config  # noqa: F401, E402

# isort: on
from semloc.maps import MapError


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
