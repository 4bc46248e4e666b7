"""Ctrl-C at given moments of `semloc demo`, `bench --quick` and `serve`, many times: how often
the command ends as promised (exit status 130, the one line `semloc: interrupted` on stderr
besides the command's own notices, no traceback, no output folder half-written, no process of
it left), and how long it took to end after the signal.

The signal goes to the command's whole process group, as a terminal's Ctrl-C does; the command
is started as the `semloc` script that pip installs (`semloc_entry:main`).

    PYTHONPATH=src python benchmarks/interrupts.py --runs 20 --at 0.5 1 2 3 10
    PYTHONPATH=src python benchmarks/interrupts.py --commands serve --runs 4 --at 1 3
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

SCRIPT = """import re
import sys
from semloc_entry import main
if __name__ == "__main__":
    sys.argv[0] = re.sub(r"(-script\\.pyw|\\.exe)?$", "", sys.argv[0])
    sys.exit(main())
"""
COMMANDS = {
    "demo": ["demo", "--out", "out"],
    "bench": ["bench", "--quick", "--out", "out", "--no-progress"],
    "serve": ["serve", "--data", "out", "--port", "0"],
    "serve-workers": ["serve", "--data", "out", "--port", "0", "--workers", "2"],
}
NOTICES = ("compiling semloc's inner loops", "more); later runs", "semloc serve: listening on")


def one_run(script: Path, argv: list[str], at: float, folder: Path) -> tuple[bool, str, float]:
    """(as promised, what went wrong, seconds from the signal to the end); a command that
    finished its job before the signal counts as promised."""
    shutil.rmtree(folder / "out", ignore_errors=True)
    proc = subprocess.Popen([sys.executable, str(script), *argv], cwd=folder, text=True,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            start_new_session=True)  # fmt: skip
    time.sleep(at)
    if proc.poll() is not None:  # finished first: fine when it did its whole job
        done = proc.returncode == 0
        return done, "" if done else f"ended first with status {proc.returncode}", 0.0
    sent = time.monotonic()
    os.killpg(proc.pid, signal.SIGINT)
    _, err = proc.communicate(timeout=600)
    took = time.monotonic() - sent
    lines = [line for line in err.splitlines() if line.strip() and not line.startswith(NOTICES)]
    left = _group_left(proc.pid)
    if proc.returncode == 0 and not left and argv[0] != "serve" and _complete(folder / "out"):
        return True, "", took  # it finished as the signal came: whole outputs, status 0
    if proc.returncode != 130:
        return False, f"status {proc.returncode}: {lines[-1:]}", took
    if lines != ["semloc: interrupted"]:
        return False, f"stderr: {lines[:2]} ... ({len(lines)} lines)", took
    if left:
        return False, "processes left", took
    if argv[0] != "serve" and (folder / "out").exists() and not _complete(folder / "out"):
        return False, "a half-written output folder", took
    return True, "", took


def _complete(out: Path) -> bool:
    return (out / "report.md").exists() or (out / "result.json").exists()


def _group_left(group: int) -> bool:
    deadline = time.monotonic() + 15
    while time.monotonic() < deadline:
        try:
            os.killpg(group, 0)
        except ProcessLookupError:
            return False
        time.sleep(0.1)
    os.killpg(group, signal.SIGKILL)
    return True


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--commands", nargs="+", default=list(COMMANDS), choices=list(COMMANDS))
    parser.add_argument("--at", nargs="+", type=float, default=[0.5, 1, 2, 3, 10])
    parser.add_argument("--runs", type=int, default=20, help="Runs per command and moment.")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        script = folder / "semloc"
        script.write_text(SCRIPT)
        print("| command | Ctrl-C at s | as promised | ends after the signal, s (max) | problems |")
        print("|---|---|---|---|---|")
        for name in args.commands:
            for at in args.at:
                results = [one_run(script, COMMANDS[name], at, folder) for _ in range(args.runs)]
                good = sum(ok for ok, _, _ in results)
                problems = sorted({why for ok, why, _ in results if not ok})
                slowest = max(took for _, _, took in results)
                print(f"| {name} | {at:g} | {good} / {args.runs} | {slowest:.1f} | "
                      f"{'; '.join(problems)[:200]} |", flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
