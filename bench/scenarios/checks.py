"""The checks of a scenario run (its ``[checks]`` table, problems/robots/scenarios.py),
verified on the per-step record and the joint trajectory: each passes, fails (put down to
the solver or to the scenario's assumption) or is not judged (a run cut by ``--steps``, a
premise that failed on another line), and says why."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from hikbench.problems.robots.limits import JointVelocityLimits

if TYPE_CHECKING:
    from hikbench.bench.scenarios.runner import ScenarioRun

__all__ = ["BLAME", "Check", "LIMIT_TOL", "LOWEST_RTOL", "OUT_OF_REACH", "REACHED_TOL", "REGULATED_ATOL",
           "REGULATED_FINAL", "VELOCITY_TOL", "check_run"]


@dataclass(frozen=True)
class Check:
    """One verified property of a run: ``passed`` True or False, or None when the run
    cannot judge it (a run cut short by ``--steps``, a premise that failed on another
    line); its detail then says why. ``judges`` says what a failure is put down to:
    ``"solver"`` (the run did not do what the hierarchy asks) or ``"scenario"`` (an
    assumption of the scenario file, such as an out-of-reach target, does not hold on
    this robot); a failed check's detail ends with it (:data:`BLAME`)."""

    name: str
    passed: bool | None
    detail: str
    judges: str = "solver"

    def __post_init__(self):
        if self.judges not in BLAME:
            raise ValueError(f"judges must be one of {', '.join(BLAME)}; got {self.judges!r}")
        if self.passed is not None:
            object.__setattr__(self, "passed", bool(self.passed))
        if self.passed is False:
            object.__setattr__(self, "detail", f"{self.detail} -> {BLAME[self.judges]}")

    @property
    def verdict(self) -> str:
        """``pass``, ``FAIL`` or ``not judged`` (the CLI's tag of the check's line)."""
        return {True: "pass", False: "FAIL", None: "not judged"}[self.passed]


#: what a failed check is put down to, by ``Check.judges``
BLAME = {"solver": "the solver failed",
         "scenario": "the scenario's assumption failed on this robot, not the solver"}


#: tolerances of the scenario checks (m, rad, or mixed 6D log units)
LIMIT_TOL = 1e-9       #: joint-limit margin allowed below 0
#: total velocity-limit excess allowed at a step, rad/s (hcod's rows sit within 1e-9 of their bounds)
VELOCITY_TOL = 1e-6
REGULATED_ATOL = 2e-3  #: a regulated task's error may exceed its initial value by this much
REGULATED_FINAL = 1e-5  #: ... and ends below this
REACHED_TOL = 1e-3     #: reaching error at the end of the in-reach phase
LOWEST_RTOL = 0.02     #: out-of-reach error at the end of its phase vs its minimum (relative)
OUT_OF_REACH = 1e-2    #: an out-of-reach target keeps an error above this


def _velocity_checks(run: ScenarioRun) -> list[Check]:
    """A check per velocity-limit task of the stack: the joint velocities u the run
    commanded stayed within |u_i| <= v_max_i (``err_<task>``: the step's total excess)."""
    out = []
    for task in run.scenario.stack.tasks:
        column = f"err_{task.name}"
        if not isinstance(task, JointVelocityLimits) or column not in run.records:
            continue
        e = run.records[column].to_numpy(dtype=float)
        worst = int(np.nanargmax(e)) if np.any(np.isfinite(e)) else 0
        out.append(Check(f"{task.name} held", bool(np.all(np.nan_to_num(e, nan=np.inf) <= VELOCITY_TOL)),
                         f"max total excess {e[worst]:.3e} rad/s at step {worst} (tol {VELOCITY_TOL:g})"))
    return out


def _completion(df: pd.DataFrame, steps_run: int, stopped: bool) -> str:
    """The detail of ``run completed``: steps run, how the run stopped, and the solver's
    statuses, recorded and not judged (the other checks judge the task errors from q and u)."""
    detail = f"{steps_run} steps" + (f", stopped at step {steps_run - 1} ({df['status'].iloc[-1]})" if stopped else "")
    if not steps_run:
        return detail
    counts = df["status"].value_counts()
    if set(counts.index) == {"optimal"}:
        return f"{detail}; every status optimal"
    first = df[df["status"] != "optimal"].iloc[0]
    said = ", ".join(f"{int(n)} {status}" for status, n in sorted(counts.items(), key=lambda sn: (-sn[1], sn[0])))
    why = f": {first['reason']}" if isinstance(first["reason"], str) and first["reason"] else ""
    return (f"{detail}; the solver's statuses, recorded (the checks judge the task errors, not the statuses): {said} "
            f"(first not optimal: step {int(first['step'])}, {first['status']}{why})")


