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
x_gap_to_first             only in a run of several warm-start modes interleaved
                           (:func:`run_interleaved`, ``hikbench scenario`` with several
                           ``--warm-start`` modes): max |u - u of the first mode| at the step,
                           whose u the loop follows (0 where they agree)
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
import time
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
import pinocchio as pin
from threadpoolctl import threadpool_limits

from hikbench.bench.scenarios.controllers import Controller, build_controller
from hikbench.bench.specs import CONTROLLER, SolverSpec, warm_start_default, warm_start_modes
from hikbench.problems.errors import HikbenchError
from hikbench.problems.robots.kinematics import KinematicState
from hikbench.problems.robots.scenarios import Scenario
from hikbench.solvers import registry
from hikbench.solvers.base import ERROR, SolveResult, checked_result
from hikbench.problems.verify import level_norms

__all__ = ["ACTIVE_RTOL", "COLUMNS", "NO_WARM_START", "REPEAT", "ScenarioRun", "active_rows", "certify_steps",
           "run_interleaved", "run_scenario", "warm_start_default"]

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
        (:class:`hikbench.bench.specs.SolverSpec`), or a scenario
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
    return run_interleaved(scenario, solver, [warm_start], options, steps=steps, repeat=repeat, resolve=resolve,
                           certify=certify, on_step=on_step)[0]


def run_interleaved(scenario: Scenario, solver: str, modes: list, options: dict | None = None, *,
                    steps: int | None = None, repeat: int = REPEAT, resolve: bool = False, certify: int = 0,
                    on_step=None) -> list[ScenarioRun]:
    """Run ``scenario`` once per warm-start mode of ``modes`` (None: the solver's default),
    interleaved step by step in one process: at step k every mode's ``repeat`` objects solve
    the step's hierarchy, the modes taken in turn from mode ``k mod len(modes)`` on, so that a
    drift of the machine's speed falls on every mode alike and the ratio of two modes is the
    solver's. The loop follows the first mode's u (the controller's); the other modes solve the
    same hierarchies, each on its own objects (so each holds its own warm-start state), and
    with several modes each row has ``x_gap_to_first``, max |u - u of the first mode| (0 where
    they agree; empty where either has no u). One :class:`ScenarioRun` per mode, in the order
    of ``modes``; the other parameters as in :func:`run_scenario`."""
    options = dict(options or {})
    if not modes:
        raise HikbenchError("run_interleaved: expected at least one warm-start mode")
    makers = [_maker(scenario, solver, dict(options), mode) for mode in modes]  # (each its own options)
    steps = scenario.steps if steps is None else int(steps)
    if steps < 1:
        raise HikbenchError(f"steps must be >= 1; got {steps}")
    if int(repeat) < 1:
        raise HikbenchError(f"repeat must be >= 1; got {repeat}")
    groups = [[make() for _ in range(int(repeat))] for make, _ in makers]  # [m][0]: mode m's controller
    robot, stack, dt = scenario.robot, scenario.stack, scenario.dt
    for make, _ in makers:  # warm-up (untimed, on a separate object): numba compilation, backend caches
        scenario.reset()
        state = KinematicState(robot, scenario.q_init)
        scenario.targets_at(0.0, state)
        first = make()
        _prepare([first], scenario.q_init)
        _solve(first, stack.hierarchy(scenario.q_init, state))  # (step 0 reports a failure)
    scenario.reset()
    q = scenario.q_init.copy()
    traj, rows = [q.copy()], [[] for _ in modes]
    before, kept = [None] * len(modes), [[] for _ in modes]  # kept[m]: (k, h, u) to certify
    with threadpool_limits(limits=1):
        for k in range(steps):
            state = KinematicState(robot, q)
            scenario.targets_at(k * dt, state)
            h = stack.hierarchy(q, state)
            results = [None] * len(modes)
            for m in [(k + j) % len(modes) for j in range(len(modes))]:
                _prepare(groups[m], q)
                res, times, agree = _timed_calls(groups[m], h)
                again = min(_timed_calls(groups[m], h)[1]) if resolve else None
                results[m] = res
                rows[m].append(_step_row(scenario, solver, makers[m][1], k, q, h, res, state, times, agree, again))
                before[m] = _record_changes(rows[m][-1], before[m], h, res.x)
            if on_step is not None:
                on_step(k, h, results[0])
            if len(modes) > 1:
                for m, res in enumerate(results):
                    rows[m][-1]["x_gap_to_first"] = _gap(res.x, results[0].x)
            for m, res in enumerate(results):
                if _finite(res.x):
                    kept[m].append((k, h, np.asarray(res.x, dtype=float)))
            u = results[0].x
            if not _finite(u):
                break  # the status column says why
            q = pin.integrate(robot.model, q, u * dt)
            if not np.all(np.isfinite(q)):  # e.g. u ~ 1e154 returned as "optimal"
                rows[0][-1]["status"] = "diverged"  # (the loop's u; the other modes' rows keep theirs)
                break
            traj.append(q.copy())
    runs = []
    for m, (_, mode) in enumerate(makers):
        df = pd.DataFrame(rows[m])
        if certify:
            _certify_records(df, kept[m], int(certify))
        runs.append(ScenarioRun(scenario, solver, mode, df, np.array(traj), kept[m]))
    return runs


