"""The closed loop of a robot scenario (ICRA 2010 sec. XII): at each control step
k (time t_k = k dt) set the targets of t_k, build the stack's hierarchy at q_k,
solve it with any registered solver, integrate ``q_{k+1} = pin.integrate(q_k,
u dt)``, repeat.

Timing: each step is solved by ``repeat`` solver objects (default
:data:`REPEAT` = 5), built alike and fed the same hierarchies from step 0, so
that a solver with warm start holds the same state in each of them at every
step (what a controller's one solver object would hold; no state is copied
or restored, the solver is not touched). The first object is the
controller's: its call is timed first, after the new hierarchy is built
(``solve_time_first_s``: what a controller sees), and its x, status and
counts are the step's record; the others then solve the same hierarchy, and
``solve_time_min_s`` is the minimum of the ``repeat`` times (the solver's
own cost: a pause of the machine, which lengthens one call, is left out).
``repeats_agree`` says whether every object returned the first's answer
(status, iterations, activations, deactivations, x bit for bit): a solver
whose objects drift apart (a nondeterministic backend) times other work in
its minimum, and the CLI says how many steps did. A scenario controller
(``pink``, bench/scenarios/controllers.py) takes q and the step's targets
before the timed calls, untimed (:meth:`Controller.prepare`), as the
hierarchy is built untimed for a solver; its timed call is its ``solve``.

Per-step record (one row per step; :data:`COLUMNS` then one column per task
and per level):

=========================  ==================================================
solver                     registry name
warm_start                 ``none`` / ``stage`` / ``time`` (the solver's ``warm_start``
                           option), ``n/a`` for a solver without that option and a
                           controller (``pink``)
step                       k
time_s                     t_k = k dt (s)
solve_time_min_s           minimum over the ``repeat`` timed calls of ``solver.solve``
                           (perf_counter_ns, GC off, BLAS threads = 1; one untimed
                           warm-up solve on a separate solver object before the run), s
solve_time_first_s         the first of them (the controller's call), s
resolve_time_min_s         with ``resolve=True`` (``hikbench scenario --resolve``): after the
                           step's timed calls, each of the ``repeat`` objects solves the same
                           hierarchy once more, timed; the minimum (s). The cost of the step's
                           problem to a solver that has just solved it (hcod ``time``: its
                           warm re-solve); the next step sees the state this call leaves.
                           Empty without it
repeat                     timed calls of the step
repeats_agree              every call returned the first's answer (see above)
iterations                 SolveResult.iterations (the first call's)
activations, deactivations SolveResult counts (active-set solvers; 0 otherwise): the
                           solver's own, from its starting active set (a cold start
                           counts every row it activates)
active_rows                inequality rows at or beyond a bound at u: within
                           :data:`ACTIVE_RTOL` x max(1, |bound|) of it (any solver)
rows_entered, rows_left    rows of ``active_rows`` that were not active at the previous
                           step / active rows of the previous step that are not now
                           (empty at step 0): the active-set changes Fig. 2 marks
status                     SolveResult.status, or ``diverged`` when q (+) u dt is not
                           finite (the run stops there)
reason                     SolveResult.reason (empty when optimal)
min_joint_limit_margin     min over bounded joints of min(q - q_l, q_u - q) at q_k
                           (rad or m; negative = violated)
err_<task>                 the task's error norm at q_k (``Task.error_norm``;
                           m for positions, rad for orientations, mixed for 6D
                           log errors; for minimal velocity ||u|| rad/s)
level_norm_<level>         ||v_k(u)||, the level's violation recomputed from u
=========================  ==================================================

With ``certify`` (``hikbench scenario --certify``), after the run each step's u is certified
exactly (:func:`certify_steps`, in worker processes) and three columns follow:

=========================  ==================================================
certified                  the exact certificate (hikbench.problems.exact) accepted the
                           active set read off u: its x* is the step's exact lexicographic
                           optimum (empty where the step has no finite u)
certify_reason             why not (the first check that failed), else empty
x_attains                  no level norm of u is above x*'s beyond the high profile's
                           tolerance (1e-9 of the level's terms, hikbench.problems.verify.judge;
                           empty where not certified)
=========================  ==================================================
"""

