"""OUT/scenarios.csv: one summary row per (scenario, robot, solver, warm-start mode, steps)
of a suite's ``[[scenarios]]`` (hikbench.bench.scenarios.suite), and the names of the
per-step files that ``hikbench scenario`` and ``hikbench run`` write alike.

A row's times are over the steps of its per-step CSV (bench/scenarios/runner.py):
``time_median_s`` is the median over the steps of ``solve_time_min_s`` (each step's
minimum over its ``repeat`` timed calls), ``time_p99_s`` its 99th percentile
(numpy.percentile, linear interpolation), and so on. The file is rewritten whole
(a temporary file, then ``os.replace``) each time a row is added: a run killed
meanwhile leaves the previous file, and a row run again replaces the old row of its key.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np
import pandas as pd

from hikbench.problems.errors import HikbenchError

__all__ = ["FINISHED", "KEY", "SCENARIOS_CSV", "SCENARIO_COLUMNS", "check_counts", "finished_keys", "markdown",
           "read_scenario_rows", "run_stem", "slug", "step_costs", "summary_row", "write_scenario_row"]

SCENARIOS_CSV = "scenarios.csv"
FINISHED = "finished"  #: status of a row whose run ended in the worker (its checks say how it went)

#: (name, description), in CSV order
SCENARIO_COLUMNS: tuple[tuple[str, str], ...] = (
    ("scenario", "the scenario's name (its TOML's `name`)"),
    ("robot", "the robot it ran on"),
    ("solver", "solver name"),
    ("warm_start", "the solver's warm_start option (none / stage / time), n/a for a solver without one"),
    ("steps", "control steps asked (the suite's `steps`, else the scenario's)"),
    ("scenario_steps", "the scenario's own steps: a run of fewer (cut by `steps`) leaves its final values unjudged "
                       "by the checks"),
    ("steps_run", "steps in the per-step CSV (fewer when the run stopped: see the check `run completed`)"),
    ("repeat", "timed calls per step (on as many solver objects, bench/scenarios/runner.py)"),
    ("status", f"`{FINISHED}` (the run ended in the worker; its checks judge it), or `timeout`, `crashed`, "
               "`error`: the job ended without a run"),
    ("reason", "why the job ended without a run"),
    ("time_median_s", "median over the steps of solve_time_min_s (each step's minimum of its timed calls), s"),
    ("time_p99_s", "99th percentile of the same, s"),
    ("time_min_s", "minimum of the same, s"),
    ("time_max_s", "maximum of the same, s"),
    ("first_median_s", "median over the steps of solve_time_first_s (the controller's call), s"),
    ("iterations_mean", "mean over the steps of the solver's iterations"),
    ("steps_not_optimal", "steps whose status is not optimal"),
    ("checks_passed", "checks of the scenario's [checks] passed (check_run)"),
    ("checks_failed", "checks failed"),
    ("checks_not_judged", "checks the run could not judge (a run cut by --steps, a scenario assumption that "
                          "failed): neither passed nor failed"),
    ("failed_checks", "names of the failed checks, separated by '; '"),
    ("csv", "the per-step CSV, relative to OUT (beside it, <stem>_q.npy: the joint trajectory)"),
    ("host", "host name of the worker"),
    ("worker", "worker id (pid@host serial, Dask worker address)"),
    ("wall_s", "wall time of the job, s"),
    ("finished_at", "UTC time the row was written (ISO 8601)"),
)
KEY = ("scenario", "robot", "solver", "warm_start", "steps")  #: a row's identity; resuming skips finished keys


def names() -> list[str]:
    return [c for c, _ in SCENARIO_COLUMNS]


def markdown() -> str:
    """The columns as a markdown table (docs/columns.md holds it)."""
    return "\n".join(["| column | meaning |", "|---|---|", *(f"| `{c}` | {d} |" for c, d in SCENARIO_COLUMNS)])


def slug(text: str) -> str:
    """``text`` as a file name: runs of other characters than ``[A-Za-z0-9_.-]`` become ``_``."""
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("_")


def run_stem(scenario: str, robot: str, label: str) -> str:
    """``<scenario>_<robot>_<label>`` as a file name: the per-step CSV is ``<stem>.csv``,
    the trajectory ``<stem>_q.npy`` (``label``: ``hcod (time)``, ``cascade-daqp``)."""
    return slug(f"{scenario}_{robot}_{label}")


def summary_row(key: dict, res: dict, csv: str | None) -> dict:
    """The row of a scenario job: ``key`` (scenario, robot, solver, warm_start, steps, repeat),
    the job's result ``res`` (hikbench.bench.scenarios.job; ``records`` and ``checks`` when its
    run ended in the worker) and the per-step CSV's path relative to OUT."""
    row = {**key, "status": res["status"], "reason": res.get("reason", ""), "csv": csv,
           **{k: res.get(k) for k in ("host", "worker", "wall_s")}}
    df = res.get("records")
    if df is not None:
        checks = res.get("checks") or []
        row.update(steps_run=len(df), **step_costs(df), **check_counts((name, ok) for name, ok, _ in checks))
    return row


