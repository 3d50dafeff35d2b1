"""The yardstick: independent solutions that every solver's x is judged against.

Two methods that share no code with the HCOD solver:

* :func:`nullspace_yardstick` (equality-only hierarchies): the null-space
  recursion with an orthonormal basis, ICRA 2010 eq. (2) with the SVD of each
  projected level,

      M_k = A_k Z_{k-1} = U S V^T,   x_k = x_{k-1} + Z_{k-1} V_r S_r^-1 U_r^T (b_k - A_k x_{k-1}),
      Z_k = Z_{k-1} V_{r+1:},                                        shapes: Z_k (n, n - sum ranks)

  which yields the minimum-norm lexicographic solution. Rank is decided by the
  documented threshold ``s_i > RANK_RTOL * ||A_k||_2`` (relative to the
  *unprojected* level, so that a level fully decided by the ones above has
  rank 0, not full rank of round-off).

* :func:`cascade_yardstick` (any hierarchy): the sequence of LSIs (ICRA 2010,
  eqs. (33)-(36)) as a cascade of QPs in (x, w) solved by Clarabel at tight
  tolerances, each level *polished*: its active set is read off the QP
  solution and the equality-constrained least-squares problem on that set is
  solved exactly (SVD null-space method); from that point, a primal active
  set that also drops rows goes on to the optimum where the QP's active set
  was not the optimal one (:func:`_descend`); the polished point is kept only if it
  is feasible and no worse, or, where the QP's point is cheaper for breaking
  the levels above within its tolerances, certified optimal by the KKT
  conditions. Higher levels are frozen exactly, the optimal
  slack being unique: a row with nonzero slack w_j* becomes the equality
  ``A_j x = bound_j + w_j*``, a row with zero slack keeps its bounds. Frozen
  equalities are eliminated (``x = x_p + N y``) before each QP, and with them
  the frozen inequality rows in their span (constant on ``x_p + N y``, met
  there). A last stage
  picks the minimum-norm x in the optimal set. The QP backends are Clarabel,
  then PIQP when Clarabel fails (the one used is recorded per stage).
  When every backend fails on a stage -- typically "primal infeasible" on a
  frozen set that is feasible but has no interior, rows held at their bounds
  by others of an ill-conditioned level -- the stage is solved again with the
  frozen inequality bounds widened by :data:`WIDEN_RTOL` of each row's scale;
  such a point is kept only if polishing puts it on the exact bounds and the
  KKT conditions certify it optimal there (multipliers of the right signs,
  found by bounded least squares); the widening is recorded in the stage's
  ``backend``. Where no try gives a point, the last is the primal active set
  :func:`_descend` from the level above's point (feasible: the levels above
  are frozen at it), kept where the KKT conditions certify it at 1e-9
  (:func:`_descend_stage`). Levels of norms far from 1 and bounds far from the origin are
  solved scaled by powers of 2 to O(1) (:data:`ROWS_BAND`,
  :data:`LEVEL_BAND`, :data:`UNITS_MIN`, :data:`UNITS_MAX`, :func:`cascade_yardstick`); so is the null-space recursion's input.
"""

from __future__ import annotations

import warnings

import numpy as np

from hikbench.problems.errors import HikbenchError
from hikbench.problems.hierarchy import Hierarchy, check_fits_in_memory
from hikbench.solvers.base import ERROR, OPTIMAL, Solver, SolveResult
from hikbench.solvers.info import SolverInfo

__all__ = ["LEVEL_BAND", "RANK_RTOL", "ROWS_BAND", "UNITS_MAX", "UNITS_MIN", "WIDEN_RTOL", "YardstickSolver",
           "cascade_yardstick", "nullspace_yardstick", "yardstick_solution"]

RANK_RTOL = 1e-10  #: singular values below RANK_RTOL * ||A_k||_2 count as zero
_ACTIVE_RTOL = 1e-7  #: a constraint within this (relative) distance of its bound is read as active
#: where the active set read at _ACTIVE_RTOL polishes to no point that is kept, it is read again at
#: these, in turn (a QP point off the optimum by more than its tolerance on an ill-conditioned
#: level; conditioning sweep trials 746 and 2798: the minimum-norm stage, on widened bounds, certified on a
#: second reading)
_ACTIVE_RETRY = (1e-6, 1e-5)
_ALMOST_SOLVED = ("AlmostSolved",)  #: Clarabel's reduced-accuracy success
_Y_REG = 1e-9  #: regularisation of the free coordinates y in a level's QP (removed by polishing)
_EPS = float(np.finfo(float).eps)
#: a working row of the level whose slack (its multiplier) has the wrong sign beyond this (relative
#: to the row's scale, ~1e3 round-offs) leaves the working set (:func:`_descend`); _FEAS_RTOL was
#: too loose: a row of norm 172 held at its bound by a slack of -6.4e-10 (1.3e-12 of its scale)
#: left level 1 of badly_scaled n=5 seed 353 3 % above its optimum
_DROP_RTOL = 1e3 * _EPS
_FEAS_RTOL = 1e-11  #: feasibility slack allowed to a polished point (relative, per row)
#: the KKT test (relative to the gradient) by which a descended point no cheaper than the polished
#: one to round-off is still taken where it passes and the polished one does not (:func:`_kkt_closer`)
_KKT_TIGHT = 1e-9
#: a slack within this of its row's scale is zero when a level is frozen (:func:`_freeze`)
_FREEZE_RTOL = 1e-13
_HELD_RTOL = 1e-9  #: a descended point whose rows above leave their bounds beyond this (relative) is not taken
#: widenings of the frozen inequality bounds (relative to each row's scale) tried, in order, on a
#: stage no backend solved; the last is _ACTIVE_RTOL: polishing reads rows that close as active anyway
WIDEN_RTOL = (1e-9, _ACTIVE_RTOL)
#: a problem whose bounds lie, as a median, within UNITS_MIN of the origin or beyond UNITS_MAX (in
#: units of x) is solved in units that bring that median to [1, 2) (:func:`_units_exponent`);
#: problems between them are left bit for bit
UNITS_MIN = 2.0**-5
UNITS_MAX = 2.0**10
#: levels are solved scaled to ``||A_k||_F`` in [1, 2) (by powers of 2) where the problem's median row
#: norm lies outside [1 / ROWS_BAND, ROWS_BAND], or the level's ``||A_k||_F`` outside [1 / LEVEL_BAND,
#: LEVEL_BAND] (:func:`_level_exponents`); problems within both are left bit for bit (the shipped
#: families, badly_scaled's rows of 1e-4 .. 1e4 included)
ROWS_BAND = 2.0**5
LEVEL_BAND = 2.0**20


class YardstickError(HikbenchError):
    """The yardstick could not solve a problem to its accuracy."""


