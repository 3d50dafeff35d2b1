"""Cascades of generic QPs (Kanoun et al., ref. [8] of the ICRA 2010 paper).

Level k of a hierarchy is solved as one QP in ``z = (x, w_k)``, shapes
x (n,), w_k (m_k,) (one slack per non-free row of level k):

    min_{x, w_k}  1/2 ||w_k||^2 + eps/2 ||x||^2
    s.t.          lower_k <= A_k x - w_k <= upper_k          (level k, eq. (34) of ICRA 2010)
                  frozen rows of the levels j < k            (eq. (35))

``eps`` is a tiny regularisation (option ``regularization``, default the backend's row of
:data:`hikbench.solvers._qp_backends.SETTINGS`, 1e-12 but for highs and piqp at ``low``): it makes the Hessian
positive definite for backends that need it; its effect on the optimal slack
is of order ``eps ||x||^2``. It does not make x the minimum-norm solution:
at 1e-12 it is below the backends' tolerances (measured: verified
answers 10-80 % above the minimum norm on most underdetermined problems, up
to 100x with quadprog and 1e11x with clarabel and cvxpy on a problem whose
levels leave 19 free directions). The ``x_norm`` column shows it.

After level k is solved, its achieved slack is recomputed from x,
``w_k* = A_k x - clip(A_k x, lower_k, upper_k)`` (so x is feasible for the
frozen rows by construction), and the level is frozen for the levels below
by one of three modes (option ``freeze``; its default, like those of ``tolerances``,
``regularization`` and ``max_iter``, is the backend's row of
:data:`hikbench.solvers._qp_backends.SETTINGS` at the option ``accuracy``, chosen by a sweep):

* ``"shift"`` (Kanoun): ``lower_k + w_k* <= A_k x <= upper_k + w_k*``;
* ``"equality"``: rows with ``|w_k*| > slack_tol`` become equalities at their
  achieved value ``A_k x = A_k x*``; the other rows keep their own bounds;
* ``"relaxed"``: the shifted bounds widened by ``delta`` (option
  ``relax_delta``; default ``NOMINAL_TOL[tolerances]``):
  ``lower_k + w_k* - delta <= A_k x <= upper_k + w_k* + delta``.

``slack_tol`` defaults to ``NOMINAL_TOL[tolerances]``. Free rows are dropped.
No final minimum-norm stage is run: x is a lexicographic optimum, not the
minimum-norm one (nullspace-svd / nullspace-cod and hcod are).

Failures come back as statuses naming the level: ``infeasible_level`` (the
backend found no solution of the QP of level k > 0 once levels 0..k-1 are
frozen: reported infeasible, or its status is not passed on by qpsolvers;
the reason says whether the QP is really infeasible or whether ``x`` of
level k-1 certifies it feasible and the backend failed, e.g. at a degenerate
vertex with more frozen rows active than variables), ``error`` (the backend
raised; the reason carries the exception), ``numerical_failure`` (NaN in the backend's x, a numerical-error
status, or no solution at level 0 without a status), ``max_iterations`` (the
backend's iteration cap). A backend that stops "inaccurate" (OSQP solved
inaccurate, Clarabel AlmostSolved) is accepted; those levels are listed in
``info["inaccurate_levels"]`` — the verification judges the result.
``build_time_s`` is the assembly of the level QPs (dense blocks, CSC
conversion); ``solve_time_s`` the ``qpsolvers.solve_problem`` calls (the
backend's own set-up and factorisation included). On failure x is the point
reached after the last successful level (None if level 0 failed).
"""

from __future__ import annotations

import time
import warnings
from typing import ClassVar

import numpy as np
import scipy.sparse as spa

from hikbench.solvers.errors import SolverOptionError
from hikbench.problems.hierarchy import Hierarchy
from hikbench.solvers import _qp_backends as tables
from hikbench.solvers.base import (
    ERROR,
    INFEASIBLE_LEVEL,
    MAX_ITERATIONS,
    NUMERICAL_FAILURE,
    OPTIMAL,
    Solver,
    SolveResult,
)
from hikbench.solvers.info import SolverInfo
from hikbench.solvers.options import check_choice, check_int, check_number

__all__ = ["FREEZE_MODES", "CascadeBase", "QPSolversCascade", "freeze_level", "level_qp"]

FREEZE_MODES = ("shift", "equality", "relaxed")


