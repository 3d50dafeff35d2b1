"""Aggregates of runtimes: shifted geometric mean, Dolan-More profiles, and
the slope of a runtime against a size on log-log axes.

Shifted geometric mean (as in qpbenchmark, but with the shift in the metric's
own units, 10 us by default for solve times, not 10 s):

    sgm(t_1..t_P) = exp( mean_p log(t_p + shift) ) - shift           [s]

Verified failures are *charged*: a row whose x is not verified (wrong level
norms, no x, timeout, crash, error) counts with the run's job timeout in place
of its time (the penalty of Mittelmann's and qpbenchmark's benchmarks); a
problem the solver did not attempt, or declared ``unsupported`` (e.g. a
null-space recursion on inequalities), is left out (the report shows how many).
Non-strict solvers (weighted, damped) are judged against the strict optimum
too, so their aggregate mostly measures that they solve a different problem.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy import stats

__all__ = ["SHIFT_S", "charged_times", "loglog_fit", "performance_profile", "shifted_geometric_mean", "timed"]

SHIFT_S = 1e-5  #: 10 us


def shifted_geometric_mean(t, shift: float = SHIFT_S) -> float:
    """``exp(mean log(t + shift)) - shift`` of times ``t`` (s, finite, >= 0:
    a failure is charged its penalty by the caller, see :func:`charged_times`);
    NaN for no times. Anything else is a ValueError naming the first bad entry."""
    t = np.asarray(t, dtype=float).ravel()
    if t.size == 0:
        return float("nan")
    bad = np.flatnonzero(~(np.isfinite(t) & (t >= 0)))
    if bad.size or not shift > 0:
        what = f"time {bad[0]} is {float(t[bad[0]])!r}" if bad.size else f"shift is {shift!r}"
        raise ValueError(f"shifted geometric mean: {what}; expected finite times >= 0 and a shift > 0")
    return float(np.exp(np.mean(np.log(t + shift))) - shift)


def timed(df: pd.DataFrame, zero_ok: bool = False) -> pd.Series:
    """The rows whose time can be used (a boolean mask): verified, with a
    finite ``time_median_s`` > 0 (a log axis or fit), or >= 0 with ``zero_ok``."""
    t = df["time_median_s"].astype(float)
    return df["verified"].eq(True) & np.isfinite(t) & ((t >= 0) if zero_ok else (t > 0))


def charged_times(df: pd.DataFrame, penalty_s: float) -> pd.Series:
    """time_median_s where the row is :func:`timed` (zero allowed), ``penalty_s``
    elsewhere (a failure, or a bogus time)."""
    return df["time_median_s"].where(timed(df, zero_ok=True), penalty_s).astype(float)


def performance_profile(times: pd.DataFrame, points: int = 300) -> tuple[np.ndarray, dict] | None:
    """Dolan-More profile of ``times`` (problems x solvers; a time that is
    NaN, infinite or <= 0 is a failure). The ratios ``r_ps = t_ps / min_s
    t_ps`` over the problems some solver solved, on ``points`` log-spaced
    ``tau`` from 1 to max(10, twice the worst ratio). Returns (taus, {solver:
    fraction of all problems with r_ps <= tau, for each tau}); None when no
    solver solved anything."""
    t = times.astype(float)
    t = t.where(np.isfinite(t) & (t > 0), np.inf)
    best = t.min(axis=1)
    solved = np.isfinite(best)
    if not solved.any():
        return None
    ratio = t.div(best.where(solved), axis=0).to_numpy()  # (NaN on the problems nobody solved)
    worst = float(ratio[np.isfinite(ratio)].max())
    taus = np.logspace(0, np.log10(max(10.0, 2.0 * worst)), points)
    return taus, {s: np.array([(ratio[:, j] <= tau).mean() for tau in taus]) for j, s in enumerate(t.columns)}


def loglog_fit(x, y) -> tuple[float, float, int]:
    """Least-squares slope of ``log y`` vs ``log x`` (``scipy.stats.linregress``)
    over the points where both are finite and > 0 (no log of 0 or of a
    negative): (slope, its standard error, number of points). NaN slope and
    error with fewer than 3 distinct x: two sizes give a line through two
    points, no fitted slope."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    keep = np.isfinite(x) & np.isfinite(y) & (x > 0) & (y > 0)
    lx, ly = np.log(x[keep]), np.log(y[keep])
    if np.unique(lx).size < 3:
        return float("nan"), float("nan"), int(lx.size)
    res = stats.linregress(lx, ly)
    return float(res.slope), float(res.stderr), int(lx.size)
