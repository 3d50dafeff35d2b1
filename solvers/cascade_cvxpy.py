"""The cascade of QPs written in cvxpy (modelling overhead included).

Same QP per level, same freezing and same statuses as :mod:`hikbench.solvers.cascade`
(Kanoun et al.; ICRA 2010 eqs. (33)-(36)); here each level is modelled with
cvxpy variables ``x`` (n,) and ``w`` (m_k,):

    min 1/2 sum_squares(w) + eps/2 sum_squares(x)
    s.t. lower_k <= A_k x - w <= upper_k  (finite sides; equality rows as ==),
         frozen rows of the levels above.

``build_time_s`` is the time to build the cvxpy Problem, ``solve_time_s`` the
time of ``Problem.solve`` — which includes cvxpy's canonicalisation: that is
what a cvxpy user pays. Option ``solver`` picks the cvxpy solver (default
``"CLARABEL"``); accuracy profiles map onto that solver's own parameter names
through :data:`hikbench.solvers._qp_backends.CVXPY_ACCURACY`. No warm start (cvxpy
re-canonicalises a new Problem at every level).
"""

from __future__ import annotations

import importlib.util
import sys
import time
import warnings

import numpy as np

from hikbench.solvers.errors import SolverOptionError
from hikbench.extras import install_hint
from hikbench.solvers import _qp_backends as tables
from hikbench.solvers.cascade import CascadeBase
from hikbench.solvers.info import SolverInfo
from hikbench.solvers.options import check_choice

__all__ = ["CvxpyCascade"]


class CvxpyCascade(CascadeBase):
    """Cascade of QPs modelled in cvxpy."""

    name = "cascade-cvxpy"
    description = "cascade of QPs (Kanoun et al.) modelled in cvxpy (modelling overhead included)"
    backend = "cvxpy"
    supports_warm_start = False

    def __init__(self, solver: str = "CLARABEL", freeze: str | None = None, accuracy: str = "high",
                 regularization: float | None = None, max_iter: int | None = None,
                 relax_delta: float | None = None, slack_tol: float | None = None, tolerances: str | None = None):
        import cvxpy as cp

        check_choice(self.name, "solver", solver, sorted(tables.CVXPY_ACCURACY))
        if solver not in cp.installed_solvers():
            raise SolverOptionError(f"{self.name}: option solver={solver!r}: not installed in cvxpy "
                                    f"(installed: {cp.installed_solvers()})")
        super().__init__(freeze=freeze, accuracy=accuracy, regularization=regularization, max_iter=max_iter,
                         relax_delta=relax_delta, slack_tol=slack_tol, tolerances=tolerances)
        self.solver = solver
        if self.max_iter is not None and solver == "SCS":
            self._iter_name = "max_iters"
        else:
            self._iter_name = "max_iter"

    def settings(self) -> dict:
        return {**super().settings(), "solver": self.solver}

    def _solve_level(self, k, A_f, lower_f, upper_f, A_k, lower_k, upper_k, z0):
        import cvxpy as cp

        n, m = A_k.shape[1], A_k.shape[0]
        t0 = time.perf_counter()
        x = cp.Variable(n)
        w = cp.Variable(m)
        cons = []
        for A, lo, up, slack in ((A_f, lower_f, upper_f, None), (A_k, lower_k, upper_k, w)):
            if A.shape[0] == 0:
                continue
            eq = lo == up
            fu = np.isfinite(up) & ~eq
            fl = np.isfinite(lo) & ~eq
            for mask, side in ((eq, "eq"), (fu, "up"), (fl, "lo")):
                if not mask.any():
                    continue
                expr = A[mask] @ x - (slack[np.flatnonzero(mask)] if slack is not None else 0)
                if side == "eq":
                    cons.append(expr == lo[mask])
                elif side == "up":
                    cons.append(expr <= up[mask])
                else:
                    cons.append(expr >= lo[mask])
        obj = 0.5 * cp.sum_squares(w) + 0.5 * self.eps * cp.sum_squares(x)
        prob = cp.Problem(cp.Minimize(obj), cons)
        opts = dict(tables.CVXPY_ACCURACY[self.solver][self.tolerances])
        if self.max_iter is not None:
            opts[self._iter_name] = int(self.max_iter)
        t1 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the status is read from the Problem, not from warnings
            prob.solve(solver=self.solver, **opts)
        t2 = time.perf_counter()
        stats = prob.solver_stats
        it = int(stats.num_iters) if stats is not None and stats.num_iters is not None else 0
        status = str(prob.status)
        z = None
        if x.value is not None and w.value is not None:
            z = np.concatenate([np.asarray(x.value, dtype=float).ravel(),
                                np.asarray(w.value, dtype=float).ravel()])
        if status == cp.OPTIMAL:
            return "ok", z, it, t1 - t0, t2 - t1, status
        if status == cp.OPTIMAL_INACCURATE:
            return "inaccurate", z, it, t1 - t0, t2 - t1, status
        if status in (cp.INFEASIBLE, cp.INFEASIBLE_INACCURATE):
            return "infeasible", None, it, t1 - t0, t2 - t1, status
        if status == cp.USER_LIMIT or "iter" in status.lower():
            return "max_iterations", z, it, t1 - t0, t2 - t1, status
        return "unknown", None, it, t1 - t0, t2 - t1, status


def _cvxpy_installed() -> bool:
    """Whether cvxpy is installed, found without importing it (its import takes 1-2 s, which
    every command listing the solvers would pay): a module blocked in ``sys.modules`` (None)
    counts as missing."""
    if "cvxpy" in sys.modules:
        return sys.modules["cvxpy"] is not None
    return importlib.util.find_spec("cvxpy") is not None


SOLVERS = [SolverInfo.of(CvxpyCascade)] if _cvxpy_installed() else []
MISSING = ({} if _cvxpy_installed()
           else {"cascade-cvxpy": install_hint("cvxpy")})
