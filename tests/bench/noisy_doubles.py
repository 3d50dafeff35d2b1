"""Solvers that write to their file descriptors without end (test doubles,
injected as ``/path/noisy_doubles.py:Name``)."""

from __future__ import annotations

import os

from doubles import SleepSolver

FLOOD_BYTES = 48 << 20  # what FloodSolver writes to fd 1 in each solve


class FloodSolver(SleepSolver):
    """Correct, after writing FLOOD_BYTES of 'garbage' lines to fd 1, the first
    line 'FLOOD START' and the last 'FLOOD END'."""

    name = "flood"

    def solve(self, hierarchy):
        os.write(1, b"FLOOD START\n")
        block = b"garbage\n" * 8192
        for _ in range(FLOOD_BYTES // len(block)):
            os.write(1, block)
        os.write(1, b"FLOOD END\n")
        return super().solve(hierarchy)
