"""How a group of file operations is kept whole against SIGINT and SIGTERM.

`signals_held` blocks them (delivered when the block ends) around renames that must not be cut;
`interrupts_deferred` asks the CLI's handler (`semloc.cli`) to let a block finish before it
raises, without blocking anything (processes started inside still get their signals), and
`interrupts_wait` is what that handler asks.
"""

from __future__ import annotations

import signal
from collections.abc import Iterator
from contextlib import contextmanager

_DEFERRING = [0]  # blocks inside `interrupts_deferred` now (nested ones count)


@contextmanager
def interrupts_deferred() -> Iterator[None]:
    """Ask the command's interrupt handler (`semloc.cli`) to let the block finish before it
    raises.  Unlike `signals_held` nothing is blocked, so the processes started inside (they
    inherit the signal mask) still end on SIGINT and SIGTERM."""
    _DEFERRING[0] += 1
    try:
        yield
    finally:
        _DEFERRING[0] -= 1


def interrupts_wait() -> bool:
    """Whether an interrupt arriving now must wait (see `interrupts_deferred`)."""
    return _DEFERRING[0] > 0


@contextmanager
def signals_held() -> Iterator[None]:
    """Hold SIGINT and SIGTERM (delivered when the block ends), so that a group of renames is
    not cut in the middle by an interrupt."""
    held = {signal.SIGINT, signal.SIGTERM}
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, held)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)