from __future__ import annotations

import gc
import inspect
import time
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
import pinocchio as pin
from threadpoolctl import threadpool_limits

from hikbench.bench.harness.worker import solver_info
from hikbench.bench.scenarios.controllers import Controller, build_controller, is_controller
from hikbench.problems.errors import HikbenchError
from hikbench.problems.robots.kinematics import KinematicState
from hikbench.problems.robots.scenarios import Scenario
from hikbench.solvers import registry
from hikbench.solvers.base import ERROR, SolveResult, checked_result
from hikbench.problems.verify import level_norms

__all__ = ["ACTIVE_RTOL", "COLUMNS", "NO_WARM_START", "REPEAT", "ScenarioRun", "active_rows", "certify_steps",
           "run_scenario", "warm_start_default"]

COLUMNS = ("solver", "warm_start", "step", "time_s", "solve_time_min_s", "solve_time_first_s",
           "resolve_time_min_s", "repeat", "repeats_agree", "iterations", "activations", "deactivations",
           "active_rows", "rows_entered", "rows_left", "status", "reason", "min_joint_limit_margin")
NO_WARM_START = "n/a"
REPEAT = 5  #: timed calls per step (``hikbench scenario --repeat``)
#: a row within ACTIVE_RTOL x max(1, |bound|) of its bound is active: the solvers of the reach
#: scenario put their active rows within 1e-10 (hcod) and 1e-6 (cascade-daqp) of them, and the
#: nearest inactive row 1e-4 away (400 steps, 64 inequality rows a step)
ACTIVE_RTOL = 1e-6


@dataclass
class ScenarioRun:
    """One run: the per-step ``records``, the joint trajectory ``q`` (steps + 1, nq) and
    ``steps``, each step with a finite u as ``(k, hierarchy, u)`` (what ``hikbench certify``
    certifies after the fact: bench/scenarios/recorded.py)."""

    scenario: Scenario
    solver: str
    warm_start: str
    records: pd.DataFrame
    q: np.ndarray
    steps: list = field(default_factory=list)

    @property
    def label(self) -> str:
        return self.solver if self.warm_start == NO_WARM_START else f"{self.solver} ({self.warm_start})"


def warm_start_default(info: registry.SolverInfo) -> str | None:
    """The default warm-start mode of a solver with the HCOD modes (none / stage /
    time): its registered option, or, for a ``module:Class`` solver, the default
    of the factory's ``warm_start`` parameter; None for a solver without one."""
    if "warm_start" in info.options:
        return str(info.options["warm_start"])
    if "warm_start" not in (registry.option_names(info) or ()):
        return None
    param = inspect.signature(info.factory).parameters["warm_start"]
    if param.default is param.empty:
        raise HikbenchError(f"solver {info.name!r}: its warm_start parameter has no default value; "
                            f"expected one (none, stage or time)")
    return str(param.default)


def active_rows(h, u: np.ndarray) -> np.ndarray:
    """Bool mask, shape (rows,): the inequality rows (lower < upper) of ``h``
    whose A_i u is within ACTIVE_RTOL x max(1, |bound|) of a finite bound or
    beyond it (saturated or violated: the rows an active-set solver holds as
    equalities); equality and free rows are False."""
    Au = h.A @ u
    ineq = h.lower < h.upper
    with np.errstate(invalid="ignore"):  # (inf - inf of free rows: NaN, compared False)
        low = np.isfinite(h.lower) & (Au - h.lower <= ACTIVE_RTOL * np.maximum(1.0, np.abs(h.lower)))
        up = np.isfinite(h.upper) & (h.upper - Au <= ACTIVE_RTOL * np.maximum(1.0, np.abs(h.upper)))
    return ineq & (low | up)