def step_costs(df: pd.DataFrame) -> dict:
    """The cost columns of a run's per-step records ``df``, as in OUT/scenarios.csv
    (``time_median_s`` ... ``steps_not_optimal``): ``hikbench scenario``'s
    summary.csv has the same."""
    t = df["solve_time_min_s"].to_numpy(dtype=float)
    return {"time_median_s": float(np.median(t)), "time_p99_s": float(np.percentile(t, 99)),
            "time_min_s": float(t.min()), "time_max_s": float(t.max()),
            "first_median_s": float(np.median(df["solve_time_first_s"])),
            "iterations_mean": float(df["iterations"].mean()),
            "steps_not_optimal": int((df["status"] != "optimal").sum())}


def check_counts(pairs) -> dict:
    """``checks_passed``, ``checks_failed``, ``checks_not_judged`` (counts) and ``failed_checks``
    (names, '; '-joined) of a run's checks, given as (name, passed) pairs, passed True, False
    or None (not judged)."""
    pairs = list(pairs)
    failed = [name for name, passed in pairs if passed is False]
    return {"checks_passed": sum(passed is True for _, passed in pairs), "checks_failed": len(failed),
            "checks_not_judged": sum(passed is None for _, passed in pairs), "failed_checks": "; ".join(failed)}


def read_scenario_rows(out) -> pd.DataFrame:
    """OUT/scenarios.csv (an empty frame with the columns when there is none); HikbenchError
    naming the file when it is not one this version writes."""
    path = Path(out) / SCENARIOS_CSV
    if not path.exists():
        return pd.DataFrame(columns=names())
    try:
        df = pd.read_csv(path, keep_default_na=False, na_values=[""])
    except (OSError, ValueError, UnicodeDecodeError) as err:
        raise HikbenchError(f"{path}: cannot read as CSV ({' '.join(str(err).split())}); expected the "
                            f"scenarios.csv written by hikbench run") from err
    if list(df.columns) != names():
        raise HikbenchError(f"{path}: its columns differ from this version's; expected the scenarios.csv "
                            f"written by this version of hikbench run (write to a new --out directory)")
    return df


def _key(row) -> tuple:
    return tuple(str(row[k]) for k in KEY)


def write_scenario_row(out, row: dict) -> Path:
    """Add ``row`` to OUT/scenarios.csv, replacing a row of the same :data:`KEY`."""
    path = Path(out) / SCENARIOS_CSV
    old = read_scenario_rows(out)
    keep = old[[_key(r) != _key(row) for _, r in old.iterrows()]] if len(old) else old
    new = pd.DataFrame([{k: row.get(k) for k in names()}], columns=names())
    df = pd.concat([keep, new], ignore_index=True) if len(keep) else new
    tmp = path.with_suffix(".csv.tmp")
    try:
        df.to_csv(tmp, index=False)
        os.replace(tmp, path)
    except OSError as err:  # (a full disk: the rows written before are kept, whole)
        tmp.unlink(missing_ok=True)
        raise HikbenchError(f"{path}: cannot write a row ({err.strerror or err}); the rows finished before it "
                            f"are kept: free space and run the same command again to resume") from None
    return path


def finished_keys(out) -> set[tuple]:
    """The keys of OUT/scenarios.csv's rows."""
    return {_key(r) for _, r in read_scenario_rows(out).iterrows()}