def _decay(e: np.ndarray, commanded: float) -> str:
    """The measured decay per step of an error over the first 50 steps, beside the commanded
    1 - lambda dt (second-order drift from the other tasks' motion slows it down); what was
    not measured is said so, not printed as nan."""
    k = min(50, len(e) - 1)
    if k == 0:
        return "decay per step not measured (one step)"
    if e[0] <= 1e-9:
        return f"decay per step not measured (e0 {e[0]:.1e}: at most 1e-9, nothing to decay)"
    if e[k] <= 0:
        return f"decay per step not measured (error 0 by step {k})"
    return f"decay per step {(e[k] / e[0]) ** (1.0 / k):.4f} vs commanded {commanded:.4f}"


def check_run(run: ScenarioRun) -> list[Check]:
    """Verify the scenario's ``[checks]`` on a run (see problems/robots/scenarios.py)."""
    spec, df, out = run.scenario.checks, run.records, []
    robot = run.scenario.robot
    steps_run = len(df)
    stopped = steps_run and (df["status"].iloc[-1] == "diverged" or not np.all(np.isfinite(run.q[-1]))
                             or len(run.q) < steps_run + 1)
    # a run cut short by --steps (not stopped by a failure): final values are not judged
    cut = not stopped and steps_run < run.scenario.steps
    out.append(Check("run completed", not stopped, _completion(df, steps_run, bool(stopped))))
    if spec.get("limits", False):
        margin = min(float(np.min(robot.limit_margin(q))) for q in run.q)
        out.append(Check("joint limits", margin >= -LIMIT_TOL, f"min margin {margin:.3e}"))
        out.extend(_velocity_checks(run))
    # a run cut by --steps has no final values: a check that needs them is not judged, unless what
    # the steps run show already fails it
    why_not = f"not judged: the run was cut to {steps_run} of the scenario's {run.scenario.steps} steps (--steps)"
    for name in spec.get("regulated", []):
        # stays regulated: never above its initial error + REGULATED_ATOL; decays to ~0 at the end
        task = run.scenario.stack.task(name)
        e = df[f"err_{name}"].to_numpy()
        worst = int(np.argmax(e))
        bounded = bool(np.all(e <= e[0] + REGULATED_ATOL))
        passed = bounded and (None if cut else bool(e[-1] <= REGULATED_FINAL))
        final = f"final {e[-1]:.2e} {why_not}" if cut else f"final {e[-1]:.2e} (tol {REGULATED_FINAL})"
        out.append(Check(f"{name} regulated", passed, f"e0 {e[0]:.2e}, max {e[worst]:.2e} at step {worst} "
                         f"(tol e0 + {REGULATED_ATOL:g}), {final}; {_decay(e, 1 - task.gain * run.scenario.dt)}"))
    for name, tol in spec.get("tracked", {}).items():
        e = df[f"err_{name}"].to_numpy()
        worst = int(np.argmax(e))
        out.append(Check(f"{name} tracked", bool(e[worst] <= tol),
                         f"max error {e[worst]:.2e} at step {worst} (tol {tol}); final {e[-1]:.2e}"))
    reach = spec.get("reach")
    if reach:
        e = df[f"err_{reach['task']}"].to_numpy()
        tsw = float(reach["out_of_reach_until"])
        phase1 = df["time_s"].to_numpy() < tsw - 1e-9
        if phase1.any():
            e1 = e[phase1]
            ended = (~phase1).any() or not cut  # (a phase a cut run did not finish has no end value)
            low = float(e1.min())
            # the scenario's assumption: the target stays out of reach (judged on every step run)
            unreachable = bool(low > OUT_OF_REACH)
            out.append(Check("out of reach: target unreachable", unreachable,
                             f"lowest error {low:.3e} (expected > {OUT_OF_REACH})" + (
                                 "" if unreachable else ": the target is within this robot's reach; give "
                                 "the scenario a longer offset (e.g. in arm lengths)"), judges="scenario"))
            # the solver: the error comes down to its lowest value and stays there (an assumption of
            # an unreachable target: a reachable one is not judged on it)
            seen = f"start {e1[0]:.3e}, end {e1[-1]:.3e}, min {low:.3e}"
            if not unreachable:
                out.append(Check("out of reach: lowest value", None, f"{seen}; not judged: the target is within "
                                 "reach (out of reach: target unreachable)"))
            elif not ended:
                out.append(Check("out of reach: lowest value", None, f"{seen}; {why_not}"))
            else:
                ok = e1[-1] <= low * (1 + LOWEST_RTOL) + 1e-6 and e1[-1] < e1[0]
                out.append(Check("out of reach: lowest value", bool(ok),
                                 f"{seen} (end within {LOWEST_RTOL:.0%} of the min expected)"))
        if (~phase1).any():
            e2 = e[~phase1]
            out.append(Check("back in reach: converges to 0", None if cut else bool(e2[-1] <= REACHED_TOL),
                             f"start {e2[0]:.3e}, end {e2[-1]:.3e} (tol {REACHED_TOL})"
                             + (f"; {why_not}" if cut else "")))
    return out
