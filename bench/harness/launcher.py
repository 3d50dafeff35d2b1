"""Run one external program, then end every process it started.

Usage (bench/harness/external.py)::

    python -I -S launcher.py STATUS TIMEOUT PARENT PROGRAM [ARGS...]

Starts PROGRAM in a session (and process group) of its own, waits at most
TIMEOUT seconds of wall time for it to exit, then kills every process it
left behind, whether it timed out or not: its process group, and on Linux
every descendant however it detached (``setsid``, a double fork). This
process is a child subreaper (``prctl(PR_SET_CHILD_SUBREAPER)``): the orphans
of PROGRAM are re-parented to it, not to init, and it kills and reaps its
children until none is left. Elsewhere than on Linux only the process group
is killed.

Writes the JSON object ``{"returncode": rc, "elapsed_ns": t, "timed_out": b}``
to STATUS (``rc`` negative: the signal that ended PROGRAM; ``t`` its wall
time from start to exit), or ``{"error": "..."}`` when PROGRAM cannot be
started. SIGTERM (sent by the harness past its own deadline, or on Linux when
PARENT dies: ``PR_SET_PDEATHSIG``) ends the wait early and still kills the
tree. Standard library only, and nothing of hikbench: it starts in a few ms.
"""

from __future__ import annotations

import json
import os
import select
import signal
import subprocess
import sys
import time

LINUX = sys.platform.startswith("linux")
_PR_SET_PDEATHSIG = 1
_PR_SET_CHILD_SUBREAPER = 36


class _Stop(Exception):
    """SIGTERM received: stop waiting, kill the tree."""


def _raise_stop(signum, frame):
    raise _Stop


def _prctl(option: int, value: int) -> None:
    """prctl(2) through libc; OSError naming the option when it fails."""
    import ctypes

    libc = ctypes.CDLL(None, use_errno=True)
    if libc.prctl(option, value, 0, 0, 0) != 0:
        raise OSError(ctypes.get_errno(), f"prctl({option}, {value}) failed")


def _children() -> list[int]:
    """Pids of this process's children (zombies included), from /proc."""
    me = os.getpid()
    listed = f"/proc/{me}/task/{me}/children"  # (this process has one thread)
    if os.path.exists(listed):
        with open(listed) as f:
            return [int(p) for p in f.read().split()]
    found = []
    for name in os.listdir("/proc"):
        if not name.isdigit():
            continue
        try:
            with open(f"/proc/{name}/stat", "rb") as f:
                stat = f.read()
        except OSError:  # the process ended while the listing was read: not a child any more
            continue
        if int(stat[stat.rindex(b")") + 2:].split()[1]) == me:  # "pid (comm) state ppid ..."
            found.append(int(name))
    return found


def _kill(pid: int, group: bool = False) -> None:
    """SIGKILL a process (or its group); nothing when it has already gone."""
    try:
        (os.killpg if group else os.kill)(pid, signal.SIGKILL)
    except ProcessLookupError:
        return  # already ended


def sweep(program_pid: int) -> None:
    """Kill PROGRAM's process group, then (Linux: as subreaper) kill and reap every
    child until none is left: a killed child's own children are re-parented here and
    killed on the next pass."""
    _kill(program_pid, group=True)
    if not LINUX:
        return
    while True:
        for pid in _children():
            _kill(pid)
        try:
            os.waitpid(-1, 0)
        except ChildProcessError:  # no child left
            return


def _wait(proc: subprocess.Popen, timeout: float) -> bool:
    """Wait at most ``timeout`` s for ``proc`` to exit (a pidfd where the kernel has
    them, else polling); True when it did not."""
    if hasattr(os, "pidfd_open"):
        try:
            fd = os.pidfd_open(proc.pid)
        except OSError:  # a kernel before 5.3: poll below
            fd = None
        if fd is not None:
            try:
                return not select.select([fd], [], [], max(timeout, 0.0))[0]
            finally:
                os.close(fd)
    try:
        proc.wait(timeout)
    except subprocess.TimeoutExpired:
        return True
    return False


def _contain(parent: int) -> None:
    """Linux: become the subreaper of everything started below, and get SIGTERM when
    ``parent`` (the harness) dies; exit at once if it is already gone."""
    if not LINUX:
        return
    _prctl(_PR_SET_CHILD_SUBREAPER, 1)
    _prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)
    if os.getppid() != parent:
        sys.exit(f"launcher: the harness (pid {parent}) ended before the program started")


def run(status: str, timeout: float, parent: int, argv: list[str]) -> None:
    """Run ``argv`` (see the module docstring) and write the STATUS file."""
    signal.signal(signal.SIGTERM, _raise_stop)
    _contain(parent)
    t0 = time.perf_counter_ns()
    try:
        proc = subprocess.Popen(argv, start_new_session=True)
    except OSError as err:
        with open(status, "w") as f:
            json.dump({"error": f"cannot run {argv[0]!r}: {err}"}, f)
        return
    timed_out = True  # (also when SIGTERM stops the wait)
    try:
        timed_out = _wait(proc, timeout)
        elapsed = time.perf_counter_ns() - t0
    except _Stop:
        elapsed = time.perf_counter_ns() - t0
    finally:
        signal.signal(signal.SIGTERM, signal.SIG_IGN)  # the sweep is not interrupted
        if timed_out:
            _kill(proc.pid, group=True)
        rc = proc.wait()
        sweep(proc.pid)
    with open(status, "w") as f:
        json.dump({"returncode": rc, "elapsed_ns": elapsed, "timed_out": timed_out}, f)


if __name__ == "__main__":
    run(sys.argv[1], float(sys.argv[2]), int(sys.argv[3]), sys.argv[4:])