def freeze_level(mode: str, A_k, lower_k, upper_k, x, slack_tol: float, delta: float):
    """Bounds that freeze level k at x, shapes (m_k,) each (see module doc).

    Returns ``(lower, upper, w)`` with w the achieved signed slack
    ``A_k x - clip(A_k x, lower_k, upper_k)``."""
    r = A_k @ x
    w = r - np.clip(r, lower_k, upper_k)
    if mode == "shift":  # -inf + w stays -inf: a one-sided row stays one-sided
        return lower_k + w, upper_k + w, w
    if mode == "relaxed":
        return lower_k + w - delta, upper_k + w + delta, w
    nonzero = np.abs(w) > slack_tol  # "equality": pin the violated rows, keep the others' bounds
    return np.where(nonzero, r, lower_k), np.where(nonzero, r, upper_k), w


def level_qp(A_f, lower_f, upper_f, A_k, lower_k, upper_k, eps: float):
    """Dense QP of one level in ``z = (x, w_k)``, shape (n + m_k,).

    Returns ``P, G, h, Aeq, beq`` for ``min 1/2 z^T P z s.t. G z <= h,
    Aeq z = beq`` (None for an empty block): the frozen rows ``(A_f, 0)`` and
    the level rows ``(A_k, -I)``; a row with ``lower == upper`` is an
    equality, each finite side of any other row one inequality."""
    n, m = A_k.shape[1], A_k.shape[0]
    P = np.diag(np.concatenate([np.full(n, eps), np.ones(m)]))
    C = np.vstack([np.hstack([A_f, np.zeros((A_f.shape[0], m))]), np.hstack([A_k, -np.eye(m)])])
    lo = np.concatenate([lower_f, lower_k])
    up = np.concatenate([upper_f, upper_k])
    eq = lo == up
    fu = np.isfinite(up) & ~eq
    fl = np.isfinite(lo) & ~eq
    G = np.vstack([C[fu], -C[fl]])
    h = np.concatenate([up[fu], -lo[fl]])
    return (P, G if G.shape[0] else None, h if h.shape[0] else None,
            C[eq] if eq.any() else None, lo[eq] if eq.any() else None)


def _no_solution(backend: str, text: str, h: Hierarchy, k: int, A_f, lower_f, upper_f, x_prev) -> str:
    """Reason of a level k > 0 without a solution from the backend. The
    level's own rows have slacks, so its QP is feasible exactly when the
    frozen rows of levels 0..k-1 are; ``x_prev`` (level k-1's solution, shape
    (n,)) is a feasibility certificate when it satisfies them. The reason
    says which case it is, and for a feasible QP how many frozen rows are
    active at ``x_prev`` against n (more than n: a degenerate vertex, which
    active-set backends cannot always handle). Level 0 (x_prev None) is
    always feasible. A_f stacks the non-free rows of h's levels 0..k-1."""
    if x_prev is None:
        return f"backend {backend} found no solution (status {text}) of a feasible QP (level 0 has slacks)"
    r = A_f @ x_prev
    # rounding scale of each frozen row at x_prev: |a| |x| + |bound| (finite bounds)
    scale = np.abs(A_f) @ np.abs(x_prev) + np.maximum(np.abs(np.where(np.isfinite(lower_f), lower_f, 0.0)),
                                                      np.abs(np.where(np.isfinite(upper_f), upper_f, 0.0)))
    tol = 1e-9 * (1.0 + scale)
    below, above = lower_f - r, r - upper_f
    excess = np.maximum(below, above)
    if np.any(excess > tol):
        worst = int(np.argmax(excess / tol))
        i = int(np.flatnonzero(~h.is_free[:h.starts[k]])[worst])  # A_f's rows in h
        lev = int(h.level[i])
        row = i - int(h.starts[lev])
        return (f"infeasible after freezing levels 0..{k - 1} (backend {backend} found no solution, status "
                f"{text}; x of level {k - 1} violates the frozen row {row} of level {lev} by "
                f"{excess[worst]:.1e})")
    viol = float(np.max(np.maximum(excess, 0.0), initial=0.0))
    active = int(np.count_nonzero((below >= -tol) | (above >= -tol)))
    n = x_prev.shape[0]
    degenerate = " (more than n: degenerate)" if active > n else ""
    return (f"backend {backend} found no solution (status {text}) of a feasible QP: x of level {k - 1} "
            f"satisfies the frozen rows of levels 0..{k - 1} to {viol:.1e}, with {active} of them active "
            f"on n = {n} variables{degenerate}")


