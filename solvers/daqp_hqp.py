"""DAQP's own hierarchical QP (Arnstrom et al.; ``daqp.solve(..., break_points=...)``, daqp >= 0.7).

One call of DAQP solves the whole hierarchy: level k's rows are soft while
level k is solved, then hard with their bounds moved by the slack found,
before level k + 1 (DAQP's ``src/hierarchical.c``):

    level k:  min_{x, s_k} 1/2 eps ||x||^2 + 1/(2 rho) ||s_k||^2
              s.t. lower_k <= D_k A_k x - s_k <= upper_k     (D_k: 1 / ||a_i|| per row)
                   the rows of levels j < k at their bounds moved by s_j*

shapes A_k (m_k, n), s_k (m_k,). DAQP normalises every row to unit norm
(its LDP scaling), so each level minimises its **row-normalised** slacks:
where a level's rows conflict and their norms differ, its optimum is that of
the hierarchy with each row divided by its norm
(:func:`hikbench.problems.hierarchy.row_normalised`), not that of the rows as
given. The solver says so (``judged_on = "row-normalised"``): the benchmark
judges its x against the yardstick of that hierarchy. Option
``normalised=False`` claims the rows as given instead (the same call: DAQP
normalises whatever it is given), for a user who wants the gap measured.

H must be positive definite: ``eps I`` (option ``eps``); ``H=None`` exits
-8. The slack weight ``rho`` (DAQP's ``rho_soft``) and the primal tolerance
(a slack below it is not moved into the bounds) set how closely levels are met:
DAQP's defaults (1e-6 both, ``accuracy="default"``) meet an equality level
to 6e-7..3e-6 and let the error grow down the hierarchy (5e-4 at level 5 of
the ``equality`` family); ``accuracy="high"`` (the default here, as for the
cascades) sets rho = 1e-9, primal_tol = 1e-9 (1e-10 stopped with exit 3 on the
``rank_deficient`` degenerate case, 1e-8 left the ``equality`` family 1e-7 above
its optimum).

Statuses from DAQP's exit flag: 1, 2 (optimal; 2: some soft slack nonzero)
-> ``optimal``; 3 (a level's LDP failed: x is the point before it) and -1 ->
``infeasible_level`` (3 with the iterations at ``iter_limit``: ``max_iterations``,
DAQP's hierarchical loop turns a level's -4 into 3); -4 -> ``max_iterations``; -8 -> ``unsupported``; the
others (-2 cycling, -3 unbounded, -5 nonconvex, -6 overdetermined initial
working set, -7 time limit) -> ``numerical_failure``; x None where DAQP
produced none. ``warm_start="time"`` passes the last call's multipliers
(DAQP's ``info["lam"]``) as its ``dual_start`` (the initial working set:
the rows whose multiplier is nonzero) when the problem has the same shape
and kinds of rows; ``"none"`` starts every call cold. (Its ``primal_start``,
the last x, took more iterations than a cold start on 8 of 9 random and
ik-like problems, ``dual_start`` fewer or as many on all 9.)
Free rows, zero rows (DAQP reports ``0 <= -1`` infeasible, exit -1; its
violation does not depend on x) and rowless levels are not passed.
"""

from __future__ import annotations

import time

import daqp
import numpy as np

from hikbench.problems.hierarchy import Hierarchy
from hikbench.solvers.base import (
    INFEASIBLE_LEVEL,
    MAX_ITERATIONS,
    NUMERICAL_FAILURE,
    OPTIMAL,
    ROW_NORMALISED,
    ROWS,
    UNSUPPORTED,
    Solver,
    SolveResult,
)
from hikbench.solvers.info import SolverInfo
from hikbench.solvers.options import check_bool, check_choice, check_int, check_number

__all__ = ["ACCURACY", "EXIT_STATUS", "SOLVERS", "DaqpHqp", "exit_status"]

WARM_STARTS = ("none", "time")
#: accuracy profile -> DAQP settings; "default" passes DAQP's own (rho_soft = primal_tol = 1e-6)
ACCURACY: dict[str, dict[str, float]] = {
    "high": {"rho_soft": 1e-9, "primal_tol": 1e-9},
    "default": {},
    "low": {"rho_soft": 1e-6, "primal_tol": 1e-5},
}
#: DAQP's exit flags (include/constants.h, src/hierarchical.c) -> (status, meaning)
EXIT_STATUS: dict[int, tuple[str, str]] = {
    1: (OPTIMAL, "optimal"),
    2: (OPTIMAL, "optimal, soft slacks nonzero"),
    3: (INFEASIBLE_LEVEL, "a level's QP failed; x is the point of the levels before it"),
    -1: (INFEASIBLE_LEVEL, "infeasible"),
    -2: (NUMERICAL_FAILURE, "cycling"),
    -3: (NUMERICAL_FAILURE, "unbounded"),
    -4: (MAX_ITERATIONS, "iteration limit"),
    -5: (NUMERICAL_FAILURE, "nonconvex"),
    -6: (NUMERICAL_FAILURE, "overdetermined initial working set"),
    -7: (NUMERICAL_FAILURE, "time limit"),
    -8: (UNSUPPORTED, "unsupported problem"),
}
_EQUALITY, _INEQUALITY = 5, 0  # DAQP's sense: immutable (equality), plain inequality
_INF = 1e30  # DAQP's infinity
DAQP_ITER_LIMIT = 10000  # DAQP's default iter_limit