#: n x n matrices of doubles the yardstick holds at once (Z, the full SVD's V^T, Z @ V^T),
#: checked against the machine's memory before the first is made
YARDSTICK_MATRICES = 3


def _null_update(x: np.ndarray, Z: np.ndarray, A: np.ndarray, b: np.ndarray):
    """One step of the SVD null-space recursion (eq. 2); returns x, Z."""
    if A.shape[0] == 0 or Z.shape[1] == 0:
        return x, Z
    thr = RANK_RTOL * np.linalg.norm(A, 2)
    M = A @ Z
    U, s, Vt = np.linalg.svd(M, full_matrices=True)
    r = int(np.sum(s > thr)) if thr > 0 else 0
    if r:
        x = x + Z @ (Vt[:r].T @ ((U[:, :r].T @ (b - A @ x)) / s[:r]))
    return x, Z @ Vt[r:].T


def nullspace_yardstick(h: Hierarchy) -> np.ndarray:
    """Minimum-norm lexicographic solution of an equality-only hierarchy.

    Returns x, shape (n,). Raises YardstickError if h has inequality rows."""
    if h.has_inequalities:
        raise YardstickError("nullspace_yardstick solves equality-only hierarchies; use cascade_yardstick")
    check_fits_in_memory(h.n, "yardstick", matrices=YARDSTICK_MATRICES)
    h, _, e_x = _normalized(h)
    x = np.zeros(h.n)
    Z = np.eye(h.n)
    for k in range(h.depth):
        s = h.level_rows(k)
        x, Z = _null_update(x, Z, h.A[s], h.lower[s])
    return np.ldexp(x, -e_x)


