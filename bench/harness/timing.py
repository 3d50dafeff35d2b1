"""Timing of solve calls (docs/reports.md, "How times are measured").

``time.perf_counter_ns`` around the solve call only; warm-up runs discarded;
GC off while timing; BLAS threads limited to 1. Two modes:

* ``cold``: each repetition builds a fresh solver object (outside the timed
  region) and solves once;
* ``warm``: one solver object solves the problem once (discarded), then each
  repetition re-solves the same problem on it (warm start from its last
  active set).

How many repetitions: at least ``repeat``; with ``samples`` S > repeat, more
until the row has S samples or its k samples, counted at their median m_k,
add up to ``sample_time`` T (k m_k >= T), and at most ``WALL_FACTOR`` x T of
the loop's wall time (fresh solvers of cold mode included). A solve whose
median is under T / S (1 ms at the defaults S = 100, T = 0.1 s) gets S
samples: k m_k < k T / S < T for every k < S; a slower one about T / m
samples. The median, not the sum: a few pauses of the machine (5-9 ms
beside 0.8 ms solves on a loaded 2-core VM) would otherwise end a fast
row's sampling early.
The tail of a row is ``tail_columns``: p50 (the median), p90, p99, max and
min of its samples (numpy.percentile, linear interpolation: with fewer than
100 samples p99 lies between the two largest).
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

__all__ = ["MODES", "SAMPLES", "SAMPLE_TIME", "WALL_FACTOR", "Timing", "quiet_timing", "reported_result",
           "tail_columns", "time_solves"]

MODES = ("cold", "warm")
SAMPLES = 100       #: samples a suite asks for by default (one that sets no ``repeat``)
SAMPLE_TIME = 0.1   #: s of timed solves a row may spend to reach them
WALL_FACTOR = 10    #: the loop's wall time stops the extra samples at WALL_FACTOR x sample_time
#: results.csv's time columns: name -> percentile of the samples (numpy.percentile)
TAIL = {"time_median_s": 50, "time_p90_s": 90, "time_p99_s": 99, "time_max_s": 100, "time_min_s": 0}


@dataclass(frozen=True)
class Timing:
    """Timed repetitions of one (problem, solver, mode).

    Attributes
    ----------
    samples_ns : ndarray of int64, shape (repeats,)
        One wall-clock duration per repetition, nanoseconds (repeats >= ``repeat``
        of :func:`time_solves`).
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
    def max_s(self) -> float:
        return float(np.max(self.samples_ns)) * 1e-9


def tail_columns(samples_ns) -> dict[str, float]:
    """The time columns of a row from its samples (ns, shape (R,), R >= 1):
    ``time_median_s`` (p50), ``time_p90_s``, ``time_p99_s``, ``time_max_s``,
    ``time_min_s``, seconds; {} for no samples."""
    s = np.asarray(samples_ns, dtype=np.float64)
    if not s.size:
        return {}
    values = np.percentile(s, list(TAIL.values()))
    return {k: float(v) * 1e-9 for k, v in zip(TAIL, values)}


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
                mode: str = "cold", warmup: int = 1, samples: int | None = None,
                sample_time: float = SAMPLE_TIME) -> Timing:
    """Time at least ``repeat`` solves of ``h``, up to ``samples`` while k of
    them at their median add up to less than ``sample_time`` s (see the module
    docstring for the rule and the modes; ``samples`` None or <= repeat:
    exactly ``repeat``).

    ``warmup`` untimed solves come first (caches, branch predictors), after
    the collector's pass and the BLAS limit of :func:`quiet_timing`, which
    evict the solver's data: with none, the first sample of a cold IK-like
    n=20 hcod solve took 4.8x the median of the others, 1.5x after one
    warm-up solve, 1.1x after two (medians over 20 jobs of 5 samples)."""
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}; got {mode!r}")
    if repeat < 1:
        raise ValueError(f"repeat must be >= 1; got {repeat}")
    if not sample_time > 0:
        raise ValueError(f"sample_time must be > 0; got {sample_time}")
    most = max(repeat, samples or 0)
    budget_ns, wall_ns = int(sample_time * 1e9), int(WALL_FACTOR * sample_time * 1e9)
    buf = np.empty(most, dtype=np.int64)
    results = []
    clock = time.perf_counter_ns
    with quiet_timing():
        if mode == "cold":
            for _ in range(warmup):
                make_solver().solve(h)
        else:
            solver = make_solver()
            solver.solve(h)
            for _ in range(max(warmup - 1, 0)):
                solver.solve(h)
        start, i, top = clock(), 0, 0
        while i < repeat or (i < most and _below(buf, i, top, budget_ns) and clock() - start < wall_ns):
            if mode == "cold":
                solver = make_solver()
            t0 = clock()
            res = solver.solve(h)
            buf[i] = clock() - t0
            results.append(res)
            top = max(top, int(buf[i]))
            i += 1
    return Timing(buf[:i].copy(), reported_result([checked_result(r, h, solver) for r in results], h))


def _below(buf: np.ndarray, i: int, top: int, budget_ns: int) -> bool:
    """i m_i < budget for the median m_i of buf[:i] (i >= 1); the largest sample
    ``top`` answers first when it can (m_i <= top: no median to take)."""
    return i * top < budget_ns or i * np.median(buf[:i]) < budget_ns


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
