"""Aggregates of runtimes: shifted geometric mean, the ranking's relative
time, Dolan-More profiles, and the slope of a runtime against a size on
log-log axes.

Shifted geometric mean (as in qpbenchmark, but with the shift in the metric's
own units, 10 us by default for solve times, not 10 s):

    sgm(t_1..t_P) = exp( mean_p log(t_p + shift) ) - shift           [s]

The ranking's relative time (docs/reports.md, "Ranking"): over one set of
problems P and solvers S, a success's time is its median time; a failure (a
row not verified) is *charged* FAILURE_FACTOR times the slowest success on
that problem, whatever the job timeout; a problem no solver succeeded on is
left out (and counted). With b_p the fastest success on p,

    score_s = exp( mean_p log( (t_ps + shift) / (b_p + shift) ) )

the shifted geometric mean of the per-problem ratios to the fastest, and the
relative time is score_s / min_s' score_s' (1.0 = the fastest solver).
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy import stats

__all__ = ["FAILURE_FACTOR", "SHIFT_S", "charge_failures", "loglog_fit", "performance_profile", "relative_time",
           "shifted_geometric_mean", "timed"]

SHIFT_S = 1e-5  #: 10 us
FAILURE_FACTOR = 10.0  #: a failure is charged this many times the slowest success on its problem


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


def charge_failures(t: pd.DataFrame, factor: float = FAILURE_FACTOR) -> tuple[pd.DataFrame, list]:
    """``t``: problems x solvers, the time of each success and NaN for each
    failure. Returns (the problems some solver succeeded on, with every
    failure charged ``factor`` x the slowest success on its problem; the
    problems no solver succeeded on, left out)."""
    solved = t.notna().any(axis=1)
    charge = t.max(axis=1) * factor
    charged = t[solved].apply(lambda col: col.fillna(charge[solved]))
    return charged.astype(float), sorted(t.index[~solved])


def relative_time(charged: pd.DataFrame, shift: float = SHIFT_S) -> pd.Series:
    """Per solver (column of ``charged``, problems x solvers with no NaN), the
    shifted geometric mean of its ratios to the fastest on each problem,
    divided by the lowest of them: 1.0 is the fastest solver (module docstring)."""
    if charged.empty:
        return pd.Series(np.nan, index=charged.columns)
    ratio = (charged + shift).div(charged.min(axis=1) + shift, axis=0)
    score = np.exp(np.log(ratio).mean(axis=0))
    return score / score.min()


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