def _step_row(scenario: Scenario, solver: str, mode: str, k: int, q, h, res: SolveResult, state, times: list,
              agree: bool, again: float | None) -> dict:
    """One step's record (module docstring): timing, counts, status, task errors, level norms."""
    robot, u = scenario.robot, res.x
    row = {"solver": solver, "warm_start": mode, "step": k, "time_s": k * scenario.dt,
           "solve_time_min_s": min(times), "solve_time_first_s": times[0], "resolve_time_min_s": again,
           "repeat": len(times), "repeats_agree": agree, "iterations": int(res.iterations),
           "activations": int(res.activations), "deactivations": int(res.deactivations),
           "active_rows": None, "rows_entered": None, "rows_left": None, "status": res.status,
           "reason": res.reason, "min_joint_limit_margin": float(np.min(robot.limit_margin(q), initial=np.inf))}
    # (a velocity task without u, the solver having returned none: an empty cell)
    row.update({f"err_{name}": np.nan if v is None else v for name, v in scenario.stack.errors(q, u, state).items()})
    norms = level_norms(h, u) if u is not None else np.full(h.depth, np.nan)
    row.update({f"level_norm_{name}": float(v) for name, v in zip(h.names, norms)})
    return row


def _record_changes(row: dict, before: np.ndarray | None, h, u) -> np.ndarray | None:
    """Fill the row's active_rows, rows_entered, rows_left; returns the step's active rows."""
    now = active_rows(h, u) if _finite(u) else None
    row.update(_changes(before, now))
    return now


def _certify_records(df: pd.DataFrame, kept: list, workers: int) -> None:
    """Columns certified, certify_reason, x_attains of each step of ``kept`` ((k, h, u))."""
    df["certified"], df["certify_reason"], df["x_attains"] = None, "", None
    for (k, _, _), res in zip(kept, certify_steps([(h, u) for _, h, u in kept], workers)):
        df.loc[df["step"] == k, ["certified", "certify_reason", "x_attains"]] = [
            res["certified"], res["reason"], res.get("attains")]


def _finite(u) -> bool:
    return u is not None and bool(np.all(np.isfinite(u)))


def _gap(u, first) -> float | None:
    """max |u - first|, None where either is missing or not finite."""
    if not (_finite(u) and _finite(first)) or np.shape(u) != np.shape(first):
        return None
    return float(np.max(np.abs(np.asarray(u) - np.asarray(first)), initial=0.0))


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
    spec = SolverSpec.parse(solver, controllers=True)
    if spec.kind == CONTROLLER:
        return (lambda: build_controller(solver, scenario.stack, **options)), NO_WARM_START
    info = spec.info()
    [mode] = warm_start_modes(info, [] if warm_start is None else [warm_start], options.get("warm_start"))
    if mode is None:
        return (lambda: registry.build(info, **options)), NO_WARM_START
    if warm_start is not None:  # solvers with the HCOD warm-start modes (none / stage / time)
        options["warm_start"] = warm_start
    return (lambda: registry.build(info, **options)), str(mode)


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