def run_scenario(scenario: Scenario, solver: str, options: dict | None = None,
                 warm_start: str | None = None, steps: int | None = None, repeat: int = REPEAT,
                 resolve: bool = False, certify: int = 0, on_step=None) -> ScenarioRun:
    """Run ``scenario`` in closed loop with solver ``solver``.

    Parameters
    ----------
    solver : str
        A registry name or ``module:Class`` / ``file.py:Class``
        (:func:`hikbench.bench.harness.worker.solver_info`), or a scenario
        controller (``pink``, bench/scenarios/controllers.py).
    options : dict
        Solver options (``registry.build(info, **options)``).
    warm_start : str, optional
        Passed as the ``warm_start`` option to solvers that have one (HCOD's
        none / stage / time); ignored, and the column reads ``n/a``, for the others.
    steps : int, optional
        Number of control steps (default: the scenario's).
    repeat : int
        Timed calls per step, on as many solver objects (module docstring).
    resolve : bool
        Also time each object solving the step's hierarchy again
        (``resolve_time_min_s``, module docstring).
    certify : int
        With ``certify`` >= 1 worker processes, certify every step's u exactly after the run
        (columns ``certified``, ``certify_reason``, ``x_attains``; module docstring).
    on_step : callable, optional
        ``on_step(k, h, result)`` after each step's timed calls: the step's hierarchy and the
        controller's SolveResult (``hikbench testset``'s recorder, bench/testset/record.py).
    """
    options = dict(options or {})
    make, mode = _maker(scenario, solver, options, warm_start)
    steps = scenario.steps if steps is None else int(steps)
    if steps < 1:
        raise HikbenchError(f"steps must be >= 1; got {steps}")
    if int(repeat) < 1:
        raise HikbenchError(f"repeat must be >= 1; got {repeat}")
    solvers = [make() for _ in range(int(repeat))]  # [0]: the controller's
    robot, stack, dt = scenario.robot, scenario.stack, scenario.dt
    # warm-up (untimed, on a separate solver object): numba compilation, backend caches
    scenario.reset()
    state = KinematicState(robot, scenario.q_init)
    scenario.targets_at(0.0, state)
    first = make()
    _prepare([first], scenario.q_init)
    _solve(first, stack.hierarchy(scenario.q_init, state))  # (step 0 reports a failure)
    scenario.reset()
    q = scenario.q_init.copy()
    traj, rows, before, steps_hx = [q.copy()], [], None, []
    with threadpool_limits(limits=1):
        for k in range(steps):
            t = k * dt
            state = KinematicState(robot, q)
            scenario.targets_at(t, state)
            h = stack.hierarchy(q, state)
            _prepare(solvers, q)
            res, times, agree = _timed_calls(solvers, h)
            if on_step is not None:
                on_step(k, h, res)
            u = res.x
            now = active_rows(h, u) if u is not None and np.all(np.isfinite(u)) else None
            row = {"solver": solver, "warm_start": mode, "step": k, "time_s": t,
                   "solve_time_min_s": min(times), "solve_time_first_s": times[0],
                   "resolve_time_min_s": min(_timed_calls(solvers, h)[1]) if resolve else None, "repeat": len(times),
                   "repeats_agree": agree, "iterations": int(res.iterations), "activations": int(res.activations),
                   "deactivations": int(res.deactivations), **_changes(before, now), "status": res.status,
                   "reason": res.reason,
                   "min_joint_limit_margin": float(np.min(robot.limit_margin(q), initial=np.inf))}
            before = now
            # (a velocity task without u, the solver having returned none: an empty cell)
            row.update({f"err_{name}": np.nan if v is None else v for name, v in stack.errors(q, u, state).items()})
            norms = level_norms(h, u) if u is not None else np.full(h.depth, np.nan)
            row.update({f"level_norm_{name}": float(v) for name, v in zip(h.names, norms)})
            rows.append(row)
            if u is None or not np.all(np.isfinite(u)):
                break  # the status column says why
            steps_hx.append((k, h, np.asarray(u, dtype=float)))
            q = pin.integrate(robot.model, q, u * dt)
            if not np.all(np.isfinite(q)):  # e.g. u ~ 1e154 returned as "optimal"
                row["status"] = "diverged"
                break
            traj.append(q.copy())
    df = pd.DataFrame(rows)
    if certify:
        df["certified"], df["certify_reason"], df["x_attains"] = None, "", None
        for (k, _, _), res in zip(steps_hx, certify_steps([(h, u) for _, h, u in steps_hx], int(certify))):
            df.loc[df["step"] == k, ["certified", "certify_reason", "x_attains"]] = [
                res["certified"], res["reason"], res.get("attains")]
    return ScenarioRun(scenario, solver, mode, df, np.array(traj), steps_hx)


