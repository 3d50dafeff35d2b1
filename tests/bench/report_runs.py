"""A made-up run for the report's tests: results.csv and run.json written
directly, so that every time and verdict is known."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd

from hikbench.bench.harness.columns import names

PROBLEMS = [f"equality/depth=2,n={n},rows=2/seed=0" for n in (4, 5, 6, 7, 8, 9, 10)]
UNSOLVED = PROBLEMS[6]  # no strict solver solves it
#: solver -> (strict, time of each problem (s), verified on each problem); None = declined
SOLVERS = {
    "fast": (True, [1e-5] * 7, [True] * 6 + [False]),
    "slow": (True, [np.nan] + [1e-4] * 6, [False] + [True] * 5 + [False]),
    "picky": (True, [5e-5] * 5 + [None, None], [True] * 5 + [None, None]),
    "wsum": (False, [2e-6] * 7, [False] * 7),
}


def make_row(problem, solver, strict, t, ok, mode="cold"):
    r = {c: None for c in names()}
    n = int(problem.split("n=")[1].split(",")[0])
    r.update(problem=problem, family="equality", params=json.dumps({"depth": 2, "n": n, "rows": 2}), seed=0,
             n=n, depth=2, rows=4, eq_rows=4, ineq_rows=0, solver=solver, settings="default", options="{}",
             strict=strict, mode=mode, repeat=3, host="h", calib_ns=2_000_000, level_norms="", ref_level_norms="")
    if t is None:
        return {**r, "status": "unsupported", "verified": False}
    r.update(status="optimal" if np.isfinite(t) else "timeout", verified=ok, time_median_s=t, time_min_s=t,
             time_p90_s=t, time_p99_s=t, time_max_s=t)
    if np.isfinite(t):
        r.update(level_norms=json.dumps([0.0, 0.5 if not strict else 0.2]), ref_level_norms=json.dumps([0.0, 0.2]))
    if not ok:
        r.update(verdict_level=1, verdict_side="worse")
    return r


def write_run(d, suite="quick", timeout=10.0):
    rows = [make_row(p, s, strict, t, ok) for s, (strict, ts, oks) in SOLVERS.items()
            for p, t, ok in zip(PROBLEMS, ts, oks)]
    d.mkdir(parents=True, exist_ok=True)
    pd.DataFrame(rows, columns=names()).to_csv(d / "results.csv", index=False)
    (d / "run.json").write_text(json.dumps({
        "suite": {"name": suite, "timeout": timeout}, "suite_rows": len(rows), "calibration_ns": 1_000_000,
        "sessions": [{"started": "2026-01-01T00:00:00+00:00", "finished": "2026-01-01T00:01:40+00:00",
                      "timeout": timeout}]}))
    return d


def markdown_table(md: str, title: str) -> tuple[list[str], list[list[str]]]:
    """The header cells and the rows' cells of the first Markdown table under the heading
    ``### TITLE...`` of report.md."""
    lines = md.splitlines()
    i = next(k for k, ln in enumerate(lines) if ln.startswith(f"### {title}"))
    head = [c.strip() for c in lines[i + 2].strip("|").split("|")]
    rows = []
    for ln in lines[i + 4:]:
        if not ln.startswith("|"):
            break
        rows.append([c.strip() for c in ln.strip("|").split("|")])
    return head, rows
