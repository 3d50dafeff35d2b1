"""Aggregates of runtimes: shifted geometric mean and Dolan-More profiles.

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

__all__ = ["shifted_geometric_mean", "charged_times", "performance_profile", "SHIFT_S"]

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


def charged_times(df: pd.DataFrame, penalty_s: float) -> pd.Series:
    """time_median_s where the row is verified and its time a finite number >= 0,
    ``penalty_s`` elsewhere (a failure, or a bogus time)."""
    t = df["time_median_s"]
    ok = df["verified"].eq(True) & np.isfinite(t) & (t >= 0)
    return df["time_median_s"].where(ok, penalty_s).astype(float)


def performance_profile(times: pd.DataFrame, taus: np.ndarray) -> dict:
    """Dolan-More profile. ``times``: problems x solvers, NaN / inf = failure.
    Returns {solver: fraction of problems with t_ps / min_s t_ps <= tau, for each tau}."""
    t = times.astype(float).replace(np.nan, np.inf)
    best = t.min(axis=1)
    ratio = t.div(best.where(np.isfinite(best)), axis=0)
    out = {}
    for s in t.columns:
        r = ratio[s].to_numpy()
        out[s] = np.array([(r <= tau).mean() if r.size else 0.0 for tau in taus])
    return out
