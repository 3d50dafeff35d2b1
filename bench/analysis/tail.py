"""Tail latency per solver (report.md's "Tail latency", docs/reports.md).

Each row of results.csv carries the p50 (``time_median_s``), p90, p99 and max
of its timed repetitions (hikbench.bench.harness.timing.tail_columns). Per solver
and mode, :func:`tail_table` gives the median over the solver's rows of each
of them, the median over rows of p99 / p50 (how far a row's slow solves
stray from its typical one), and the worst solve of all its rows (max of the
row maxima, with its problem). Rows: the verified ones of a strict solver,
every row with a time of a non-strict one (their times are real times,
docs/reports.md "Non-strict solvers"). Each solver is over its own rows, as
in "Each solver on its own problems": the figures do not rank solvers.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from hikbench.bench.analysis.shgeom import timed

__all__ = ["PERCENTILES", "tail_table"]

#: report column -> results.csv column
PERCENTILES = {"p50": "time_median_s", "p90": "time_p90_s", "p99": "time_p99_s", "max": "time_max_s"}


def _rows(d: pd.DataFrame, strict: set[str]) -> pd.DataFrame:
    """The rows whose times count: verified for strict labels, any finite time >= 0 otherwise."""
    cols = d[list(PERCENTILES.values())].astype(float)
    finite = np.isfinite(cols).all(axis=1) & (cols >= 0).all(axis=1)
    strict_ok = d["label"].isin(strict) & timed(d, zero_ok=True)
    loose_ok = ~d["label"].isin(strict) & (d["status"] != "unsupported")
    return d[finite & (strict_ok | loose_ok)]


def tail_table(d: pd.DataFrame, strict: set[str]) -> list[dict]:
    """One dict per label of ``d`` (rows of one mode with a ``label`` column)
    that has rows with times, sorted by label: ``solver``, ``rows``,
    ``samples_per_row`` (median of ``repeat``), ``p50_s`` ... ``max_s``
    (medians over rows), ``p99_over_p50`` (median over rows), ``worst_s`` and
    ``worst_problem`` (the largest ``time_max_s``)."""
    r = _rows(d, strict)
    out = []
    for label, g in sorted(r.groupby("label"), key=lambda kv: kv[0]):
        p50 = g["time_median_s"].astype(float)
        ratio = (g["time_p99_s"].astype(float) / p50)[p50 > 0]
        worst = int(np.argmax(g["time_max_s"].astype(float).to_numpy()))
        out.append({"solver": label, "rows": len(g),
                    "samples_per_row": float(np.median(g["repeat"].astype(float))),
                    **{f"{k}_s": float(g[c].astype(float).median()) for k, c in PERCENTILES.items()},
                    "p99_over_p50": float(ratio.median()) if len(ratio) else float("nan"),
                    "worst_s": float(g["time_max_s"].astype(float).iloc[worst]),
                    "worst_problem": str(g["problem"].iloc[worst])})
    return out
