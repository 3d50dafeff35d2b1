"""The worker side of a scenario job of ``hikbench run`` (a suite's ``[[scenarios]]``): run
one (scenario, robot, solver, warm-start mode) in closed loop and return its per-step
records, trajectory and checks as plain data.

Runs in the isolated worker process (bench/harness/isolation.py), like a solve job, so
that a solver that hangs or kills its process costs its row, not the run. A job is::

    {"kind": "scenario", "scenario": NAME or PATH, "robot": REF or None, "solver": spec,
     "warm_start": MODE or None, "steps": K, "repeat": R}

Before the run, the solver's ``warmup()`` (if it has one) and one untimed solve of the
scenario's first hierarchy; then ``notify()``, so that the worker's caller switches from
the first-solve allowance to the job's timeout (as for a solve job).
"""

from __future__ import annotations

import os
import socket
import traceback

from hikbench.bench.scenarios.rows import FINISHED
from hikbench.bench.scenarios.checks import check_run
from hikbench.bench.scenarios.runner import run_scenario
from hikbench.bench.specs import SolverSpec
from hikbench.problems.robots.kinematics import KinematicState
from hikbench.problems.robots.scenarios import load_scenario
from hikbench.solvers import registry
from hikbench.solvers.base import ERROR

__all__ = ["execute_scenario"]


def _first_solve(scenario, spec: str, warm_start: str | None) -> None:
    """Compile and load what the solver needs: its warm-up, then one solve of step 0's hierarchy."""
    info = SolverSpec.parse(spec).info()
    slv = registry.build(info, **({} if warm_start is None else {"warm_start": warm_start}))
    if callable(getattr(slv, "warmup", None)):
        slv.warmup()
    scenario.reset()
    state = KinematicState(scenario.robot, scenario.q_init)
    scenario.targets_at(0.0, state)
    slv.solve(scenario.stack.hierarchy(scenario.q_init, state))
    scenario.reset()


def execute_scenario(job: dict, notify=None) -> dict:
    """Run a scenario job; never raises (an exception is status ``error`` with its reason).
    Returns ``status`` (``finished``), ``records`` (the per-step DataFrame), ``q``
    (steps + 1, nq), ``checks`` [(name, passed (True, False or None: not judged), detail)], ``warm_start`` and ``label``."""
    base = {"host": socket.gethostname(), "pid": os.getpid()}
    try:
        scenario = load_scenario(job["scenario"], robot=job.get("robot"))
        _first_solve(scenario, job["solver"], job.get("warm_start"))
        if notify is not None:
            notify()
        run = run_scenario(scenario, job["solver"], warm_start=job.get("warm_start"), steps=job["steps"],
                           repeat=job["repeat"])
        checks = [(c.name, c.passed, c.detail) for c in check_run(run)]
        return {**base, "status": FINISHED, "reason": "", "records": run.records, "q": run.q,
                "checks": checks, "warm_start": run.warm_start, "label": run.label}
    except Exception as err:  # noqa: BLE001 - a failing job costs its row (status error + reason)
        tb = traceback.extract_tb(err.__traceback__)
        where = f" at {os.path.basename(tb[-1].filename)}:{tb[-1].lineno}" if tb else ""
        return {**base, "status": ERROR, "reason": f"{type(err).__name__}: {err}{where}"}
