"""Solvers that end their process (test doubles, injected as
``/path/crash_doubles.py:Name``)."""

from __future__ import annotations

import os
import sys

from doubles import SleepSolver


class AbortSolver(SleepSolver):
    """Calls abort(): the process dies with SIGABRT."""

    name = "abort"

    def solve(self, hierarchy):
        os.abort()


class ExitSolver(SleepSolver):
    """Calls sys.exit(3) from its solve."""

    name = "exit"

    def solve(self, hierarchy):
        sys.exit(3)


class ChattyExitSolver(SleepSolver):
    """Prints a line, then calls os._exit(0) without answering."""

    name = "chatty"

    def solve(self, hierarchy):
        print("about to vanish", flush=True)
        os._exit(0)
