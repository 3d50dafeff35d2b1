"""A suite's ``[[scenarios]]``: closed-loop robot scenarios run by ``hikbench run`` after the
problems, each (scenario, robot, solver, warm-start mode) one job in the isolated worker.

Each job writes what ``hikbench scenario`` writes, under ``OUT/scenarios/<scenario>/``:
``<scenario>_<robot>_<label>.csv`` (per step, bench/scenarios/runner.py) and ``..._q.npy``,
and one summary row to ``OUT/scenarios.csv`` (hikbench.bench.scenarios.rows).

Decisions (docs/suites.md, "Scenarios in a suite"):

* The entry's ``solvers`` are patterns as for problems (default: the suite's; ``--solvers``
  replaces both); a solver that is not built or installed is skipped with its hint, an
  external program (no solver object to keep in the loop) is skipped with that reason.
* ``warm_start`` lists the modes of the solvers that have a ``warm_start`` option (hcod:
  none / stage / time; soth, lexls: none / time), one run each; a solver without the option
  runs once (``n/a``); without the key, each solver's default mode. A mode a solver refuses
  is an error before anything runs.
* The scenario, the robot and every (solver, mode) are loaded and built when the suite is
  expanded: a bad entry stops ``run`` with one line naming ``scenarios[i].KEY``.
* Resuming skips the runs whose row is in OUT/scenarios.csv (key: scenario, robot, solver,
  warm_start, steps); ``--rerun`` runs them again and replaces their rows.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hikbench.bench.harness.environment import utc_now
from hikbench.bench.scenarios.rows import (
    FINISHED,
    finished_keys,
    run_stem,
    slug,
    summary_row,
    write_scenario_row,
)
from hikbench.bench.scenarios.runner import NO_WARM_START, REPEAT
from hikbench.bench.specs import EXTERNAL, warm_start_modes
from hikbench.bench.suites import Suite, SuiteError, resolve_solvers
from hikbench.problems.errors import HikbenchError
from hikbench.solvers import registry

__all__ = ["ScenarioTask", "TIMEOUT_S", "expand_scenarios", "run_scenarios"]

TIMEOUT_S = 600.0  #: default ``timeout`` of a [[scenarios]] entry: one run of 700 steps takes 3-15 s


@dataclass(frozen=True)
class ScenarioTask:
    """One (scenario, robot, solver, warm-start mode) run of a suite."""

    name: str               # the entry's name: a shipped scenario or a .toml path
    robot_ref: str | None   # the entry's robot (None: the scenario's)
    scenario: str           # the scenario's own name
    robot: str              # the robot's name
    solver: str             # the solver's name in the rows
    spec: str               # how the worker builds it
    warm_start: str | None  # None: the solver has no warm_start option
    steps: int
    scenario_steps: int     # the scenario's own
    repeat: int
    timeout: float

    @property
    def mode(self) -> str:
        return NO_WARM_START if self.warm_start is None else self.warm_start

    @property
    def label(self) -> str:
        return self.solver if self.warm_start is None else f"{self.solver} ({self.warm_start})"

    @property
    def key(self) -> tuple[str, ...]:
        return (self.scenario, self.robot, self.solver, self.mode, str(self.steps))

    def job(self, first_timeout: float) -> dict:
        return {"kind": "scenario", "scenario": self.name, "robot": self.robot_ref, "solver": self.spec,
                "warm_start": self.warm_start, "steps": self.steps, "repeat": self.repeat,
                "first_timeout": first_timeout}


def expand_scenarios(suite: Suite, solver_patterns=None) -> tuple[list[ScenarioTask], dict[str, str]]:
    """Every run of the suite's ``[[scenarios]]`` and the solvers skipped (name -> why);
    SuiteError naming ``scenarios[i].KEY`` for an entry that cannot run."""
    tasks, skipped, seen = [], {}, {}
    suite_file = suite.source or suite.name
    for i, e in enumerate(suite.scenarios):
        where = f"suite {suite_file}: scenarios[{i}]"
        scenario = _load(e, where)
        pats = tuple(solver_patterns) if solver_patterns else tuple(e.get("solvers") or suite.solvers)
        entries, sk = resolve_solvers(pats, (), "--solvers" if solver_patterns else f"{where}.solvers", suite_file)
        skipped.update(sk)
        modes = e.get("warm_start")
        if modes and len(set(modes)) < len(modes):
            raise SuiteError(f"{where}.warm_start = {modes}: expected each mode once")
        for entry in entries:
            if entry.spec.kind == EXTERNAL:
                skipped[entry.solver] = "an external program cannot run a closed-loop scenario (no solver object)"
                continue
            for mode in _modes(entry, modes, where):
                t = ScenarioTask(e["name"], e.get("robot"), scenario.name, scenario.robot.name, entry.solver,
                                 entry.spec.text, mode, int(e.get("steps", scenario.steps)), scenario.steps,
                                 int(e.get("repeat", REPEAT)), float(e.get("timeout", TIMEOUT_S)))
                if t.key in seen:
                    raise SuiteError(f"{where}: runs {t.label} on {t.scenario} ({t.robot}, {t.steps} steps) as "
                                     f"scenarios[{seen[t.key]}] does: expected each run once")
                seen[t.key] = i
                tasks.append(t)
    return tasks, skipped


def _load(e: dict, where: str):
    """The entry's scenario on its robot (robots are loaded once per process)."""
    from hikbench.problems.robots.models import load_robot
    from hikbench.problems.robots.scenarios import load_scenario

    if "robot" in e:
        try:
            load_robot(e["robot"])
        except HikbenchError as err:
            raise SuiteError(f"{where}.robot: {' '.join(str(err).split())}") from err
    try:
        return load_scenario(e["name"], robot=e.get("robot"))
    except HikbenchError as err:
        raise SuiteError(f"{where}.name: {' '.join(str(err).split())}") from err


