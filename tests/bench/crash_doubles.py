"""Solvers that end their process (test doubles, injected as
``/path/crash_doubles.py:Name``)."""

from __future__ import annotations

import os
import sys
import time

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


class HangAfterFirstSolver(SleepSolver):
    """Answers its first solve in a process, then never returns."""

    name = "hang-after-first"
    solves = 0

    def solve(self, hierarchy):
        HangAfterFirstSolver.solves += 1
        while HangAfterFirstSolver.solves > 1:
            time.sleep(0.05)
        return super().solve(hierarchy)
