"""OUT/summary.json: the run in a few numbers (docs/reports.md, "summary.json"),
written by ``hikbench run`` at the end of each run and read back by the
report for its one-line summary.

Keys: ``rows``, ``solvers`` (their names, ``[settings]`` variants apart),
``problems``, ``modes``, ``verified`` (rows with ``verified`` True),
``not_verified`` (rows attempted and not verified: False, or no yardstick),
``unsupported`` (rows a solver declined), ``statuses`` ({status: rows}),
``strict`` and ``non_strict`` (the same three counts for the rows of each
kind of solver), ``yardstick`` ({kind: {"problems": P, "rows": R}} for the
kinds ``certified``, ``reference-only``, ``none`` of results.csv's
``yardstick`` column: rows are verified only against a certified one), ``sessions`` and ``wall_time_s`` (the sum over the run's
sessions of finished - started, from run.json; None while one is unfinished),
``scenarios`` (the rows of OUT/scenarios.csv: ``runs``, ``finished`` (runs that
ended in the worker), ``all_checks_passed`` (finished runs none of whose checks
failed), ``statuses`` ({status: runs}); zeros for a suite without scenarios).
"""

from __future__ import annotations

import json
from datetime import datetime
from pathlib import Path

import pandas as pd

from hikbench.bench.harness.environment import read_run_json
from hikbench.bench.harness.results import read_results

__all__ = ["SUMMARY_FILE", "run_summary", "scenario_counts", "summary_line", "write_summary", "yardstick_counts"]

SUMMARY_FILE = "summary.json"


def _counts(df: pd.DataFrame) -> dict:
    """verified / not_verified / unsupported rows of ``df``."""
    declined = df["status"].eq("unsupported")
    ok = df["verified"].eq(True)
    return {"verified": int(ok.sum()), "not_verified": int((~ok & ~declined).sum()),
            "unsupported": int(declined.sum())}


def yardstick_counts(df: pd.DataFrame) -> dict:
    """{kind: {"problems": P, "rows": R}} of the ``yardstick`` column, every kind listed ({} for
    a results.csv without the column)."""
    if "yardstick" not in df.columns:
        return {}
    kinds = df["yardstick"].astype(object).fillna("none")  # (all empty: read as float NaN)
    return {k: {"problems": int(df.loc[kinds == k, "problem"].nunique()), "rows": int((kinds == k).sum())}
            for k in ("certified", "reference-only", "none")}


def wall_time_s(meta: dict) -> float | None:
    """Sum over run.json's sessions of finished - started, s; None when a session has no end."""
    total = 0.0
    for s in meta.get("sessions") or []:
        if not (s.get("started") and s.get("finished")):
            return None
        total += (datetime.fromisoformat(s["finished"]) - datetime.fromisoformat(s["started"])).total_seconds()
    return total


def scenario_counts(sc: pd.DataFrame) -> dict:
    """``runs``, ``finished``, ``all_checks_passed`` and ``statuses`` of OUT/scenarios.csv's rows ``sc``."""
    from hikbench.bench.scenarios.rows import FINISHED

    done = sc["status"].eq(FINISHED)
    return {"runs": len(sc), "finished": int(done.sum()),
            "all_checks_passed": int((done & pd.to_numeric(sc["checks_failed"]).eq(0)).sum()),
            "statuses": {str(k): int(v) for k, v in sorted(sc["status"].value_counts().items())}}


def run_summary(df: pd.DataFrame, meta: dict, scenarios: pd.DataFrame) -> dict:
    """The summary of the rows ``df`` (results.csv), run.json ``meta`` and the rows
    ``scenarios`` of OUT/scenarios.csv (hikbench.bench.scenarios.rows.read_scenario_rows)."""
    labels = df["solver"].where(df["settings"] == "default", df["solver"] + " [" + df["settings"] + "]")
    strict = df["strict"].astype(str).eq("True")
    return {"suite": (meta.get("suite") or {}).get("name"), "rows": len(df),
            "solvers": sorted(labels.unique()), "problems": int(df["problem"].nunique()),
            "modes": sorted(df["mode"].unique()), **_counts(df),
            "statuses": {k: int(v) for k, v in sorted(df["status"].value_counts().items())},
            "strict": _counts(df[strict]), "non_strict": _counts(df[~strict]), "yardstick": yardstick_counts(df),
            "sessions": len(meta.get("sessions") or []), "wall_time_s": wall_time_s(meta),
            "scenarios": scenario_counts(scenarios)}


def summary_line(s: dict) -> str:
    """The summary in one line of prose (report.md's opening line)."""
    wall = "wall time unknown (a session did not finish)" if s["wall_time_s"] is None else \
        f"wall time {s['wall_time_s']:.0f} s over {s['sessions']} session{'s' * (s['sessions'] != 1)}"
    y = s.get("yardstick")
    return (f"{s['rows']} rows: {len(s['solvers'])} solvers x {s['problems']} problems "
            f"({', '.join(s['modes'])}); {s['verified']} verified, {s['not_verified']} not verified "
            f"(strict solvers: {s['strict']['not_verified']}), {s['unsupported']} unsupported; "
            + (f"yardstick certified on {y['certified']['problems']} of {s['problems']} problems; " if y else "")
            + _scenarios_clause(s.get("scenarios") or {}) + f"{wall}.")


def _scenarios_clause(sc: dict) -> str:
    if not sc.get("runs"):
        return ""
    return (f"{sc['runs']} scenario run{'s' * (sc['runs'] != 1)}, {sc['finished']} finished, "
            f"{sc['all_checks_passed']} with every check passed; ")


def write_summary(out) -> Path:
    """Write OUT/summary.json from OUT/results.csv, OUT/run.json and OUT/scenarios.csv; its path."""
    from hikbench.bench.scenarios.rows import read_scenario_rows

    out = Path(out)
    path = out / SUMMARY_FILE
    summary = run_summary(read_results(out), read_run_json(out), read_scenario_rows(out))
    path.write_text(json.dumps(summary, indent=1) + "\n")
    return path