class CascadeBase(Solver):
    """The cascade loop, the freezing and the failure statuses; subclasses
    implement :meth:`_solve_level` for one modelling layer / backend."""

    supports_inequalities = True
    backend: ClassVar[str] = ""

    def __init__(self, freeze: str | None = None, accuracy: str = "high", regularization: float | None = None,
                 max_iter: int | None = None, relax_delta: float | None = None,
                 slack_tol: float | None = None, tolerances: str | None = None):
        accuracy = check_choice(self.name, "accuracy", accuracy, tables.PROFILES)
        chosen = tables.SETTINGS[self.backend][accuracy]  # (the sweep's row: each option None takes it)
        freeze = check_choice(self.name, "freeze", chosen["freeze"] if freeze is None else freeze, FREEZE_MODES)
        tolerances = check_choice(self.name, "tolerances", chosen["tolerances"] if tolerances is None
                                  else tolerances, tables.PROFILES)
        regularization, relax_delta, slack_tol = (
            check_number(self.name, opt, val, low=0, none_ok=True)
            for opt, val in (("regularization", regularization), ("relax_delta", relax_delta),
                             ("slack_tol", slack_tol)))
        max_iter = check_int(self.name, "max_iter", max_iter, none_ok=True)
        if max_iter is not None and self.backend in tables.MAX_ITER_NAME and \
                tables.MAX_ITER_NAME[self.backend] is None:
            raise SolverOptionError(f"{self.name}: option max_iter: backend {self.backend} has no "
                                    "iteration limit")
        self.freeze = freeze
        self.accuracy = accuracy
        self.tolerances = tolerances
        self.eps = chosen["regularization"] if regularization is None else regularization
        self.max_iter = chosen["max_iter"] if max_iter is None else max_iter
        tol = tables.NOMINAL_TOL[tolerances]
        self.delta = tol if relax_delta is None else relax_delta
        self.slack_tol = tol if slack_tol is None else slack_tol
        self._last_z: dict[int, np.ndarray] = {}

    def settings(self) -> dict:
        """The settings this cascade runs with, every default resolved (column ``solver_settings``)."""
        return {"backend": self.backend, "accuracy": self.accuracy, "tolerances": self.tolerances,
                "freeze": self.freeze, "regularization": self.eps, "max_iter": self._max_iter(),
                "relax_delta": self.delta, "slack_tol": self.slack_tol}

    def _max_iter(self) -> int | None:
        """The iteration cap passed to the backend (None: its own)."""
        return self.max_iter if self.max_iter is not None else tables.DEFAULT_MAX_ITER.get(self.backend)

    def reset(self) -> None:
        self._last_z = {}

    def _solve_level(self, k: int, A_f, lower_f, upper_f, A_k, lower_k, upper_k, z0):
        """Solve the QP of level k. Returns ``(outcome, z, iterations, build_s,
        solve_s, text)``; outcome is ``"ok"``, ``"inaccurate"``, ``"infeasible"``,
        ``"max_iterations"`` or ``"unknown"``; exceptions propagate."""
        raise NotImplementedError

    def solve(self, hierarchy: Hierarchy) -> SolveResult:
        self.check_hierarchy(hierarchy)
        h = hierarchy
        n = h.n
        x = np.zeros(n)
        A_f = np.zeros((0, n))
        lower_f = np.zeros(0)
        upper_f = np.zeros(0)
        iters: list[int] = []
        build_s = solve_s = 0.0
        inaccurate: list[int] = []
        info = {"backend": self.backend, "freeze": self.freeze, "accuracy": self.accuracy,
                "tolerances": self.tolerances}
        if n == 0:  # x in R^0 is decided; cvxpy cannot model a Variable(0)
            return SolveResult(x=x, status=OPTIMAL, iterations_per_level=(0,) * h.depth, info=info)

        def fail(status: str, k: int, why: str, x_out) -> SolveResult:
            info["failed_level"] = k
            return SolveResult(x=x_out, status=status, reason=f"{self.name}: level {k}: {why}",
                               iterations=sum(iters),
                               iterations_per_level=tuple(iters + [0] * (h.depth - len(iters))),
                               build_time_s=build_s, solve_time_s=solve_s, info=info)

        for k in range(h.depth):
            s = h.level_rows(k)
            keep = ~h.is_free[s]
            A_k, lower_k, upper_k = h.A[s][keep], h.lower[s][keep], h.upper[s][keep]
            if A_k.shape[0] == 0:
                iters.append(0)
                continue
            z0 = self._last_z.get(k)
            if z0 is None or z0.shape[0] != n + A_k.shape[0]:
                r = A_k @ x
                z0 = np.concatenate([x, r - np.clip(r, lower_k, upper_k)])
            x_prev = x if k else None
            try:
                outcome, z, it, b_s, s_s, text = self._solve_level(k, A_f, lower_f, upper_f, A_k, lower_k,
                                                                upper_k, z0)
            except Exception as err:  # noqa: BLE001 - any backend exception becomes a status with its text
                return fail(ERROR, k, f"backend {self.backend} raised {type(err).__name__}: {err}", x_prev)
            build_s += b_s
            solve_s += s_s
            iters.append(it)
            if z is not None and not np.all(np.isfinite(z)):
                return fail(NUMERICAL_FAILURE, k, f"backend {self.backend} returned NaN/inf (status {text})",
                            x_prev)
            if outcome == "max_iterations":
                x_out = z[:n] if z is not None else x_prev
                return fail(MAX_ITERATIONS, k, f"backend {self.backend} hit its iteration limit "
                                               f"({it} iterations, status {text})", x_out)
            if outcome == "infeasible" or (outcome == "unknown" and k > 0):
                why = _no_solution(self.backend, text, h, k, A_f, lower_f, upper_f, x_prev)
                return fail(INFEASIBLE_LEVEL, k, why, x_prev)
            if outcome in ("unknown", "numerical") or z is None:
                return fail(NUMERICAL_FAILURE, k, f"backend {self.backend} found no solution (status {text})",
                            x_prev)
            if outcome == "inaccurate":
                inaccurate.append(k)
            self._last_z[k] = z
            x = z[:n]
            lo, up, _ = freeze_level(self.freeze, A_k, lower_k, upper_k, x, self.slack_tol, self.delta)
            A_f = np.vstack([A_f, A_k])
            lower_f = np.concatenate([lower_f, lo])
            upper_f = np.concatenate([upper_f, up])
        if inaccurate:
            info["inaccurate_levels"] = inaccurate
        return SolveResult(x=x, status=OPTIMAL, iterations=sum(iters), iterations_per_level=tuple(iters),
                           build_time_s=build_s, solve_time_s=solve_s, info=info)


