"""Signals around a command: SIGTERM as Ctrl-C for the command (``hikbench.bench.cli``),
and the kernel's default action around in-process solver calls (``hikbench scenario``).
Its own module so that a command needs no import of the CLI that loads it."""

from __future__ import annotations

import contextlib
import signal
import threading

__all__ = ["Terminated", "sigterm_as_interrupt", "solver_calls_killable"]


class Terminated(KeyboardInterrupt):
    """SIGTERM received (``kill``, a CI job's time limit): unwinds like Ctrl-C."""


@contextlib.contextmanager
def sigterm_as_interrupt():
    """SIGTERM raises :class:`Terminated` in the main thread, so that the command
    stops as on Ctrl-C: rows written so far kept, a Dask cluster closed (killed
    at once, Python left its semaphores to the resource tracker's warning).
    Elsewhere than in the main thread (where no handler can be set) nothing changes."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def raise_terminated(signum, frame):
        raise Terminated()

    previous = signal.signal(signal.SIGTERM, raise_terminated)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


@contextlib.contextmanager
def solver_calls_killable():
    """SIGTERM and SIGINT take the kernel's default action (end the process)
    inside the block: around a command's in-process solver calls (``scenario``).
    Python runs its own handlers only between bytecodes, so a backend looping in
    C or numba code, which never returns to the interpreter, could not be
    stopped by ``kill`` or Ctrl-C. ``run`` and ``solve`` do not need it: their
    solves run in the isolated worker. A signal ignored by the parent (``nohup``, a background job) stays
    ignored. Elsewhere than in the main thread nothing changes."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {sig: signal.signal(sig, signal.SIG_DFL) for sig in (signal.SIGTERM, signal.SIGINT)
                if signal.getsignal(sig) is not signal.SIG_IGN}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
