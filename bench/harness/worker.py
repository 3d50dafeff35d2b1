"""The worker side of a solve: build the solver, time it, return plain data.

Runs inside the isolated worker process (``python -m hikbench.bench.harness.isolation``), for
external programs too (``"kind": "external"``, with ``"program_timeout"``: the program is started,
and its answer read and checked, here). A job is a dict::

    {"kind": "solve" | "external" | "generate" | "yardstick" | "candidate" | "certify", "hierarchy": Hierarchy, "solver": spec,
     "options": {...}, "mode": "cold" | "warm", "repeat": R, "warmup": W,
     "samples": S or None, "sample_time": T}      # (hikbench.bench.harness.timing.time_solves)

A ``generate`` job (with ``"spec"``, a ProblemSpec of a user's ``module:function`` family) returns
its ``hierarchy``. A ``yardstick`` job returns the independent yardstick's point, a ``candidate`` job (with
``"solver"``) one cold solve's point of a registry solver (:func:`candidate_point`: ``hcod``'s, the
yardstick's other candidate), a ``certify`` job (with ``"x"``) the exact certificate of x
(:func:`certify_point`).

``spec`` is a registry name or ``module:Class`` / ``file.py:Class`` (a
:class:`~hikbench.solvers.base.Solver` subclass or any factory), which is how tests
inject hanging or crashing solvers without touching the registry; it is parsed by
:class:`hikbench.bench.specs.SolverSpec`.
"""

from __future__ import annotations

import gc
import os
import socket
import traceback

import numpy as np

from hikbench.bench.specs import SolverSpec
from hikbench.problems.errors import HikbenchError
from hikbench.solvers import registry
from hikbench.solvers.base import ERROR, SolveResult

__all__ = ["candidate_point", "certify_point", "exception_text", "execute"]

_frozen: set[str] = set()  # solvers whose first solve in this process is behind gc.freeze()


def _result_dict(res: SolveResult, samples_ns) -> dict:
    return {
        "status": res.status, "reason": res.reason,
        "x": None if res.x is None else np.asarray(res.x, dtype=float),
        "iterations": int(res.iterations), "iterations_per_level": [int(i) for i in res.iterations_per_level],
        "activations": int(res.activations), "deactivations": int(res.deactivations),
        "flops": None if res.flops is None else int(res.flops),
        "build_time_s": float(res.build_time_s), "solve_time_s": float(res.solve_time_s),
        "samples_ns": [int(s) for s in samples_ns],
    }


def candidate_point(h, solver: str) -> dict:
    """One cold solve of h by the registry solver ``solver`` (default options): ``status``
    optimal and ``x`` where it gave a finite x with status optimal, else ``status`` error and
    the ``reason``."""
    res = registry.create(solver).solve(h)
    if res.x is not None and res.status == "optimal" and np.all(np.isfinite(res.x)):
        return {"status": "optimal", "reason": "", "x": np.asarray(res.x, dtype=float)}
    return {"status": ERROR, "reason": f"{res.status} {res.reason}".strip(), "x": None}


def certify_point(h, x: np.ndarray) -> dict:
    """The exact certificate of x (:func:`hikbench.problems.exact.certify`): ``certified``,
    ``reason`` (why not), and where certified ``x_cert`` (the exact optimum x*, rounded: the
    yardstick, whatever x's level norms are; a point within a tolerance of x* is not x*, and a
    tolerance that grew with ``||x||`` hid a gap of 65 of x above it), ``attains`` (no level
    of x above x*'s beyond the ``high`` profile, hikbench.problems.verify.judge) and
    ``above_level`` (the first level of x above x*'s, where it does not attain it) and
    ``level_norms`` (x*'s exact level norms, rounded).
    ``x_cert`` is None, and ``unrepresentable_level`` the first level where it fails, when the
    rounded x* does not hold the certificate's exact level norms within the ``high``
    tolerance at x (an x* of norm 5e16 on levels rank-deficient only to rounding): no double
    reaches that optimum, and x stays the yardstick."""
    from hikbench.problems.exact import certify
    from hikbench.problems.verify import PROFILES, judge, level_norms, level_tolerances

    cert = certify(h, x)
    out = {"status": "optimal", "certified": bool(cert.certified), "reason": cert.reason}
    if cert.certified:
        xc = np.asarray(cert.x, dtype=float)
        rtol = PROFILES["high"].rtol
        off = np.flatnonzero(~(np.abs(level_norms(h, xc) - np.asarray(cert.level_norms, dtype=float))
                               <= level_tolerances(h, x, rtol)))  # (at x's scale: x* may be huge)
        v = judge(h, x, xc, rtol)
        out.update(x_cert=None if off.size else xc, unrepresentable_level=int(off[0]) if off.size else None,
                   level_norms=[float(v) for v in cert.level_norms],
                   attains=v.lower != "b", above_level=None if v.lower != "b" else int(v.level))
    return out