def certify_steps(problems: list, workers: int = 2) -> list[dict]:
    """The exact certificate of each (hierarchy, x) of ``problems``
    (:func:`hikbench.bench.harness.worker.certify_point`: ``certified``, ``reason``, and where
    certified ``attains``), in ``workers`` fresh processes (spawned: no state of the caller's),
    in order."""
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    from hikbench.bench.harness.worker import certify_point

    if not problems:
        return []
    if workers < 1:
        raise HikbenchError(f"certify: workers must be >= 1; got {workers}")
    with ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn")) as pool:
        chunk = max(1, len(problems) // (8 * workers))
        return list(pool.map(certify_point, *zip(*problems), chunksize=chunk))


def _maker(scenario: Scenario, solver: str, options: dict, warm_start: str | None):
    """``(make, mode)``: a function building one solver object (a registered or
    ``module:Class`` solver, or a scenario controller on the scenario's stack,
    bench/scenarios/controllers.py) and the run's warm-start mode."""
    if is_controller(solver):
        return (lambda: build_controller(solver, scenario.stack, **options)), NO_WARM_START
    info = solver_info(solver)
    default = warm_start_default(info)
    if default is None:
        return (lambda: registry.build(info, **options)), NO_WARM_START
    if warm_start is not None:  # solvers with the HCOD warm-start modes (none / stage / time)
        options["warm_start"] = warm_start
    return (lambda: registry.build(info, **options)), str(options.get("warm_start", default))


def _prepare(solvers: list, q: np.ndarray) -> None:
    """Untimed: each scenario controller takes q and the step's targets (solvers: nothing)."""
    for slv in solvers:
        if isinstance(slv, Controller):
            slv.prepare(q)


def _timed_calls(solvers: list, h) -> tuple[SolveResult, list[float], bool]:
    """Each solver object solves ``h`` once, timed (s; GC off around each call
    only, as in the harness, bench/harness/timing.py), the first first. Returns
    the first's result, the times, and whether every result is the first's."""
    times, results = [], []
    for slv in solvers:
        gc.disable()
        try:
            t0 = time.perf_counter_ns()
            res = _solve(slv, h)
            times.append((time.perf_counter_ns() - t0) * 1e-9)
        finally:
            gc.enable()
        results.append(res)
    first = results[0]
    return first, times, all(_same_answer(first, r) for r in results[1:])


def _same_answer(a: SolveResult, b: SolveResult) -> bool:
    """Same status, counts and x (bit for bit, or both None)."""
    same_x = (a.x is None and b.x is None) or (a.x is not None and b.x is not None and np.array_equal(a.x, b.x))
    return same_x and (a.status, a.iterations, a.activations, a.deactivations) == (
        b.status, b.iterations, b.activations, b.deactivations)


def _changes(before: np.ndarray | None, now: np.ndarray | None) -> dict:
    """active_rows, rows_entered, rows_left of a step (None where unknown:
    no u, or no previous step, or another number of rows)."""
    out = {"active_rows": None if now is None else int(now.sum()), "rows_entered": None, "rows_left": None}
    if before is not None and now is not None and before.shape == now.shape:
        out.update(rows_entered=int((now & ~before).sum()), rows_left=int((before & ~now).sum()))
    return out


def _solve(slv, h) -> SolveResult:
    """``slv.solve(h)``; an exception escaping from the solver (a user's
    ``file.py:Class``), or an answer that breaks the contract
    (:func:`hikbench.solvers.base.checked_result`), is returned as status ``error`` with
    its type and message."""
    try:
        return checked_result(slv.solve(h), h, slv)
    except Exception as err:  # noqa: BLE001 - a crashing solver ends its run with a status row
        return SolveResult(None, ERROR, reason=f"{type(err).__name__}: {err}")
