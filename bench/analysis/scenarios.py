"""The report's "Scenarios" section: one line per run of the suite's ``[[scenarios]]``
(OUT/scenarios.csv, hikbench.bench.scenarios.rows), and the same rows for report.json."""

from __future__ import annotations

import math
from pathlib import Path

from hikbench.bench.scenarios.rows import FINISHED, SCENARIOS_CSV, read_scenario_rows

__all__ = ["TITLE", "scenario_rows", "scenario_section"]

TITLE = "Scenarios"
FAILED_SHOWN = 3  #: failed checks named in a cell; the others counted


def _us(t) -> str:
    """Seconds as us with one decimal; '-' for none."""
    return "-" if t is None or not math.isfinite(float(t)) else f"{float(t) * 1e6:.1f}"


def _plain(v):
    """A CSV cell as JSON takes it: NaN (an empty cell) as None, numpy scalars as Python's."""
    if hasattr(v, "item"):
        v = v.item()
    return None if isinstance(v, float) and math.isnan(v) else v


def scenario_rows(run_dir) -> list[dict]:
    """The rows of RUN/scenarios.csv ([] when the run has none)."""
    df = read_scenario_rows(run_dir)
    return [{k: _plain(v) for k, v in r.items()} for r in df.to_dict("records")]


def _checks(r: dict) -> str:
    if r["checks_passed"] is None:
        return "-"
    passed, failed, unjudged = int(r["checks_passed"]), int(r["checks_failed"]), int(r["checks_not_judged"])
    cell = f"{passed}/{passed + failed + unjudged} passed" + (f", {unjudged} not judged" if unjudged else "")
    if failed:
        names = str(r["failed_checks"]).split("; ")
        more = f" and {len(names) - FAILED_SHOWN} more" if len(names) > FAILED_SHOWN else ""
        cell += f"; failed: {', '.join(names[:FAILED_SHOWN])}{more}"
    return cell


def _steps(r: dict) -> str:
    """Steps run, with what cut or stopped the run."""
    run = r["steps"] if r["steps_run"] is None else int(r["steps_run"])
    notes = []
    if r["steps"] < r["scenario_steps"]:
        notes.append(f"cut: the scenario has {r['scenario_steps']}")
    if run < r["steps"]:
        notes.append(f"stopped: {r['steps']} asked")
    return f"{run} ({'; '.join(notes)})" if notes else str(run)


def _status(r: dict) -> str:
    if r["status"] == FINISHED:
        return FINISHED
    return f"{r['status']}: {str(r['reason'] or '')[:160]}".replace("|", "/")


def scenario_section(doc, run_dir: Path, meta: dict) -> list[dict]:
    """Write the section into ``doc`` (report.py's _Doc) when the run has scenario rows;
    returns those rows."""
    rows = scenario_rows(run_dir)
    if not rows:
        return rows
    doc.section(TITLE)
    planned = meta.get("suite_scenario_runs")
    incomplete = (f" **{len(rows)} of the suite's {planned} runs so far.**"
                  if isinstance(planned, int) and len(rows) < planned else "")
    doc.text(f"Each closed-loop run of the suite's `[[scenarios]]` ({SCENARIOS_CSV}; per-step CSVs under "
             f"scenarios/<scenario>/). Times are over the steps of each step's solve time, the minimum of its "
             f"`repeat` timed calls (the solver's cost; the first call, what a controller sees, is the "
             f"CSV's solve_time_first_s); the checks are the scenario's own (docs/robots.md). Steps not "
             f"optimal: steps whose solver status was not optimal (the run goes on with its x)." + incomplete)
    doc.table("scenarios", "Scenario runs (steps: those run; a run cut by the suite's `steps` to fewer than the "
              "scenario's leaves its final values unjudged by the checks)",
              ["scenario", "robot", "solver", "warm start", "steps", "median [us]", "p99 [us]", "min [us]",
               "mean iterations", "steps not optimal", "checks", "status"],
              [[r["scenario"], r["robot"], r["solver"], r["warm_start"],
                _steps(r),
                _us(r["time_median_s"]), _us(r["time_p99_s"]), _us(r["time_min_s"]),
                "-" if r["iterations_mean"] is None else f"{r['iterations_mean']:.2f}",
                "-" if r["steps_not_optimal"] is None else int(r["steps_not_optimal"]), _checks(r), _status(r)]
               for r in rows])
    return rows