class QPSolversCascade(CascadeBase):
    """Cascade whose levels are solved by a qpsolvers backend (class attribute ``backend``)."""

    def _solve_level(self, k, A_f, lower_f, upper_f, A_k, lower_k, upper_k, z0):
        import qpsolvers

        t0 = time.perf_counter()
        P, G, hv, Aeq, beq = level_qp(A_f, lower_f, upper_f, A_k, lower_k, upper_k, self.eps)
        if tables.SPARSE[self.backend]:
            P, G, Aeq = (None if M is None else spa.csc_matrix(M) for M in (P, G, Aeq))
        problem = qpsolvers.Problem(P, np.zeros(P.shape[0]), G, hv, Aeq, beq)
        opts = dict(tables.ACCURACY[self.backend][self.tolerances])
        max_iter = self._max_iter()
        if max_iter is not None:
            opts[tables.MAX_ITER_NAME[self.backend]] = int(max_iter)
        initvals = z0 if tables.WARM_START[self.backend] else None
        t1 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # statuses are read from the Solution, not from warnings
            sol = qpsolvers.solve_problem(problem, solver=self.backend, initvals=initvals, verbose=False,
                                          **opts)
        t2 = time.perf_counter()
        it = tables.iterations(self.backend, sol)
        z = None if sol.x is None else np.asarray(sol.x, dtype=float)
        if z is not None and z.shape != (P.shape[0],):
            z = None
        if sol.found:
            return "ok", z, it, t1 - t0, t2 - t1, "solved"
        outcome, text = tables.status_outcome(self.backend, sol)
        return outcome, (z if outcome in ("inaccurate", "max_iterations") else None), it, t1 - t0, t2 - t1, text


def _make(backend: str) -> type[QPSolversCascade]:
    cls = type(f"Cascade_{backend}", (QPSolversCascade,), {
        "__module__": __name__,  # (else type() takes the caller's frame: 'abc')
        "name": f"cascade-{backend}",
        "description": f"cascade of QPs (Kanoun et al.), one QP per level solved by {backend} via qpsolvers",
        "backend": backend,
        "supports_warm_start": tables.WARM_START[backend],
        "__doc__": f"Cascade of QPs solved by {backend}.",
    })
    return cls


def _installed() -> list[str]:
    try:
        import qpsolvers
    except ModuleNotFoundError:
        return []
    return [b for b in tables.BACKENDS if b in qpsolvers.available_solvers]


CLASSES = {b: _make(b) for b in tables.BACKENDS}
SOLVERS = [SolverInfo.of(CLASSES[b]) for b in _installed()]
MISSING = {f"cascade-{b}": f"qpsolvers backend {b!r} is not installed; install it with: {tables.INSTALL[b]}"
           for b in tables.BACKENDS if b not in _installed()}