def _modes(entry, modes, where: str) -> list[str | None]:
    """The warm-start modes to run ``entry`` in (None: it has no warm_start option), each
    checked by building the solver with it."""
    try:
        info = entry.spec.info(entry.solver)
        out = warm_start_modes(info, modes)
    except HikbenchError as err:
        raise SuiteError(f"{where}.solvers: {err}") from err
    if out == [None]:
        return out
    for mode in out:
        try:
            registry.build(info, warm_start=mode)
        except HikbenchError as err:
            raise SuiteError(f"{where}.warm_start: solver {entry.solver!r}: {' '.join(str(err).split())}") from err
    return out


def run_scenarios(tasks: list[ScenarioTask], out: Path, executor, first_timeout: float, *, rerun: bool = False,
                  limit: int | None = None, progress=None) -> tuple[int, int, dict]:
    """Run ``tasks`` through ``executor`` (isolated workers) into ``out`` (module docstring).
    Returns (runs already finished and skipped, rows written, {status: rows})."""
    done = set() if rerun else finished_keys(out)
    todo = [t for t in tasks if t.key not in done]
    skipped = len(tasks) - len(todo)
    if limit is not None:
        todo = todo[: max(int(limit), 0)]
    tid = progress.add("scenarios", len(todo)) if progress is not None and todo else None
    written, statuses = 0, {}
    items = ((i, t.job(first_timeout), t.timeout) for i, t in enumerate(todo))
    for i, res in executor.map(items):
        t = todo[i]
        csv = _write_run(out, t, res) if res.get("records") is not None else None
        key = {"scenario": t.scenario, "robot": t.robot, "solver": t.solver, "warm_start": t.mode,
               "steps": t.steps, "scenario_steps": t.scenario_steps, "repeat": t.repeat}
        row = summary_row(key, res, csv)
        row["finished_at"] = utc_now()
        write_scenario_row(out, row)
        written += 1
        statuses[row["status"]] = statuses.get(row["status"], 0) + 1
        if row["status"] != FINISHED or row.get("checks_failed"):
            print(f"hikbench run: scenario {t.scenario} ({t.robot}), {t.label}: {row['status']}"
                  + (f", failed checks: {row['failed_checks']}" if row.get("checks_failed") else "")
                  + (f": {row['reason']}" if row.get("reason") else ""), file=sys.stderr)
        if tid is not None:
            progress.advance(tid, f"scenarios: {t.scenario} {t.label}")
    return skipped, written, statuses


def _write_run(out: Path, t: ScenarioTask, res: dict) -> str:
    """The per-step CSV and the trajectory of a run, as ``hikbench scenario`` writes them;
    the CSV's path relative to ``out``."""
    d = out / "scenarios" / slug(t.scenario)
    d.mkdir(parents=True, exist_ok=True)
    stem = run_stem(t.scenario, t.robot, t.label)
    res["records"].to_csv(d / f"{stem}.csv", index=False)
    np.save(d / f"{stem}_q.npy", res["q"])
    return (d / f"{stem}.csv").relative_to(out).as_posix()
