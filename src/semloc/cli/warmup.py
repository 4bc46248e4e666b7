"""`semloc warmup`: compile (after an install) or load the inner loops ahead of use."""

from __future__ import annotations

from semloc.cli.app import app, console, err_console
from semloc.compiling import warmup as run_warmup


@app.command()
def warmup() -> None:
    """Compile the inner loops now (once after installing or upgrading; later: a quick load).

    Run it where semloc is installed, e.g. in a Dockerfile, so that the first localization
    starts at once; the compiled code is cached beside the sources (or in NUMBA_CACHE_DIR).
    """
    done = run_warmup(lambda text: err_console.print(f"{text}…", style="dim"))
    console.print(f"ready: {done.describe()}")