def exit_status(exitflag: int, iterations: int, iter_limit: int) -> tuple[str, str]:
    """hikbench's status of DAQP's ``exitflag`` and what it means (:data:`EXIT_STATUS`; an
    unknown flag is a numerical failure). DAQP's hierarchical loop reports a level stopped
    by ``iter_limit`` (its -4) as 3: with ``iterations >= iter_limit`` that is ``max_iterations``."""
    if exitflag == 3 and iterations >= iter_limit:
        return MAX_ITERATIONS, f"a level stopped at the iteration limit, {iter_limit}"
    return EXIT_STATUS.get(exitflag, (NUMERICAL_FAILURE, "unknown exit flag"))


class DaqpHqp(Solver):
    """DAQP's hierarchical QP, one ``daqp.solve`` call per solve (module doc).

    Parameters
    ----------
    accuracy : {"high", "default", "low"}
        :data:`ACCURACY`: DAQP's ``rho_soft`` and ``primal_tol``.
    eps : float > 0
        H = eps I, shape (n, n) (default 1e-8).
    rho_soft, primal_tol, dual_tol : float > 0 or None
        DAQP's settings; None: the accuracy profile's (else DAQP's default).
    iter_limit : int or None
        DAQP's cap on active-set iterations over all levels (None: DAQP's 10000).
    normalised : bool
        True (default): claims the row-normalised hierarchy; False: the rows as given.
    warm_start : {"time", "none"}
    """

    name = "daqp-hqp"
    description = "DAQP's own hierarchical QP (soft levels hardened in turn), one daqp.solve call"
    supports_inequalities = True
    supports_warm_start = True
    strict = True

    def __init__(self, accuracy: str = "high", eps: float = 1e-8, rho_soft: float | None = None,
                 primal_tol: float | None = None, dual_tol: float | None = None,
                 iter_limit: int | None = None, normalised: bool = True, warm_start: str = "time"):
        accuracy = check_choice(self.name, "accuracy", accuracy, tuple(ACCURACY))
        self.daqp_settings = dict(ACCURACY[accuracy])  # (DAQP's own names)
        for opt, val in (("rho_soft", rho_soft), ("primal_tol", primal_tol), ("dual_tol", dual_tol)):
            val = check_number(self.name, opt, val, low=0, low_open=True, none_ok=True)
            if val is not None:
                self.daqp_settings[opt] = val
        iter_limit = check_int(self.name, "iter_limit", iter_limit, none_ok=True)
        if iter_limit is not None:
            self.daqp_settings["iter_limit"] = iter_limit
        self.eps = check_number(self.name, "eps", eps, low=0, low_open=True)
        self.judged_on = ROW_NORMALISED if check_bool(self.name, "normalised", normalised) else ROWS
        self.warm_start = check_choice(self.name, "warm_start", warm_start, WARM_STARTS)
        self._last: tuple | None = None  # (shape key, multipliers) of the last successful call

    def reset(self) -> None:
        self._last = None

    def settings(self) -> dict:
        """DAQP's settings passed (its defaults where not), H = eps I, the claim, the warm start."""
        return {"rho_soft": 1e-6, "primal_tol": 1e-6, "iter_limit": DAQP_ITER_LIMIT, **self.daqp_settings,
                "eps": self.eps, "judged_on": self.judged_on, "warm_start": self.warm_start}

    def solve(self, hierarchy: Hierarchy) -> SolveResult:
        self.check_hierarchy(hierarchy)
        h = hierarchy
        t0 = time.perf_counter()
        keep = ~h.is_free & np.any(h.A != 0.0, axis=1)  # (a zero row's violation does not depend on x)
        A = np.ascontiguousarray(h.A[keep])
        lower, upper = h.lower[keep], h.upper[keep]
        counts = np.bincount(h.level[keep], minlength=h.depth)
        if A.shape[0] == 0:  # nothing constrains x: its minimum norm
            return SolveResult(np.zeros(h.n), OPTIMAL, iterations_per_level=(0,) * h.depth)
        bp = np.concatenate([[0], np.cumsum(counts[counts > 0])]).astype(np.intc)
        sense = np.where(lower == upper, _EQUALITY, _INEQUALITY).astype(np.intc)
        bl = np.where(np.isfinite(lower), lower, -_INF)
        bu = np.where(np.isfinite(upper), upper, _INF)
        key = (h.n, bp.tobytes(), sense.tobytes())
        start = self._last[1] if self.warm_start == "time" and self._last and self._last[0] == key else None
        H = self.eps * np.eye(h.n)
        t1 = time.perf_counter()
        x, _, exitflag, info = daqp.solve(H, np.zeros(h.n), A, bu, bl, sense, break_points=bp,
                                          dual_start=start, **self.daqp_settings)
        t2 = time.perf_counter()
        status, meaning = exit_status(int(exitflag), int(info["iterations"]),
                                      self.daqp_settings.get("iter_limit", DAQP_ITER_LIMIT))
        usable = status in (OPTIMAL, INFEASIBLE_LEVEL, MAX_ITERATIONS)  # (DAQP wrote x)
        x = np.array(x, dtype=float) if usable else None
        reason = "" if status == OPTIMAL else f"{self.name}: DAQP exit {int(exitflag)} ({meaning})"
        if status == OPTIMAL and np.all(np.isfinite(x)):
            self._last = (key, np.array(info["lam"], dtype=float))
        else:
            self._last = None
        return SolveResult(x, status, reason=reason, iterations=int(info["iterations"]),
                           build_time_s=t1 - t0, solve_time_s=t2 - t1,
                           info={"exitflag": int(exitflag), "judged_on": self.judged_on,
                                 "warm_started": start is not None})


def _judged_on(options: dict) -> str:
    """What a daqp-hqp built with ``options`` claims (see :attr:`Solver.judged_on`)."""
    return ROW_NORMALISED if options.get("normalised", True) else ROWS


SOLVERS = [SolverInfo.of(DaqpHqp, judged_on=_judged_on)]
