"""Timing of solve calls (DESIGN.md, "Performance ground rules").

``time.perf_counter_ns`` around the solve call only; warm-up runs discarded;
GC off while timing; BLAS threads limited to 1. Two modes:

* ``cold``: each repetition builds a fresh solver object (outside the timed
  region) and solves once;
* ``warm``: one solver object solves the problem once (discarded), then each
  repetition re-solves the same problem on it (warm start from its last
  active set).
"""

from __future__ import annotations

import gc
import time
from collections.abc import Callable
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np
from threadpoolctl import threadpool_limits

from problems.hierarchy import Hierarchy
from solvers.base import Solver, SolveResult, checked_result

__all__ = ["MODES", "Timing", "quiet_timing", "time_solves"]

MODES = ("cold", "warm")


@dataclass(frozen=True)
class Timing:
    """Timed repetitions of one (problem, solver, mode).

    Attributes
    ----------
    samples_ns : ndarray of int64, shape (repeat,)
        One wall-clock duration per repetition, nanoseconds.
    result : SolveResult
        The result of the last timed repetition.
    """

    samples_ns: np.ndarray
    result: SolveResult

    @property
    def median_s(self) -> float:
        return float(np.median(self.samples_ns)) * 1e-9

    @property
    def min_s(self) -> float:
        return float(np.min(self.samples_ns)) * 1e-9

    @property
    def p95_s(self) -> float:
        return float(np.percentile(self.samples_ns, 95)) * 1e-9


@contextmanager
def quiet_timing():
    """BLAS threads = 1 and GC off for the duration."""
    was_enabled = gc.isenabled()
    with threadpool_limits(limits=1):
        gc.collect()
        gc.disable()
        try:
            yield
        finally:
            if was_enabled:
                gc.enable()


def time_solves(make_solver: Callable[[], Solver], h: Hierarchy, repeat: int = 1,
                mode: str = "cold", warmup: int = 1) -> Timing:
    """Time ``repeat`` solves of ``h`` (see the module docstring for modes).

    ``warmup`` untimed solves come first (caches, branch predictors), after
    the collector's pass and the BLAS limit of :func:`quiet_timing`, which
    evict the solver's data: with none, the first sample of a cold IK-like
    n=20 hcod solve took 4.8x the median of the others, 1.5x after one
    warm-up solve, 1.1x after two (medians over 20 jobs of 5 samples)."""
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}; got {mode!r}")
    if repeat < 1:
        raise ValueError(f"repeat must be >= 1; got {repeat}")
    samples = np.empty(repeat, dtype=np.int64)
    clock = time.perf_counter_ns
    with quiet_timing():
        if mode == "cold":
            for _ in range(warmup):
                make_solver().solve(h)
            for i in range(repeat):
                solver = make_solver()
                t0 = clock()
                result = solver.solve(h)
                samples[i] = clock() - t0
        else:
            solver = make_solver()
            solver.solve(h)
            for _ in range(max(warmup - 1, 0)):
                solver.solve(h)
            for i in range(repeat):
                t0 = clock()
                result = solver.solve(h)
                samples[i] = clock() - t0
    return Timing(samples, checked_result(result, h, solver))
