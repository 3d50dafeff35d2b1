"""Solvers that break the harness's assumptions rather than the solve contract (test
doubles, injected as ``/path/fault_doubles.py:Name``)."""

from __future__ import annotations

import fcntl
import os
import stat

from doubles import SleepSolver

from hikbench.solvers.base import SolveResult


class NeedsArgSolver(SleepSolver):
    """Its constructor needs ``alpha``, which no suite option gives."""

    name = "needs-arg"

    def __init__(self, alpha: float, delay: float = 0.0):
        super().__init__(delay)
        self.alpha = alpha


class UnpicklableResultSolver(SleepSolver):
    """Correct x, with a reason the pickle module cannot send (a lambda)."""

    name = "unpicklable"

    def solve(self, hierarchy):
        res = super().solve(hierarchy)
        return SolveResult(res.x, res.status, reason=lambda: "a closure")


def _writable_pipes() -> list[int]:
    """The file descriptors above 2 of this process that are pipes open for writing."""
    fds = []
    for name in os.listdir("/proc/self/fd"):
        fd = int(name)
        try:
            if fd > 2 and stat.S_ISFIFO(os.fstat(fd).st_mode) and \
                    fcntl.fcntl(fd, fcntl.F_GETFL) & os.O_ACCMODE == os.O_WRONLY:
                fds.append(fd)
        except OSError:  # (the listing's own descriptor, closed by now)
            continue
    return fds


class ChannelWriterSolver(SleepSolver):
    """Writes ``garbage`` (a header announcing 2**64 - 1 bytes by default) into every
    pipe it can write (the job channel among them) before a correct solve."""

    name = "channel-writer"

    def __init__(self, garbage: str = "ff" * 8, times: int = 1, delay: float = 0.0):
        super().__init__(delay)
        self.garbage, self.times = bytes.fromhex(garbage), int(times)

    def solve(self, hierarchy):
        for fd in _writable_pipes():
            for _ in range(self.times):
                os.write(fd, self.garbage)
        return super().solve(hierarchy)