def execute(job: dict, notify=None) -> dict:
    """Run one job; never raises for a solver failure (the reason is returned).

    A solve job starts with the solver's ``warmup()`` (if it has one: all its
    kernels compiled) and one untimed solve on a fresh solver (JIT
    compilation, imports), then calls ``notify()`` so that the isolated
    worker's caller can switch from the first-solve allowance to the job
    timeout (bench/harness/isolation.py). The job's ``warmup`` discarded solves come
    after that, right before the timed ones (:func:`hikbench.bench.harness.timing.time_solves`)."""
    base = {"host": socket.gethostname(), "pid": os.getpid()}
    h = job["hierarchy"]
    try:
        if job["kind"] == "yardstick":
            from hikbench.solvers.yardstick import yardstick_solution
            x = yardstick_solution(h)
            return {**base, "status": "optimal", "reason": "", "x": np.asarray(x, dtype=float)}
        if job["kind"] == "candidate":
            return {**base, **candidate_point(h, job["solver"])}
        if job["kind"] == "certify":
            return {**base, **certify_point(h, np.asarray(job["x"], dtype=float))}
        if job["kind"] == "generate":  # (a user's module:function family, here: one that hangs is killed)
            from hikbench.bench.suites.problemset import generate
            try:
                return {**base, "status": "optimal", "reason": "", "x": None, "hierarchy": generate(job["spec"])}
            except HikbenchError as err:  # (the family's own fault, named: the run's one-line error)
                return {**base, "status": ERROR, "reason": str(err), "x": None, "user_error": True}
        if job["kind"] == "external":  # (the program's answer is read and checked here, not by the run)
            from hikbench.bench.harness.external import run_external
            return {**base, **run_external(job, float(job["program_timeout"]))}
        from hikbench.bench.harness.timing import SAMPLE_TIME, time_solves
        make = SolverSpec.parse(job["solver"]).factory(job.get("options", {}))
        first = make()
        if callable(getattr(first, "warmup", None)):  # (module:Class solvers need not derive from Solver)
            first.warmup()
        first.solve(h)
        if job["solver"] not in _frozen:
            # The first solve of a solver in this process compiles (numba) or imports what it
            # needs: some 480K long-lived objects after hcod's kernels, which the gc.collect()
            # before each job's timing (hikbench.bench.harness.timing.quiet_timing) would walk again: 0.3 s per
            # job of every solver after it. Frozen once, the collector skips them.
            gc.collect()
            gc.freeze()
            _frozen.add(job["solver"])
        if notify is not None:
            notify()
        calib = []
        if job.get("calibrate"):
            from hikbench.bench.harness.calibration import calibrate
            calib.append(calibrate(reps=3))
        # every warm-up solve in time_solves, after its gc.collect() and BLAS limit: the first
        # solve after them took 2-7x the median when the untimed first solve counted as one
        t = time_solves(make, h, repeat=int(job["repeat"]), mode=job["mode"], warmup=int(job["warmup"]),
                        samples=job.get("samples"), sample_time=job.get("sample_time", SAMPLE_TIME))
        out = {**base, **_result_dict(t.result, t.samples_ns)}
        if callable(getattr(first, "settings", None)):  # (module:Class solvers need not derive from Solver)
            out["settings"] = first.settings()
        if calib:
            out["calib_ns"] = min(calib[0], calibrate(reps=3))  # around the timed solves
        return out
    except (Exception, KeyboardInterrupt) as err:  # noqa: BLE001 - a failing job costs its row (status error + reason)
        # (KeyboardInterrupt too: this process has a session of its own, no terminal's Ctrl-C reaches
        # it; one raised here is the solver's own, and would end the worker with a traceback)
        tb = traceback.extract_tb(err.__traceback__)
        where = f" at {os.path.basename(tb[-1].filename)}:{tb[-1].lineno}" if tb else ""
        out = {**base, "status": ERROR, "reason": f"{exception_text(err)}{where}", "x": None,
               "samples_ns": []}
        if isinstance(err, HikbenchError):  # (a wrong option value: `solve` makes it its one-line user error)
            out["user_error"] = str(err)
        return out


def exception_text(err: BaseException) -> str:
    """``TypeName: message`` of a solver's exception, on one line; an exception whose ``str``
    itself raises is named with that failure instead of its message."""
    try:
        message = str(err)
    except Exception as inner:  # noqa: BLE001 - the solver's __str__ raises what it raises
        message = f"(its message cannot be shown: str() raised {type(inner).__name__})"
    return " ".join(f"{type(err).__name__}: {message}".split()) if message else type(err).__name__