def _rowwise_lstsq_update(x: np.ndarray, Z: np.ndarray, A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """x + Z dy, dy the minimum-norm argmin ||A (x + Z dy) - b|| over the directions of Z
    that a row of A sees beyond RANK_RTOL of *its own* norm: the rank is that of M = D^-1 A Z
    (D the row norms of A), the step the unweighted least squares on M's row space.
    Shapes: x (n,), Z (n, p), A (m, n), b (m,).

    :func:`_null_update`'s threshold, RANK_RTOL * ||A||_2, cuts a direction that a row of a
    small norm sees in a level with a row 1e7 times larger: badly_scaled n=12 seed 964's level
    2, whose row of norm 3.4e-3 sees the last free direction at 2.5e-6, under 1e-10 * 2.6e4. The
    step then stopped short of the working set's optimum and :func:`_descend` stalled above the
    level's optimum. Not the default: on an ill-conditioned level of rows of like norms, the
    directions it keeps beyond the level's threshold are round-off of the projection (conditioning
    sweep trial 1014, cond 1e6: a descent so steered ended 50 % dearer, uncertified)."""
    if A.shape[0] == 0 or Z.shape[1] == 0:
        return x
    M = A @ Z
    norms = np.linalg.norm(A, axis=1)
    keep = norms > 0
    if not keep.any():
        return x
    _, s, Vt = np.linalg.svd(M[keep] / norms[keep, None], full_matrices=False)
    Vr = Vt[: int(np.sum(s > RANK_RTOL))].T
    if Vr.shape[1] == 0:
        return x
    c = np.linalg.lstsq(M @ Vr, b - A @ x, rcond=None)[0]
    return x + Z @ (Vr @ c)


def _constrained_lstsq(x0: np.ndarray, C: np.ndarray, d: np.ndarray, G: np.ndarray, t: np.ndarray,
                       rowwise: bool = False) -> np.ndarray:
    """argmin ||G x - t|| s.t. C x = d (least squares on C if inconsistent)
    closest to x0, by the SVD null-space method started at x0 (the rank of C at
    RANK_RTOL * ||C||_2, that of G too, or with ``rowwise`` row by row:
    :func:`_rowwise_lstsq_update`)."""
    x = np.array(x0, dtype=float)
    Z = np.eye(x.size)
    x, Z = _null_update(x, Z, C, d)
    if rowwise:
        return _rowwise_lstsq_update(x, Z, G, t)
    return _null_update(x, Z, G, t)[0]


def _meets(A: np.ndarray, lo: np.ndarray, up: np.ndarray, x: np.ndarray, rtol: float) -> bool:
    """Whether every row of ``A x`` is within its bounds to ``rtol`` of its scale (:func:`_row_scale`)."""
    r, tol = A @ x, rtol * _row_scale(A, lo, up, x)
    return bool(np.all(r <= up + tol) and np.all(r >= lo - tol))


def _signed_slack(r: np.ndarray, lo: np.ndarray, up: np.ndarray) -> np.ndarray:
    """w = r - clip(r, lo, up): positive above upper, negative below lower."""
    return r - np.clip(r, lo, up)


def _stage_cost(x, A_k, lo_k, up_k, final: bool) -> float:
    """A stage's cost at x: ||w||^2 of level k's signed slack (eq. 35), or ||x||^2 on the final
    (minimum-norm) stage."""
    w = x if final else _signed_slack(A_k @ x, lo_k, up_k)
    return float(w @ w)


def _qp_level(A_hi, lo_hi, up_hi, A_k, lo_k, up_k, final: bool, widen: float = 0.0):
    """Build and solve the QP of one level.

    Level k (not final): min 1/2 ||w||^2  s.t. lo_hi <= A_hi x <= up_hi,
    lo_k <= A_k x - w <= up_k. Final stage: min 1/2 ||x||^2 s.t. the first set.
    The equality rows of the higher levels (frozen rows) are eliminated first,
    ``x = x_p + N y`` with N an orthonormal basis of their null space (SVD,
    rank threshold RANK_RTOL), so that the QP in z = (y, w) has no redundant
    equality constraints, on which interior-point backends stall; so are the
    inequality rows of A_hi in their span (``||A_i N|| <= RANK_RTOL ||A_i||``)
    that x_p meets to ``_FEAS_RTOL``. ``widen`` > 0
    moves each remaining bound of A_hi outward by ``widen`` times the row's
    scale (:func:`_row_scale` at x_p).
    Returns x, shape (n,) (n = A_hi's columns), and the backend name."""
    import qpsolvers

    eq_hi = lo_hi == up_hi
    nx = A_hi.shape[1]
    x_p, N = _null_update(np.zeros(nx), np.eye(nx), A_hi[eq_hi], lo_hi[eq_hi])
    if widen > 0:
        gap = widen * _row_scale(A_hi, lo_hi, up_hi, x_p)
        lo_hi, up_hi = np.where(eq_hi, lo_hi, lo_hi - gap), np.where(eq_hi, up_hi, up_hi + gap)
    A_hi, lo_hi, up_hi = A_hi[~eq_hi], lo_hi[~eq_hi] - A_hi[~eq_hi] @ x_p, up_hi[~eq_hi] - A_hi[~eq_hi] @ x_p
    lo_k, up_k = lo_k - A_k @ x_p, up_k - A_k @ x_p
    # an inequality row in the span of the frozen equalities is constant on x_p + N y: its
    # projection A_i N is round-off, and as a constraint it would cut y along a random direction
    # (two such rows, 1e-16 of their norm with bounds +-1e-14, had Clarabel report a level's QP
    # solved at 1.16 where 0.0063 was feasible). Met at x_p (to _FEAS_RTOL), it is left out
    row_norm = np.linalg.norm(A_hi, axis=1)
    A_hi = A_hi @ N
    feas = _FEAS_RTOL * row_norm * (1.0 + np.linalg.norm(x_p))
    constant = (np.linalg.norm(A_hi, axis=1) <= RANK_RTOL * row_norm) & (lo_hi <= feas) & (up_hi >= -feas)
    A_hi, lo_hi, up_hi = A_hi[~constant], lo_hi[~constant], up_hi[~constant]
    A_k = A_k @ N
    n, m = N.shape[1], A_k.shape[0]
    if n == 0:
        return x_p, "none"
    nz = n + m
    P = np.zeros((nz, nz))
    q = np.zeros(nz)
    if final:
        P[:n, :n] = np.eye(n)
        q[:n] = N.T @ x_p
    else:
        P[n:, n:] = np.eye(m)
        # y directions that no row sees have zero cost: unregularised, an
        # interior-point method lets them drift until round-off in A N breaks
        # the frozen rows. The O(_Y_REG) bias is removed by the polishing.
        P[:n, :n] = _Y_REG * np.eye(n)
    rows_A = [np.hstack([A_hi, np.zeros((A_hi.shape[0], m))]), np.hstack([A_k, -np.eye(m)])]
    Afull = np.vstack(rows_A)
    lo = np.concatenate([lo_hi, lo_k])
    up = np.concatenate([up_hi, up_k])
    eq = lo == up
    G_parts, h_parts = [], []
    fin_u = np.isfinite(up) & ~eq
    fin_l = np.isfinite(lo) & ~eq
    G_parts += [Afull[fin_u], -Afull[fin_l]]
    h_parts += [up[fin_u], -lo[fin_l]]
    G = np.vstack(G_parts)
    hv = np.concatenate(h_parts)
    Aeq, beq = Afull[eq], lo[eq]
    problem = qpsolvers.Problem(P, q, _csc(G), hv if hv.size else None,
                                _csc(Aeq), beq if beq.size else None)
    problem.P = _csc(P)
    tried = []
    for label, backend, options in _QP_BACKENDS:
        with warnings.catch_warnings():  # a stalled backend is recorded below, not warned
            warnings.simplefilter("ignore", RuntimeWarning)
            warnings.simplefilter("ignore", UserWarning)
            sol = qpsolvers.solve_problem(problem, solver=backend, **options)
        extras = sol.extras if isinstance(sol.extras, dict) else {}
        status = extras.get("status", getattr(extras.get("info"), "status", None))  # (PIQP: in its info)
        # the QP only has to identify the active set (polishing is exact), so
        # an almost-solved point is accepted; its status is kept in the name
        usable = sol.found or str(status) in _ALMOST_SOLVED
        if usable and sol.x is not None and np.all(np.isfinite(sol.x)):
            return x_p + N @ sol.x[:n], label if sol.found else f"{label} ({status})"
        tried.append(f"{label}: {status}")
    raise YardstickError("no QP backend solved the level (" + "; ".join(tried) + ")")


def _csc(M: np.ndarray):
    from scipy import sparse
    return sparse.csc_matrix(M) if M.size else None


# Tried in order, (label, backend, options): Clarabel (interior point) at
# tight tolerances; PIQP (proximal interior point) when Clarabel stalls, as it
# does on rows whose norms spread over 1e8; Clarabel at its default
# tolerances when both break down numerically (seen on ik-like n=40 seed 3).
# The QP only has to identify the active set: polishing is exact. The label of
# the attempt that succeeded is recorded per stage.
_QP_BACKENDS = (
    ("clarabel", "clarabel", {"tol_gap_abs": 1e-10, "tol_gap_rel": 1e-10, "tol_feas": 1e-10,
                              "tol_ktratio": 1e-8, "max_iter": 500, "verbose": False}),
    ("piqp", "piqp", {"eps_abs": 1e-10, "eps_rel": 1e-10, "verbose": False}),
    ("clarabel-default-tol", "clarabel", {"max_iter": 500, "verbose": False}),
)


def _row_scale(A: np.ndarray, lo: np.ndarray, up: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Per-row size of the terms of ``A_i x - bound_i``, shape (rows,)."""
    b = np.maximum(np.where(np.isfinite(lo), np.abs(lo), 0.0), np.where(np.isfinite(up), np.abs(up), 0.0))
    return np.linalg.norm(A, axis=1) * (1.0 + np.linalg.norm(x)) + b + 1e-300


def _kkt_residual(g: np.ndarray, A: np.ndarray, side: np.ndarray):
    """The part of the gradient g (shape (n,)) that the working rows A (shape (m, n)) cannot
    cancel: ``r = g + C^T lam``, with C the rows of A signed so that a right multiplier is >= 0
    (a row held at its lower bound, ``side`` -1, negated) and lam the bounded least-squares
    multipliers, free on equality rows (``side`` 2), >= 0 on rows held at a bound. Returns r
    and C."""
    from scipy.optimize import lsq_linear

    C = A * np.where(side == -1, -1.0, 1.0)[:, None]
    lam = lsq_linear(C.T, -g, bounds=(np.where(side == 2, -np.inf, 0.0), np.inf), method="bvls").x
    return g + C.T @ lam, C


def _kkt_certified(x, A_hi, lo_hi, up_hi, A_k, lo_k, up_k, final: bool, rtol: float = 1e-7) -> bool:
    """Whether the feasible x is optimal for the stage by the KKT conditions:
    multipliers, free for the equality rows of A_hi and of the right sign for
    its rows at a bound, that cancel the gradient of the
    stage's cost, ``g = x`` (final) or ``A_k^T w`` (``w`` the slack of level
    k): ``min || g + C^T lam ||`` over those signs (bounded least squares) is
    at most ``rtol`` ||g|| plus round-off. A row counts as at its (nearer) bound
    within ``_FEAS_RTOL`` of its scale -- where polishing put it -- so that a
    point merely near a bound is not certified (no complementary slackness
    beyond that)."""
    if final:
        g, floor = x, 1e-12 * (1.0 + float(np.linalg.norm(x)))
    else:
        scale = _row_scale(A_k, lo_k, up_k, x)
        r_k = A_k @ x
        w = _signed_slack(r_k, lo_k, up_k)
        g = A_k.T @ w
        # round-off reaches g through the rows with a slack or within 1e-12 of their scale from a
        # bound; a row well inside its bounds adds an exact 0 (when every row counted, level 3's row
        # of norm 4.7e3, inside its bounds, set a floor 100 times |g| and certified a point where a
        # met row of norm 2.9 held back the objective: badly_scaled n=12 seed 6444, see _kkt_closer)
        near = (w != 0) | (np.minimum(r_k - lo_k, up_k - r_k) <= 1e-12 * scale)
        floor = 1e-12 * float(np.linalg.norm(A_k[near], axis=1) @ scale[near])
    r = A_hi @ x
    delta = _FEAS_RTOL * _row_scale(A_hi, lo_hi, up_hi, x)
    eq = lo_hi == up_hi
    at_up = ~eq & np.isfinite(up_hi) & (np.abs(up_hi - r) <= delta) & (up_hi - r <= r - lo_hi)
    at_lo = ~eq & ~at_up & np.isfinite(lo_hi) & (np.abs(r - lo_hi) <= delta)
    held = np.vstack([A_hi[eq], A_hi[at_up], A_hi[at_lo]])
    if held.shape[0] == 0:
        return float(np.linalg.norm(g)) <= floor
    side = np.repeat([2, 1, -1], [int(eq.sum()), int(at_up.sum()), int(at_lo.sum())])
    res, _ = _kkt_residual(g, held, side)
    return float(np.linalg.norm(res)) <= rtol * float(np.linalg.norm(g)) + floor


def _kkt_closer(x_opt, x, cost_opt: float, cost_x: float, A_hi, lo_hi, up_hi, A_k, lo_k, up_k, final: bool) -> bool:
    """Whether the descended x_opt is taken over the polished x although its cost is not lower
    beyond 1e-9: the cost is second order in the move, so a slack off by 1e-6 of itself costs
    1e-12 of it (rank_deficient n=5 seed 1899: level 1's row 6 at -1.3156e-6 against the exact
    -1.0848e-6). x_opt is taken where its slack (x itself on the final stage) moved beyond 1e-12
    of the rows' scales, its cost is no dearer to round-off (1e-12) and it passes the KKT test at
    :data:`_KKT_TIGHT` while x does not."""
    if final:
        moved = np.linalg.norm(x_opt - x) > 1e-12 * (1.0 + float(np.linalg.norm(x)))
    else:
        scale = _row_scale(A_k, lo_k, up_k, x)
        dw = _signed_slack(A_k @ x_opt, lo_k, up_k) - _signed_slack(A_k @ x, lo_k, up_k)
        moved = bool(np.any(np.abs(dw) > 1e-12 * scale))
    return bool(moved and cost_opt <= cost_x * (1 + 1e-12)
                and _kkt_certified(x_opt, A_hi, lo_hi, up_hi, A_k, lo_k, up_k, final, rtol=_KKT_TIGHT)
                and not _kkt_certified(x, A_hi, lo_hi, up_hi, A_k, lo_k, up_k, final, rtol=_KKT_TIGHT))


def _polish(x_qp, A_hi, lo_hi, up_hi, A_k, lo_k, up_k, final: bool, certify: bool = False,
            active_rtol: float = _ACTIVE_RTOL):
    """Read the active set off x_qp (rows within ``active_rtol`` of their
    scale from a bound) and solve the equality problem on it exactly, by the
    smallest correction of x_qp (so that constraints inactive at x_qp stay
    satisfied); from that feasible point, go on to the optimum by :func:`_descend`.

    Returns the polished x if it is feasible and no worse than x_qp (or
    certified optimal by :func:`_kkt_certified` where x_qp is cheaper), else
    x_qp, and whether polishing was kept. With ``certify`` (x_qp from widened bounds,
    so possibly better than the exact optimum) the polished x must instead pass
    :func:`_kkt_certified`."""
    delta = active_rtol * _row_scale(A_hi, lo_hi, up_hi, x_qp)
    r_hi = A_hi @ x_qp
    eq_hi = lo_hi == up_hi
    at_up = ~eq_hi & np.isfinite(up_hi) & (np.abs(r_hi - up_hi) <= delta)
    at_lo = ~eq_hi & ~at_up & np.isfinite(lo_hi) & (np.abs(r_hi - lo_hi) <= delta)
    C = np.vstack([A_hi[eq_hi], A_hi[at_up], A_hi[at_lo]])
    d = np.concatenate([lo_hi[eq_hi], up_hi[at_up], lo_hi[at_lo]])
    if final:
        G, t = np.eye(A_hi.shape[1]), np.zeros(A_hi.shape[1])
    else:
        r_k = A_k @ x_qp
        delta = active_rtol * _row_scale(A_k, lo_k, up_k, x_qp)
        above = r_k > up_k + delta
        below = r_k < lo_k - delta
        eq_k = lo_k == up_k
        tight_u = ~eq_k & ~above & np.isfinite(up_k) & (np.abs(r_k - up_k) <= delta)
        tight_l = ~eq_k & ~below & ~tight_u & np.isfinite(lo_k) & (np.abs(r_k - lo_k) <= delta)
        soft = (above | below | eq_k) & ~(tight_u | tight_l)
        target = np.where(r_k > up_k, up_k, lo_k)
        target = np.where(eq_k, lo_k, target)
        # tight rows of level k: zero slack at the optimum -> constraints
        C = np.vstack([C, A_k[tight_u], A_k[tight_l]])
        d = np.concatenate([d, up_k[tight_u], lo_k[tight_l]])
        G, t = A_k[soft], target[soft]
    def cost(z):
        return _stage_cost(z, A_k, lo_k, up_k, final)

    # Primal active-set refinement (activations; _descend below drops rows too): go from the feasible
    # point toward the exact point of the current active set, stop at the
    # first blocking constraint, activate it, repeat. The rows of the working set (in C) do not
    # block: rounding, not the step, moves them (taking one for the blocking row, again and again,
    # once left a stage at its iteration cap with the real blocking row never activated).
    x_cur = x_qp
    working = eq_hi | at_up | at_lo
    for _ in range(A_hi.shape[0] + 1):
        x = _constrained_lstsq(x_cur, C, d, G, t)
        if _meets(A_hi, lo_hi, up_hi, x, _FEAS_RTOL):
            break
        r = A_hi @ x
        r0 = A_hi @ x_cur
        dr = r - r0
        with np.errstate(divide="ignore", invalid="ignore"):
            tau_u = np.where(dr > 0, (up_hi - r0) / dr, np.inf)
            tau_l = np.where(dr < 0, (lo_hi - r0) / dr, np.inf)
        tau = np.where(working, np.inf, np.minimum(tau_u, tau_l))
        j = int(np.argmin(tau))
        if not np.isfinite(tau[j]):
            return x_qp, False  # only working rows are violated: C x = d has no exact solution
        working[j] = True
        step = float(np.clip(tau[j], 0.0, 1.0))
        x_cur = x_cur + step * (x - x_cur)
        C = np.vstack([C, A_hi[j:j + 1]])
        d = np.append(d, up_hi[j] if tau_u[j] <= tau_l[j] else lo_hi[j])
    else:
        return x_qp, False
    # where the QP's active set was not the optimal one: on to the optimum, dropping rows too. A
    # point no cheaper beyond 1e-9 is not taken: moved by round-off, rows at a bound come off it,
    # and the stages below see another frozen set (humanoid_step seed 104: a minimum-norm stage
    # no longer polished), unless the KKT conditions tell it closer (_kkt_closer)
    x_opt = _descend(x, A_hi, lo_hi, up_hi, A_k, lo_k, up_k, final)
    cost_opt, cost_x = cost(x_opt), cost(x)
    # _descend holds its working rows of A_hi by one least squares whose rank is decided at the
    # stacked rows' threshold: a held row of norm 6e-4 beside one of 3e4 was cut there and left its
    # bound by 2e-4 of its scale (badly_scaled n=12 seed 5034, the minimum-norm stage, level 4 then
    # 1.6e-3 above its optimum); such a point is not taken (_HELD_RTOL: held rows drift by rounding,
    # 3.4e-11 of their scale on the Talos reaching step 181)
    if _meets(A_hi, lo_hi, up_hi, x_opt, _HELD_RTOL) and (
            cost_opt < cost_x * (1 - 1e-9)
            or _kkt_closer(x_opt, x, cost_opt, cost_x, A_hi, lo_hi, up_hi, A_k, lo_k, up_k, final)):
        x = x_opt
    if certify:
        return (x, True) if _kkt_certified(x, A_hi, lo_hi, up_hi, A_k, lo_k, up_k, final) else (x_qp, False)
    c_tol = 0.0 if final else float(np.sum((_FEAS_RTOL * _row_scale(A_k, lo_k, up_k, x)) ** 2))
    if cost(x) <= cost(x_qp) * (1 + 1e-9) + c_tol:
        return x, True
    # x_qp may be cheaper for violating the rows above within the QP's tolerances (their
    # multipliers times that violation): the feasible x is then kept if the KKT conditions
    # certify it optimal on the exact bounds
    if _kkt_certified(x, A_hi, lo_hi, up_hi, A_k, lo_k, up_k, final):
        return x, True
    return x_qp, False


def _descend(x, A_hi, lo_hi, up_hi, A_k, lo_k, up_k, final: bool, rowwise: bool = False):
    """The stage's primal active set with deactivations, from a feasible x
    (the activations of :func:`_polish` reach the exact point of the QP's
    active set; where that set is not the optimal one, this goes on to the
    optimum).

    The stage is the QP in (x, w), ICRA 2010 eq. (35): min 1/2 ||w||^2 s.t. the rows of A_hi in
    their bounds, ``lo_k <= A_k x - w <= up_k`` (final stage: min 1/2 ||x||^2 s.t. the first).
    A row of level k is free (``w_i = 0``, A_k x inside its bounds) or in the working set at one
    bound (``w_i = a_i x - bound``, its multiplier is w_i: the row is dropped where w_i takes the
    wrong sign beyond ``_DROP_RTOL`` of its scale); a row of A_hi is free or held at a bound (its
    multiplier from bounded least squares, :func:`_kkt_residual`; where those leave a
    residual r of the gradient, the row that ``-r`` leaves fastest is dropped). A working row of
    level k met to within ``_DROP_RTOL`` of its scale counts as a row held at its bound: its w_i
    is round-off, which neither tells its sign nor belongs in the gradient (a row of norm 1e3
    at a bound sets a floor that hides the force of the level's rows of norm 1e-4). Each step goes
    to the exact point of the working set (:func:`_constrained_lstsq`) and stops at the first
    free row it would push out of its bounds, which enters the working set. Nocedal & Wright,
    Numerical Optimization, alg. 16.3. Stops where the KKT conditions hold to 1e-9 of the
    gradient plus its round-off (no rounder: on a badly scaled level, :func:`_kkt_certified`'s
    floor passed a point 14 % above the optimum), where no row is left to drop, or after
    ``3 * rows + 10`` steps (cycling on a degenerate set). A row that a step blocks on at tau = 0
    while it is the last row dropped (the multipliers' residual, not an exact multiplier, chose it) is not
    dropped again until a step cut short by a blocking row moves x (tau > 0; badly_scaled n=5 seed
    343 dropped and took back one row to the step cap at a vertex; clearing that at every full
    step too, 5 fewer solves of the conditioning sweep agree with ``hcod``). Where it stops with
    the KKT conditions unmet, it goes on from there once more with the working set's least
    squares deciding rank row by row (``rowwise``, :func:`_rowwise_lstsq_update`), kept where
    cheaper beyond round-off (1e-12). Returns a feasible x, in exact arithmetic no dearer than
    the one given."""
    feas_hi = _FEAS_RTOL * _row_scale(A_hi, lo_hi, up_hi, x)
    r = A_hi @ x
    eq_hi = lo_hi == up_hi
    # s: 0 free, +1 at the upper bound, -1 at the lower bound, 2 equality
    s_hi = np.where(eq_hi, 2, np.where(np.abs(up_hi - r) <= feas_hi, 1, np.where(np.abs(r - lo_hi) <= feas_hi, -1, 0)))
    if final:
        s_k = np.zeros(0, dtype=int)
    else:
        feas_k = _FEAS_RTOL * _row_scale(A_k, lo_k, up_k, x)
        r = A_k @ x
        s_k = np.where(lo_k == up_k, 2, np.where(r >= up_k - feas_k, 1, np.where(r <= lo_k + feas_k, -1, 0)))
    rows = np.vstack([A_hi, A_k])
    lo, up = np.concatenate([lo_hi, lo_k]), np.concatenate([up_hi, up_k])
    n_hi = A_hi.shape[0]
    s = np.concatenate([s_hi, s_k])  # (one array for every row: s_hi and s_k are its views)
    s_hi, s_k = s[:n_hi], s[n_hi:]
    dropped, stuck = -1, set()  # (the last row dropped; rows that blocked at once after their drop)
    certified = False
    for _ in range(3 * rows.shape[0] + 10):
        bound = np.where(s == 1, up, lo)
        on_hi, on_k = s_hi != 0, s_k != 0
        if final:
            G, t = np.eye(x.size), np.zeros(x.size)
        else:
            G, t = A_k[on_k], bound[n_hi:][on_k]
        x_new = _constrained_lstsq(x, A_hi[on_hi], bound[:n_hi][on_hi], G, t, rowwise)
        # ratio test on the free rows
        r0, r1 = rows @ x, rows @ x_new
        # a free row of level k that a step takes out of its bounds blocks beyond what _freeze counts
        # as a zero slack (1e-13 of its scale), not _FEAS_RTOL's 1e-11: left out by 3.7e-8 (1e-11 of
        # its scale 3.9e3), badly_scaled n=5 seed 2095's level 1 row 2 was frozen at that slack, its
        # optimum 0, and level 2 ended 2 % above its optimum
        feas = _row_scale(rows, lo, up, x_new) * np.where(np.arange(rows.shape[0]) < n_hi, _FEAS_RTOL, _FREEZE_RTOL)
        dr = r1 - r0
        with np.errstate(divide="ignore", invalid="ignore"):
            tau_u = np.where((s == 0) & (dr > 0) & (r1 > up + feas), (up - r0) / dr, np.inf)
            tau_l = np.where((s == 0) & (dr < 0) & (r1 < lo - feas), (lo - r0) / dr, np.inf)
        tau = np.minimum(tau_u, tau_l)
        j = int(np.argmin(tau))
        if tau[j] < 1.0:
            if j == dropped and tau[j] <= 0.0:
                stuck.add(j)  # (dropped by its bounded least-squares multiplier, pushed out by the step)
            elif tau[j] > 0.0:
                stuck.clear()
            dropped = -1
            x = x + max(float(tau[j]), 0.0) * (x_new - x)
            s[j] = 1 if tau_u[j] <= tau_l[j] else -1
            continue
        x = x_new
        # multipliers of level k's working rows: their slack, of the sign of their bound
        if not final:
            w = A_k @ x - bound[n_hi:]
            scale_k = _row_scale(A_k, lo_k, up_k, x)
            wrong = np.where(s_k == 1, -w, np.where(s_k == -1, w, 0.0)) / scale_k
            if wrong.size and wrong.max() > _DROP_RTOL:
                s_k[np.argmax(wrong)] = 0
                continue
            # a working row met to that much (|w_i| <= _DROP_RTOL of its scale) is a constraint:
            # its multiplier, not its slack, says whether it stays (the slack of a row of norm 1.4e3
            # pinned at its bound is round-off: badly_scaled n=5 seed 583 kept one at its lower bound,
            # level 1 at 4.08e-5 against the optimum 2.56e-5 with it at its upper bound)
            met = np.flatnonzero(on_k & (np.abs(w) <= _DROP_RTOL * scale_k))
            unmet = on_k.copy()
            unmet[met] = False
            g = A_k[unmet].T @ w[unmet]
            floor = _EPS * float(np.linalg.norm(A_k[unmet], axis=1) @ scale_k[unmet])
        else:
            met = np.zeros(0, dtype=int)
            g, floor = x, _EPS * (1.0 + float(np.linalg.norm(x)))
        # multipliers of A_hi's working rows and of level k's met ones
        held = np.flatnonzero(on_hi)
        if held.size + met.size == 0:
            certified = float(np.linalg.norm(g)) <= floor
            break
        side = np.concatenate([s_hi[held], s_k[met]])
        res, C = _kkt_residual(g, np.vstack([A_hi[held], A_k[met]]), side)
        if float(np.linalg.norm(res)) <= 1e-9 * float(np.linalg.norm(g)) + floor:
            certified = True
            break
        index = np.concatenate([held, n_hi + met])
        leave = np.where((side == 2) | np.isin(index, list(stuck)), -np.inf,
                         C @ res / (np.linalg.norm(C, axis=1) + 1e-300))
        i = int(np.argmax(leave))
        if not leave[i] > 0:
            break
        dropped = int(index[i])
        s[dropped] = 0
    if certified or rowwise:
        return x
    # stopped short of the KKT conditions: a direction the working set's least squares cut at the
    # level's rank threshold may be one a small row of the level sees (badly_scaled n=12 seed 964)
    x_row = _descend(x, A_hi, lo_hi, up_hi, A_k, lo_k, up_k, final, rowwise=True)
    cheaper = _stage_cost(x_row, A_k, lo_k, up_k, final) < _stage_cost(x, A_k, lo_k, up_k, final) * (1 - 1e-12)
    return x_row if cheaper else x


def _stage(A_hi, lo_hi, up_hi, A_k, lo_k, up_k, final: bool, name: str):
    """One stage of the cascade: the QP (:func:`_qp_level`), then polishing
    (:func:`_polish`, on the exact bounds). When no backend solves the QP, or its point can be
    neither polished nor kept (out of the bounds of A_hi beyond ``_ACTIVE_RTOL`` of their
    scale), it is solved again with the bounds of A_hi widened by each of WIDEN_RTOL in turn;
    a widened QP's point counts only once polished onto the exact bounds and
    certified optimal there (:func:`_kkt_certified`). Returns x, whether it was
    polished, the backend label, and the QP's own point on the exact bounds
    where polishing replaced it (else None). Raises YardstickError naming the
    stage (``name``) and every try."""
    failed = []
    for widen in (0.0, *WIDEN_RTOL):
        try:
            x_qp, backend = _qp_level(A_hi, lo_hi, up_hi, A_k, lo_k, up_k, final, widen)
        except YardstickError as err:
            failed.append(f"bounds widened by {widen:g}: {err}" if widen else str(err))
            continue
        x, ok = _polish(x_qp, A_hi, lo_hi, up_hi, A_k, lo_k, up_k, final, certify=widen > 0)
        if not ok:  # (the active set read again, looser: _ACTIVE_RETRY)
            for active_rtol in _ACTIVE_RETRY:
                x, ok = _polish(x_qp, A_hi, lo_hi, up_hi, A_k, lo_k, up_k, final, certify=widen > 0,
                                active_rtol=active_rtol)
                if ok:
                    break
        if not widen:
            # an unpolished point is kept within the tolerance the active set is read at; one further
            # out of the bounds above is no level's optimum (badly_scaled n=12 seed 6112: Clarabel's
            # almost-solved point of level 3 left level 0 by 3.3e-3, and level 4 had no feasible set)
            if ok or _meets(A_hi, lo_hi, up_hi, x_qp, _ACTIVE_RTOL):
                return x, ok, backend, (x_qp if ok else None)
            failed.append(f"{backend} solved it, but its point leaves the levels above by more than "
                          f"{_ACTIVE_RTOL:g} of their scale and could not be polished onto their bounds")
            continue
        if ok:
            return x, ok, f"{backend}, bounds widened by {widen:g}", None
        failed.append(f"bounds widened by {widen:g}: {backend} solved it, but its point could not be polished "
                      f"onto the exact bounds and certified optimal there (KKT check)")
    raise YardstickError(f"{name}: " + "; ".join(failed))


_DESCENT_FAILED = "the primal active set from the level above's point: not certified optimal (KKT check)"


def _descend_stage(x, A_hi, lo_hi, up_hi, A_k, lo_k, up_k, final: bool):
    """The last try on a stage no QP backend solved (:func:`_stage`): the primal active set
    :func:`_descend` from x, the level above's point (feasible: the levels above are frozen at
    it), kept only where the KKT conditions certify it at :data:`_KKT_TIGHT` (no QP point to
    compare it with). Returns what :func:`_stage` returns, or None. (badly_scaled n = 12 seed 89,
    with OpenBLAS's SkylakeX kernels: at level 4 Clarabel made insufficient progress and PIQP
    called the set infeasible, on the exact bounds and on widened ones.)"""
    x_d = _descend(x, A_hi, lo_hi, up_hi, A_k, lo_k, up_k, final)
    if not _kkt_certified(x_d, A_hi, lo_hi, up_hi, A_k, lo_k, up_k, final, rtol=_KKT_TIGHT):
        return None
    return x_d, True, "none solved it: primal active set from the level above's point, KKT-certified", None


def _freeze(A_k, lo_k, up_k, x):
    """Level k frozen at x (exact, the optimal slack being unique): a row with
    nonzero slack becomes an equality at its achieved value (then eliminated
    by the null-space step of the next QPs); a row with zero slack keeps its
    bounds. Returns the signed slack w (shape (rows,)) and the frozen bounds.

    A slack under 1e-13 of its row's scale counts as zero. One above that but under 1e-13 of
    the level's largest row scale may be the level's round-off reaching a small row through x
    (badly_scaled n = 12 seed 2802: level 2's row of norm 1.2e-3 at -8.7e-16 beside a row of
    norm 2.4e4, where the optimum has that row inside its bounds, 9.7e-4 from the one it was
    pinned at; level 3 ended 20 % above its optimum): such a row is frozen as ICRA 2010 eq. (35)
    has it, its bounds shifted by w, ``lo + w <= A_k x <= up + w``, which in exact arithmetic
    leaves the next levels the same optimum, and where w is round-off lets the row move inside
    its bounds."""
    achieved = A_k @ x
    w = _signed_slack(achieved, lo_k, up_k)
    scale = _row_scale(A_k, lo_k, up_k, x)
    w[np.abs(w) <= _FREEZE_RTOL * scale] = 0.0
    pinned = np.abs(w) > _FREEZE_RTOL * np.max(scale, initial=0.0)  # (else shifted by w, 0 or not)
    return w, np.where(pinned, achieved, lo_k + w), np.where(pinned, achieved, up_k + w)


def _safe_row_norms(A: np.ndarray) -> np.ndarray:
    """Each row's 2-norm without overflow (entries up to the largest double), shape (rows,)."""
    m = np.max(np.abs(A), axis=1, initial=0.0)
    return m * np.linalg.norm(A / np.where(m > 0, m, 1.0)[:, None], axis=1)


def _level_exponents(h: Hierarchy) -> np.ndarray:
    """Per level, 0 or the e_k that brings ``2^e_k ||A_k||_F`` into [1, 2), shape (depth,),
    ints, computed without overflow (rows of norm 1e308): every level when the median row norm
    of the problem lies outside [1 / ROWS_BAND, ROWS_BAND] (A in other units), else each level
    whose ``||A_k||_F`` lies outside [1 / LEVEL_BAND, LEVEL_BAND]; 0 for a level of zero rows.
    Level k times ``2^e_k``, bounds alike, has the same minimisers: its slack is scaled, not
    reshaped."""
    e = np.zeros(h.depth, dtype=int)
    norms = _safe_row_norms(h.A)
    if not np.any(norms > 0):
        return e
    logs = np.sort(np.log2(norms[norms > 0]))
    log_med = float(logs[logs.size // 2])  # (a row's norm: the mean of two 1e308 overflows, that of
    every = abs(log_med) > np.log2(ROWS_BAND)  # rows of norm 1 and 1e-154 is neither's)
    for k in range(h.depth):
        nk = norms[h.level_rows(k)]
        m = float(np.max(nk, initial=0.0))
        if m > 0:
            log_fro = np.log2(m) + np.log2(np.linalg.norm(nk / m))
            if every or abs(log_fro) > np.log2(LEVEL_BAND):
                e[k] = -int(np.floor(log_fro))
    return e


def _units_exponent(h: Hierarchy) -> int:
    """0, or the e that brings ``2^e d`` into [1, 2), ``d`` the median of ``|bound_i| /
    ||a_i||`` over the finite nonzero bounds of nonzero rows (the distances of the bounds'
    hyperplanes from the origin, in units of x), when ``d < UNITS_MIN``, or its lower middle
    element when that is beyond ``UNITS_MAX`` (the mean of the two middle ones of distances 1
    and 1e143, a wide problem in its units, is neither's).
    The median, not the largest: a robot stack's distances spread over 1e-4 .. 500 around a
    median of 1-4, and bringing its largest to 1 left the yardstick at bounds x 1e-6 above the
    optimum again (humanoid_reach seed 0: level 0 at 1.7e-8 of its size, the levels below lower
    than they can be)."""
    b = np.concatenate([h.lower, h.upper])
    norms = np.tile(_safe_row_norms(h.A), 2)
    ok = (norms > 0) & np.isfinite(b) & (b != 0)
    with np.errstate(over="ignore"):
        d = np.abs(b[ok]) / norms[ok]
    d = d[np.isfinite(d)]
    if not d.size:
        return 0
    top = np.ldexp(1.0, int(np.frexp(np.max(d))[1]) - 1)  # (a power of 2: d / top is exact, <= 2)
    med = float(np.median(d / top))  # (scaled: the mean of two distances of 1e308 overflows)
    low = float(np.sort(d)[(d.size - 1) // 2])  # (the lower middle: not the mean of 1 and 1e143)
    if med * top >= UNITS_MIN and low <= UNITS_MAX:
        return 0
    if low > UNITS_MAX:
        return int(1 - np.frexp(low)[1])
    return int(1 - np.frexp(med)[1] - np.frexp(top)[1] + 1)


def _normalized(h: Hierarchy) -> tuple[Hierarchy, np.ndarray, int]:
    """h with each level scaled (:func:`_level_exponents`, e_k) and in units of x that bring its
    bounds to O(1) (:func:`_units_exponent`, e_x): rows ``2^e_k a_i``, bounds ``2^(e_k + e_x)
    bound_i``, both exact (powers of 2). Its minimisers are ``2^e_x`` times h's. Returns the
    scaled hierarchy, e (shape (depth,)) and e_x; h itself with zeros where no scaling is
    needed (problems within the bands are solved bit for bit as given), or where a scaled
    number would leave the doubles."""
    e, e_x = _level_exponents(h), _units_exponent(h)
    if not (e.any() or e_x):
        return h, e, 0
    row_e = e[h.level]
    A = np.ldexp(h.A, row_e[:, None])
    lower, upper = np.ldexp(h.lower, row_e + e_x), np.ldexp(h.upper, row_e + e_x)
    if not (np.all(np.isfinite(A)) and np.all(np.isfinite(lower) == np.isfinite(h.lower))
            and np.all(np.isfinite(upper) == np.isfinite(h.upper))):
        return h, np.zeros_like(e), 0
    return Hierarchy(A, lower, upper, h.level, n=h.n, depth=h.depth), e, e_x


def cascade_yardstick(h: Hierarchy) -> tuple[np.ndarray, dict]:
    """Minimum-norm lexicographic solution of any hierarchy.

    Returns x, shape (n,), and an info dict with, per stage (levels then the
    final minimum-norm stage), ``polished`` (bool: the exact active-set point
    was kept) and ``backend`` (the QP backend that solved it), and ``slack``
    (the signed optimal slack w_k* of each level). Raises YardstickError when
    no backend solves a stage, not even on widened bounds with a certified
    polished point (:func:`_stage`).

    The QPs' tolerances and the regularisation ``_Y_REG`` are absolute, so the
    problem is solved in numbers of O(1) (:func:`_normalized`): where the
    problem's median row norm lies outside [1 / ROWS_BAND, ROWS_BAND], every
    level, else each level whose ``||A_k||_F`` lies outside [1 / LEVEL_BAND,
    LEVEL_BAND], is multiplied by the power of 2 that brings its
    ``||A_k||_F`` to [1, 2), bounds alike
    (``info["levels_scaled_by"]``: the same minimisers, its slack scaled); a
    problem whose bounds lie, as a median, within ``UNITS_MIN`` of the origin
    or beyond ``UNITS_MAX`` (in x, :func:`_units_exponent`) is solved with its
    bounds times the power of 2 that brings that median to [1, 2), then x and
    the slacks divided by it (``info["bounds_scaled_by"]``: the problem is
    homogeneous in (x, bounds)). Without them, bounds x 1e-6 .. 1e-9 left the
    yardstick above the exact optimum on 20 of 20 IK-like and random problems,
    and A x 1e-12 or x 1e100 (random n = 12 seed 0) from level 1 or level 3 on.

    A level frozen at its polished (exact) optimum can leave the next stage a
    feasible set with no interior to round-off, a sliver no backend solves
    (seen on a humanoid's step: ~1e-6 wide after 21 equalities, a level of
    conflicting equalities met at 17 joint bounds). The next stage is then
    tried once more with that level frozen at its QP's own point instead,
    within the QP's tolerances of the optimum; the level is then recorded
    unpolished, its backend label saying why."""
    check_fits_in_memory(h.n, "yardstick", matrices=YARDSTICK_MATRICES)
    hs, e, e_x = _normalized(h)
    if hs is not h:
        x, info = _cascade(hs)
        info["slack"] = [np.ldexp(w, -(int(ek) + e_x)) for w, ek in zip(info["slack"], e)]
        info["levels_scaled_by"] = [float(np.ldexp(1.0, int(ek))) for ek in e]
        info["bounds_scaled_by"] = float(np.ldexp(1.0, e_x))
        return np.ldexp(x, -e_x), info
    return _cascade(h)


def _cascade(h: Hierarchy) -> tuple[np.ndarray, dict]:
    """:func:`cascade_yardstick` on a hierarchy as given (no scaling)."""
    n = h.n
    levels = [(h.A[s], h.lower[s], h.upper[s]) for s in map(h.level_rows, range(h.depth))]
    frozen: list[tuple[np.ndarray, np.ndarray]] = []  # (lower, upper) of each level above
    x = np.zeros(n)
    polished, slacks, backends = [], [], []
    last, last_qp = None, None  # the last level with rows, and its QP point where polishing replaced it

    def above():
        """A, lower, upper of the levels frozen so far."""
        if not frozen:
            return np.zeros((0, n)), np.zeros(0), np.zeros(0)
        return (np.vstack([levels[j][0] for j in range(len(frozen))]), np.concatenate([f[0] for f in frozen]),
                np.concatenate([f[1] for f in frozen]))

    def stage(k, final):
        A_k, lo_k, up_k = levels[k] if not final else (np.zeros((0, n)), np.zeros(0), np.zeros(0))
        name = "the minimum-norm stage" if final else f"level {k}"
        try:
            return _stage(*above(), A_k, lo_k, up_k, final, name)
        except YardstickError as err:
            failed = str(err)
        if last_qp is not None:
            kept = frozen[last]
            w, lo_f, up_f = _freeze(*levels[last], last_qp)
            frozen[last] = (lo_f, up_f)
            try:
                result = _stage(*above(), A_k, lo_k, up_k, final, name)
            except YardstickError as again:
                frozen[last] = kept
                failed += f"; with level {last} frozen at its QP's point, not its polished one: {again}"
            else:
                slacks[last], polished[last] = w, False
                backends[last] += f" (its QP's point kept: {name} had no solvable frozen set at the polished one)"
                return result
        descended = _descend_stage(x, *above(), A_k, lo_k, up_k, final)
        if descended is None:
            raise YardstickError(f"{failed}; {_DESCENT_FAILED}")
        return descended

    for k in range(h.depth):
        A_k, lo_k, up_k = levels[k]
        if A_k.shape[0] == 0:
            frozen.append((lo_k, up_k))
            slacks.append(np.zeros(0))
            polished.append(True)
            backends.append("none")
            continue
        x, ok, backend, x_qp = stage(k, False)
        backends.append(backend)
        polished.append(ok)
        w, lo_f, up_f = _freeze(A_k, lo_k, up_k, x)
        slacks.append(w)
        frozen.append((lo_f, up_f))
        last, last_qp = k, x_qp
    if sum(len(f[0]) for f in frozen):
        x, ok, backend, _ = stage(h.depth, True)
        backends.append(backend)
        polished.append(ok)
    return x, {"polished": polished, "slack": slacks, "backend": backends}


def yardstick_solution(h: Hierarchy) -> np.ndarray:
    """The yardstick's x: null-space recursion for equality-only hierarchies,
    polished QP cascade otherwise."""
    if not h.has_inequalities:
        return nullspace_yardstick(h)
    return cascade_yardstick(h)[0]


class YardstickSolver(Solver):
    """The yardstick behind the solver interface (slow: for tests, single
    problems and the runner's verification; registered as ``yardstick``)."""

    name = "yardstick"
    description = "independent yardstick: SVD null-space recursion / polished Clarabel QP cascade"
    supports_inequalities = True

    def solve(self, hierarchy: Hierarchy) -> SolveResult:
        self.check_hierarchy(hierarchy)
        try:
            if hierarchy.has_inequalities:
                x, info = cascade_yardstick(hierarchy)
            else:
                x, info = nullspace_yardstick(hierarchy), {}
        except (YardstickError, np.linalg.LinAlgError, ValueError) as err:
            return SolveResult(x=None, status=ERROR, reason=f"yardstick: {err}")
        return SolveResult(x=x, status=OPTIMAL, info=info)


SOLVERS = [SolverInfo.of(YardstickSolver)]
