"""Every handling of SIGINT and SIGTERM in semloc: one module.

The command (`semloc.cli.main`) runs inside `interrupts_raise()`: the two signals raise
`Interrupted` in the main thread, which the command turns into `semloc: interrupted` and
status 128 + the signal number (130, 143).  An interrupt is not raised where it could break
something; it waits, and is sent to the process again a moment later:

- inside numba's or llvmlite's own Python code (compiling, loading compiled code, boxing a
  compiled function's results: an exception there left a tuple half-built, a crash; one cut
  in a compilation failed the next cache write with "no compiled object yet").  On the first
  use after an install, Ctrl-C therefore ends the command when the function being compiled
  is done (seconds, up to about twenty on 2 cores);
- inside `interrupts_deferred()`: a block that must not be cut (a Dask cluster starting or
  closing), where nothing is blocked at the OS level;
- inside `signals_held()`: renames of a group of files, the initialisation of an extension
  module (open3d); the two signals are also blocked for the calling thread.  Blocking alone
  is not enough: a signal sent to the process goes to a thread that does not block it (numba's
  and OpenBLAS's threads) and Python then runs the handler in the main thread all the same.

A signal that arrives while a block that waits raises an exception of its own (a Dask cluster
whose workers took the terminal's Ctrl-C and failed to start) makes the block raise
`Interrupted` instead: the interrupt, not its consequence, is what the user sees.

Worker processes that the command closes itself (Dask's) are started with SIGINT blocked
(`children_spared`) and ignore it once they run (`ignore_sigint`), so that a terminal's Ctrl-C,
which reaches the whole process group, prints nothing there.  The
one handler outside this module is the `semloc` script's (`semloc_entry`): it keeps the
signals that arrive while the command is still being imported (this package included) and
hands them to `interrupts_raise(early=...)`, so that Ctrl-C is honoured from the first moment;
in the worker processes started by `multiprocessing` (spawn), which import the script again
first, it ignores SIGINT from their first moment.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from types import FrameType

SIGNALS = (signal.SIGINT, signal.SIGTERM)
MESSAGE = "semloc: interrupted"
"""The one line an interrupted command prints on stderr."""


class Interrupted(BaseException):
    """SIGINT or SIGTERM arrived; raised in the main thread while `interrupts_raise` runs."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum

    @property
    def status(self) -> int:
        """The exit status of the interrupted command: 128 + the signal number."""
        return 128 + self.signum


class _State:
    """What the handler needs to know: how many blocks wait now (nested ones count), the
    signals that arrived while one did, and whether held signals may be sent again."""

    lock = threading.RLock()  # re-entrant: a second signal can land while the first is held
    waiting = 0
    arrived: list[int] = []
    armed = False
    pending: int | None = None


@contextmanager
def interrupts_deferred() -> Iterator[None]:
    """Let the block finish before an interrupt is raised (nothing is blocked: the processes
    started inside still end on SIGINT and SIGTERM).  If the block raises while a signal is
    waiting, it raises `Interrupted` from that exception."""
    with _State.lock:
        _State.waiting += 1
        if _State.waiting == 1:
            _State.arrived = []
    try:
        yield
    except Exception as exc:
        arrived = _arrived()
        if arrived is not None:
            raise Interrupted(arrived) from exc
        raise
    finally:
        with _State.lock:
            _State.waiting -= 1


def _arrived() -> int | None:
    with _State.lock:
        return _State.arrived[0] if _State.arrived else None


def interrupts_wait() -> bool:
    """Whether an interrupt arriving now must wait (see `interrupts_deferred`)."""
    return _State.waiting > 0


@contextmanager
def signals_held() -> Iterator[None]:
    """Hold SIGINT and SIGTERM until the block ends: blocked for this thread, and deferred by
    the command's handler (see the module docstring), so that a group of renames or an
    extension module's initialisation is not cut in the middle."""
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, set(SIGNALS))
    try:
        with interrupts_deferred():
            yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


@contextmanager
def children_spared() -> Iterator[None]:
    """Start worker threads and processes that the command closes itself (a Dask cluster)
    inside this block: SIGINT is blocked for the calling thread meanwhile, so the threads it
    starts and the processes they spawn inherit it blocked (a thread starts with its creator's
    signal mask, a process with its parent thread's, kept across exec) and a terminal's Ctrl-C,
    which reaches the whole process group, cannot cut a worker from its first instruction on
    (one cut while Python itself started printed a KeyboardInterrupt traceback).  This process
    still gets the signal: the block is deferred (`interrupts_deferred`), a SIGINT still
    pending when the mask comes back included.

    `multiprocessing`'s resource tracker is started first: the thread that starts it unblocks
    SIGINT afterwards (`resource_tracker.ensure_running`), and Dask's event-loop thread did so,
    so the worker processes it then started had SIGINT unblocked all the same."""
    from multiprocessing import resource_tracker

    with interrupts_deferred():
        resource_tracker.ensure_running()  # ignores SIGINT itself, from its first moment
        previous = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        try:
            yield
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, previous)


def ignore_sigint() -> None:
    """In a worker process that the command closes itself: SIGINT ignored, so that a
    terminal's Ctrl-C (sent to the whole process group) prints no traceback there."""
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)


def _raise_interrupted(signum: int, frame: FrameType | None) -> None:
    if _inside_numba(frame) or interrupts_wait():
        with _State.lock:
            if interrupts_wait():
                _State.arrived.append(signum)
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

    @staticmethod
    def later(signum: int) -> None:
        with _State.lock:
            _State.pending = signum
        again = threading.Timer(0.01, _Resend.deliver)
        again.daemon = True
        again.start()

    @staticmethod
    def deliver() -> None:
        with _State.lock:
            if _State.armed and _State.pending is not None:
                os.kill(os.getpid(), _State.pending)
            _State.pending = None

    @staticmethod
    def arm(armed: bool) -> None:
        """While armed, held signals are sent again; disarming drops one still held (the
        command is done: it keeps its status and its complete outputs)."""
        with _State.lock:
            _State.armed, _State.pending = armed, None


@contextmanager
def interrupts_raise(script: bool, early: list[int] | None = None) -> Iterator[None]:
    """SIGINT and SIGTERM raise `Interrupted` during the block (main thread only); a signal
    in `early` (kept by `early_hold` before the block) is raised at its start.

    Afterwards the previous handlers come back, except for the `script` (the process ends with
    the command): there a late signal is ignored, so that a finished command keeps its status."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {s: signal.signal(s, _raise_interrupted) for s in SIGNALS}
    previous_hook = sys.unraisablehook
    sys.unraisablehook = _redeliver(previous_hook)
    _Resend.arm(True)
    try:
        if early:
            raise Interrupted(early[0])
        yield
    finally:
        _Resend.arm(False)
        for signum, handler in previous.items():
            signal.signal(signum, signal.SIG_IGN if script else handler)
        sys.unraisablehook = previous_hook


def _redeliver(previous_hook: Callable) -> Callable:
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


def interrupt_behind(exc: BaseException | None) -> Interrupted | None:
    """The `Interrupted` that caused `exc` (through its cause / context chain), if any: e.g.
    an extension module's import that turned it into an ImportError."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, Interrupted):
            return exc
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return None
