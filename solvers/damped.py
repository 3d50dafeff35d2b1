"""Weighted and damped IK: no strict hierarchy (``strict=False``).

All levels are stacked into one task ``J x = e`` (J shape (m, n)); the
harness reports how far the result lands from the lexicographic optimum.

* ``weighted`` — one regularised least-squares step with per-level weights
  (kinematics lecture 003, "optimality principle"):

      x = J# e,   J# = (J^T C J + W)^-1 J^T C,

  C = diag(c_k on the rows of level k), c_k from option ``weights`` (one per
  level) or ``ratio ** k`` (option ``ratio``, default 1e-2), W = ``regularization`` I
  (default 1e-9).
* ``dls`` — one damped least-squares step (Wampler; Boutin et al. eq. (1)
  without the joint-limit term), all rows with the same weight:

      x = J^T (J J^T + lambda^2 I)^-1 e,     lambda = option ``damping`` (1e-3).

* ``dls-liegeois`` — Boutin et al. eq. (1) iterated from x = 0 (they iterate
  until the task is met; here until ``||dx|| <= tol (1 + ||x||)``, at most
  ``max_iter`` steps, else status ``max_iterations``):

      dx = J^+_lambda (e - J x) + alpha (I - J^+ J) grad(phi)(x),

  with J^+_lambda the damped pseudo-inverse above, J^+ the exact
  (SVD, rank threshold 1e-10 ||J||_2) pseudo-inverse in the null-space
  projector (Boutin prints ``I - J^T J``, a misprint for the projector), and
  Liegeois' joint-limit gradient (Boutin et al. eq. (2)), per variable,

      grad(phi)_i = (qmax_i - qmin_i)^2 (qmax_i + qmin_i - 2 q_i) / ((qmax_i - q_i)^2 (qmin_i - q_i)^2),

  which points towards the middle of [qmin_i, qmax_i] (so alpha > 0 moves
  away from the limits). Near the middle c_i of a box of half-width a_i,
  grad(phi)_i ~ -8 (q_i - c_i) / a_i^2; option ``alpha`` (Boutin's scalar)
  defaults to ``min_i a_i^2 / 8``, the step that takes the narrowest joint to
  its middle in that quadratic approximation (a fixed alpha would be stable
  for some box widths and crawl for others). q is the current iterate x: the limits are taken
  from the first **box level** of the hierarchy — a level whose rows are
  +-unit vectors (several rows on one variable: their intersection), at
  least one an inequality with a finite bound (unit equality rows alone are
  a posture task) — and that level is not part of the task. Variables without two finite, distinct limits get a zero gradient. A
  hierarchy without a box level gets status ``unsupported``. The method keeps
  x inside the box only through that gradient, which acts in the null space
  of the task rows: task rows that pull x out of the box win. So ``optimal``
  means converged *and* inside the box (to ``BOX_RTOL (1 + |limit|)``); a
  converged x outside it gets status ``infeasible_level``, and the reason
  names the box level, the worst variable and the excess (a ``max_iterations``
  reason says so too when the last iterate is outside).

Inequality rows (all three solvers): a free row is ignored; an inequality
row is a target only where it is violated — the first solve uses the
equality rows only, then it is repeated (``passes`` solves at most, default 3)
adding the rows violated by the current x as equality targets at their
violated bound (rows once added stay,
at the bound first violated). The status is ``optimal`` when a pass adds no
row (the selection converged) and ``max_iterations`` when the last pass still
leaves violated rows that are not targets (the reason counts them).
dls-liegeois does the same at every iteration
(re-selecting from scratch makes the iteration chatter between two row sets).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from hikbench.problems.hierarchy import Hierarchy
from hikbench.solvers.base import INFEASIBLE_LEVEL, MAX_ITERATIONS, NUMERICAL_FAILURE, OPTIMAL, Solver, SolveResult
from hikbench.solvers.info import SolverInfo
from hikbench.solvers.options import check_int, check_number, check_numbers

__all__ = ["BOX_RTOL", "DLS", "DLSLiegeois", "Weighted", "box_excess", "box_limits", "liegeois_gradient"]

#: dls-liegeois: x may leave a limit by ``BOX_RTOL (1 + |limit|)`` and still be ``optimal``
BOX_RTOL = 1e-9


def _mark_violated(h: Hierarchy, rows: np.ndarray, x: np.ndarray, side: np.ndarray) -> int:
    """Mark in ``side`` (m,) int8 the inequality rows among ``rows`` (bool mask)
    violated at x and not yet targets: 1 above the upper bound, -1 below the
    lower. Returns how many were added."""
    r = h.A @ x
    cand = rows & ~h.is_equality & (side == 0)
    new_up = cand & (r > h.upper)
    new_lo = cand & (r < h.lower)
    side[new_up] = 1
    side[new_lo] = -1
    return int(new_up.sum() + new_lo.sum())


def _selection(h: Hierarchy, side: np.ndarray):
    """Target rows (side != 0) and their targets: the upper bound (equality
    rows: lower == upper) for side 1, the lower bound for side -1."""
    sel = np.flatnonzero(side != 0)
    return sel, np.where(side[sel] < 0, h.lower[sel], h.upper[sel])


def box_limits(h: Hierarchy):
    """Per-variable limits from the first box level.

    Returns ``(k, qmin, qmax)``, qmin/qmax shape (n,) (+-inf where a variable
    has no row; the intersection of a variable's rows), or None when no level
    is a box level: rows that are +-unit vectors, at least one of them an
    inequality with a finite bound (a level of unit equality rows is a
    posture task, not a limit)."""
    for k in range(h.depth):
        s = h.level_rows(k)
        A = h.A[s]
        lo, up = h.lower[s], h.upper[s]
        if A.shape[0] == 0 or not np.any((lo < up) & (np.isfinite(lo) | np.isfinite(up))):
            continue
        nz = A != 0
        if not np.all(nz.sum(axis=1) == 1):
            continue
        cols = np.argmax(nz, axis=1)
        vals = A[np.arange(A.shape[0]), cols]
        if not np.all(np.abs(vals) == 1.0):
            continue
        qmin = np.full(h.n, -np.inf)
        qmax = np.full(h.n, np.inf)
        # a variable with several rows (position and velocity limits) gets their intersection
        np.maximum.at(qmin, cols, np.where(vals > 0, lo, -up))
        np.minimum.at(qmax, cols, np.where(vals > 0, up, -lo))
        return k, qmin, qmax
    return None


def box_excess(x: np.ndarray, qmin: np.ndarray, qmax: np.ndarray, k: int, rtol: float = BOX_RTOL) -> str:
    """Where x (n,) leaves [qmin, qmax] by more than ``rtol (1 + |limit|)``:
    a sentence naming box level k, how many variables, the worst one and by
    how much; "" when x is inside (to that tolerance)."""
    with np.errstate(invalid="ignore"):
        below, above = qmin - x, x - qmax  # > 0 outside; -inf for a missing limit
        excess = np.maximum(below, above)
        limit = np.where(below >= above, qmin, qmax)
        out = excess > rtol * (1 + np.abs(limit))
    if not out.any():
        return ""
    i = int(np.argmax(np.where(out, excess, -np.inf)))
    return (f"level {k} (box level) violated: {int(out.sum())} of {x.size} variables outside their limits, "
            f"worst x[{i}] = {x[i]:.6g} outside [{qmin[i]:.6g}, {qmax[i]:.6g}] by {excess[i]:.3g} "
            f"(norm of the excess {np.linalg.norm(excess[out]):.3g})")


def liegeois_gradient(q: np.ndarray, qmin: np.ndarray, qmax: np.ndarray) -> np.ndarray:
    """Boutin et al. eq. (2), shape (n,); 0 where a limit is infinite, qmin >= qmax, or q is
    on a limit (eq. (2) is infinite there: a velocity bound of 0 for a joint at its position
    limit puts x = 0 on it). Outside the limits it points back inside."""
    ok = np.isfinite(qmin) & np.isfinite(qmax) & (qmax > qmin) & (q != qmin) & (q != qmax)
    g = np.zeros_like(q)
    lo, hi, qq = qmin[ok], qmax[ok], q[ok]
    with np.errstate(divide="ignore", invalid="ignore"):
        g[ok] = (hi - lo) ** 2 * (hi + lo - 2 * qq) / ((hi - qq) ** 2 * (lo - qq) ** 2)
    return g


class _Stacked(Solver):
    supports_inequalities = True
    supports_warm_start = False

    def _row_weights(self, h: Hierarchy) -> np.ndarray:
        return np.ones(h.rows)

    def _declines(self, h: Hierarchy) -> str | None:
        """Why the solver cannot take h with its options (None: it can)."""
        return None

    def _step(self, J, e, c) -> np.ndarray:
        raise NotImplementedError

    def solve(self, hierarchy: Hierarchy) -> SolveResult:
        self.check_hierarchy(hierarchy)
        h = hierarchy
        why = self._declines(h)
        if why is not None:
            return self.unsupported(h, why)
        rows = ~h.is_free
        side = np.zeros(h.rows, dtype=np.int8)
        side[rows & h.is_equality] = 1
        c_all = self._row_weights(h)
        x = np.zeros(h.n)
        passes = 0
        with np.errstate(all="ignore"):
            while passes < self.passes:
                if passes and _mark_violated(h, rows, x, side) == 0:
                    break
                passes += 1
                sel, e = _selection(h, side)
                try:
                    x = self._step(h.A[sel], e, c_all[sel]) if sel.size else np.zeros(h.n)
                except (np.linalg.LinAlgError, ValueError) as err:
                    return SolveResult(x=None, status=NUMERICAL_FAILURE,
                                       reason=f"{self.name}: factorisation failed: {err}", iterations=passes)
                if not np.all(np.isfinite(x)):
                    return SolveResult(x=x, status=NUMERICAL_FAILURE, reason=f"{self.name}: NaN/inf in x",
                                       iterations=passes)
        info = {"target_rows": int((side != 0).sum())}
        if passes == self.passes:
            left = _mark_violated(h, rows, x, side)  # (side is not read after this)
            if left:
                return SolveResult(x=x, status=MAX_ITERATIONS, iterations=passes, info=info,
                                   reason=f"{self.name}: pass limit {self.passes} reached with {left} inequality "
                                          f"row(s) violated at x that are not targets yet (option passes)")
        return SolveResult(x=x, status=OPTIMAL, iterations=passes, info=info)


class Weighted(_Stacked):
    """x = (J^T C J + W)^-1 J^T C e with per-level weights (lecture 003)."""

    name = "weighted"
    strict = False
    description = "one weighted regularised least-squares step J# = (J^T C J + W)^-1 J^T C, per-level weights"

    def __init__(self, weights=None, ratio: float = 1e-2, regularization: float = 1e-9, passes: int = 3):
        self.ratio = check_number(self.name, "ratio", ratio, low=0, low_open=True)
        self.regularization = check_number(self.name, "regularization", regularization, low=0)
        self.passes = check_int(self.name, "passes", passes)
        self.weights = None if weights is None else check_numbers(self.name, "weights", weights, low=0,
                                                                  what="one weight per level")

    def _row_weights(self, h: Hierarchy) -> np.ndarray:
        c = self.ratio ** np.arange(h.depth, dtype=float) if self.weights is None else self.weights
        return c[h.level]  # (one weight per level: _declines checked the count)

    def _declines(self, h: Hierarchy) -> str | None:
        if self.weights is not None and self.weights.size != h.depth:
            return f"option weights has {self.weights.size} entries, the hierarchy has {h.depth} levels"
        return None

    def _step(self, J, e, c):
        JtC = J.T * c  # (n, m): J^T C
        H = JtC @ J + self.regularization * np.eye(J.shape[1])
        return scipy.linalg.cho_solve(scipy.linalg.cho_factor(H), JtC @ e)


class DLS(_Stacked):
    """x = J^T (J J^T + lambda^2 I)^-1 e (damped least squares)."""

    name = "dls"
    strict = False
    description = "one damped least-squares step J^T (J J^T + lambda^2 I)^-1 e, all levels stacked"

    def __init__(self, damping: float = 1e-3, passes: int = 3):
        self.damping = check_number(self.name, "damping", damping, low=0)
        self.passes = check_int(self.name, "passes", passes)

    def _step(self, J, e, c):
        G = J @ J.T + self.damping ** 2 * np.eye(J.shape[0])
        return J.T @ scipy.linalg.cho_solve(scipy.linalg.cho_factor(G), e)


class DLSLiegeois(Solver):
    """Boutin et al. eqs. (1)-(2): DLS plus the Liegeois joint-limit gradient in the null space."""

    name = "dls-liegeois"
    strict = False
    description = "iterated DLS + Liegeois joint-limit gradient projected in the null space (Boutin eqs. 1-2)"
    supports_inequalities = True
    supports_warm_start = False

    def __init__(self, damping: float = 1e-3, alpha: float | None = None, max_iter: int = 1000,
                 tol: float = 1e-10):
        self.damping = check_number(self.name, "damping", damping, low=0)
        self.alpha = check_number(self.name, "alpha", alpha, low=0, none_ok=True)
        self.max_iter = check_int(self.name, "max_iter", max_iter)
        self.tol = check_number(self.name, "tol", tol, low=0, low_open=True)

    def solve(self, hierarchy: Hierarchy) -> SolveResult:
        self.check_hierarchy(hierarchy)
        h = hierarchy
        box = box_limits(h)
        if box is None:
            return self.unsupported(h, "needs per-variable limits: no level is a box level (rows that are "
                                       "+-unit vectors, at least one an inequality with a finite bound)")
        kbox, qmin, qmax = box
        alpha = self.alpha
        if alpha is None:
            half = (qmax - qmin)[np.isfinite(qmax - qmin) & (qmax > qmin)] / 2
            alpha = float(half.min() ** 2 / 8) if half.size else 0.0
        rows = ~h.is_free & (h.level != kbox)
        n = h.n
        x = np.zeros(n)
        cache: dict[bytes, tuple] = {}
        side = np.zeros(h.rows, dtype=np.int8)
        side[rows & h.is_equality] = 1
        it = 0
        converged = False
        with np.errstate(all="ignore"):
            for it in range(1, self.max_iter + 1):
                _mark_violated(h, rows, x, side)  # rows once targets stay targets
                sel, e = _selection(h, side)
                key = side.tobytes()
                if key not in cache:
                    J = h.A[sel]
                    if sel.size:
                        G = J @ J.T + self.damping ** 2 * np.eye(sel.size)
                        try:
                            Jd = J.T @ scipy.linalg.cho_solve(scipy.linalg.cho_factor(G), np.eye(sel.size))
                        except (np.linalg.LinAlgError, ValueError) as err:
                            return SolveResult(x=x, status=NUMERICAL_FAILURE, iterations=it,
                                               reason=f"{self.name}: damped inverse failed: {err}")
                        _, S, Vt = np.linalg.svd(J, full_matrices=True)
                        rank = int(np.sum(S > 1e-10 * (S[0] if S.size else 0.0)))
                        N = Vt[rank:].T @ Vt[rank:]  # I - J^+ J, shape (n, n)
                    else:
                        Jd, N = np.zeros((n, 0)), np.eye(n)
                    cache[key] = (J, Jd, N)
                J, Jd, N = cache[key]
                dx = Jd @ (e - J @ x) + alpha * (N @ liegeois_gradient(x, qmin, qmax))
                if not np.all(np.isfinite(dx)):
                    return SolveResult(x=x, status=NUMERICAL_FAILURE, iterations=it,
                                       reason=f"{self.name}: NaN/inf step at iteration {it} "
                                              "(an iterate on a limit?)")
                x = x + dx
                converged = np.linalg.norm(dx) <= self.tol * (1 + np.linalg.norm(x))
                if converged:
                    break
        info = {"box_level": kbox, "alpha": alpha}
        outside = box_excess(x, qmin, qmax, kbox)
        if not converged:
            return SolveResult(x=x, status=MAX_ITERATIONS, iterations=it, info=info,
                               reason=f"{self.name}: no convergence in {self.max_iter} iterations "
                                      f"(last ||dx|| = {np.linalg.norm(dx):.3g})"
                                      + (f"; {outside}" if outside else ""))
        if outside:  # converged, but not to what the method is for: x within the limits
            return SolveResult(x=x, status=INFEASIBLE_LEVEL, iterations=it, info=info,
                               reason=f"{self.name}: converged in {it} iterations outside the limits: "
                                      f"{outside} (the joint-limit gradient acts only in the null space "
                                      "of the task rows: it cannot hold x inside the box against them)")
        return SolveResult(x=x, status=OPTIMAL, iterations=it, info=info)


SOLVERS = [SolverInfo.of(cls) for cls in (Weighted, DLS, DLSLiegeois)]
