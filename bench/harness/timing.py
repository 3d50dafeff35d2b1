"""Timing of solve calls (docs/reports.md, "How times are measured").

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
from dataclasses import dataclass, replace

import numpy as np
from threadpoolctl import threadpool_limits

from hikbench.problems.hierarchy import Hierarchy
from hikbench.problems.verify import compare_lexicographic, level_norms, level_scales
from hikbench.solvers.base import OPTIMAL, Solver, SolveResult, checked_result

__all__ = ["MODES", "Timing", "quiet_timing", "reported_result", "time_solves"]

MODES = ("cold", "warm")


@dataclass(frozen=True)
class Timing:
    """Timed repetitions of one (problem, solver, mode).

    Attributes
    ----------
    samples_ns : ndarray of int64, shape (repeat,)
        One wall-clock duration per repetition, nanoseconds.
    result : SolveResult
        The result of the last timed repetition, unless an earlier one was worse
        (:func:`reported_result`): a non-optimal status beside the last's optimal,
        or an x lexicographically above the last's; then that repetition's, its
        reason saying so.
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
    results = [None] * repeat
    clock = time.perf_counter_ns
    with quiet_timing():
        if mode == "cold":
            for _ in range(warmup):
                make_solver().solve(h)
            for i in range(repeat):
                solver = make_solver()
                t0 = clock()
                results[i] = solver.solve(h)
                samples[i] = clock() - t0
        else:
            solver = make_solver()
            solver.solve(h)
            for _ in range(max(warmup - 1, 0)):
                solver.solve(h)
            for i in range(repeat):
                t0 = clock()
                results[i] = solver.solve(h)
                samples[i] = clock() - t0
    return Timing(samples, reported_result([checked_result(r, h, solver) for r in results], h))


def reported_result(results: list[SolveResult], h: Hierarchy, rtol: float = 1e-9) -> SolveResult:
    """The result a row reports for its timed repetitions ``results`` (in order).

    The last one, unless it is ``optimal`` and an earlier one is not (the first
    such), or an earlier x is lexicographically above the last's beyond ``rtol``
    at the last x's level scales (the highest such): a solver whose answer
    changes from one repetition to the next is judged on its worst, not on the
    last. The reported repetition's reason then names it and why."""
    last = results[-1]
    count = len(results)
    if last.status == OPTIMAL:
        for i, r in enumerate(results[:-1]):
            if r.status != OPTIMAL:
                return replace(r, reason=_joined(r.reason, f"repetition {i + 1} of {count} is reported: "
                                                           f"the last gave status {OPTIMAL}"))
    if last.x is None or not np.all(np.isfinite(last.x)):
        return last
    last_norms = level_norms(h, last.x)
    scales = level_scales(h, last.x)
    worst_i, worst_norms = count - 1, last_norms
    for i, r in enumerate(results[:-1]):
        if r.status != last.status or r.x is None or np.array_equal(r.x, last.x):
            continue
        norms = level_norms(h, r.x) if np.all(np.isfinite(r.x)) else np.full(h.depth, np.inf)
        if compare_lexicographic(norms, worst_norms, scales, rtol).lower == "b":
            worst_i, worst_norms = i, norms
    if worst_i == count - 1:
        return last
    v = compare_lexicographic(worst_norms, last_norms, scales, rtol)
    worst = results[worst_i]
    note = (f"repetition {worst_i + 1} of {count} is reported: its x is above the last's at level {v.level} "
            f"by {v.difference:.3g}")
    return replace(worst, reason=_joined(worst.reason, note))


def _joined(reason: str, note: str) -> str:
    return f"{reason}; {note}" if reason else note
