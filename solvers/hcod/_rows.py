"""The pieces every phase of the inequality kernel (:mod:`._kernel`) shares:
the row states and the kernel's constants, the floors of a row's residual
(the tolerances, docs/hcod.md "Tolerances"), the level's COD (19) of
``J_hat_k Z`` from scratch and updated, the LSE's right-hand side and
direction (eqs. 28, 30-31) and the step length (sec. VIII).

Row states (``state``): INACTIVE (a constraint with zero slack, inside its
bounds), WORK (in the working set of constraints ``J_bar`` of the levels
above, its row in the decomposition ``W``/``R``), IMPLIED (a frozen row that
is a combination of working rows: not in ``W``, kept implicitly; it
re-enters ``W`` when a working row leaves and its projection on ``Z`` is
beyond the rank threshold at its own norm), OBJECTIVE (a row of the current
level in the least-squares objective ``J_hat_k``, eq. 43), DEPENDENT (an
inequality row above that blocked a step but is a combination of the
working rows to the rank threshold at its own norm: it cannot enter ``W``,
and a step in ``Z`` moves it by at most that threshold times the step; it
blocks no more until a working row leaves or the level ends, then it is
INACTIVE again). ``side``: +1 upper bound, -1 lower bound, 0 equality /
frozen (never leaves).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from hikbench.solvers.hcod import _cache  # noqa: F401  (before any @njit: cache stamps over every hcod file)
from hikbench.solvers.hcod._basis import (
    basis_n,
)
from hikbench.solvers.hcod._linalg import (
    FASTMATH,
    ROW_RANK_RTOL,
    apply_reflectors,
    cod,
    cod_append,
    row_dot,
    vdot,
)

_FM = set(FASTMATH)

INACTIVE, WORK, IMPLIED, OBJECTIVE, DEPENDENT = 0, 1, 2, 3, 4
ST_OPTIMAL, ST_MAXIT, ST_NUMERICAL = 0, 1, 2
G_ROUNDING = 1e-2  #: a row's rounding in the noise floor of g, a fraction of its _floor (1e-15)
BLAND_AFTER = 32  #: consecutive iterations that leave u where it is before the anti-cycling rule takes over
#: a ``time`` re-solve is done again cold when a level's optimum u_k has ``||u_hat|| > COLD_AFTER_WARM
#: (1 + ||u_k||)`` for a warm point u_hat of this level or one above: its steps cancelled. (At 1e6 the
#: rounding left, eps 1e6 = 2.2e-10 relative, stays below the 1e-9 of verify's high profile.)
COLD_AFTER_WARM = 1e6
#: the same ratio within a solve: a level's optimum u_k with ``||u|| > CANCELLED (1 + ||u_k||)`` at a
#: point of this level or one above (a step along a pivot of ``J_k Z`` at its rank threshold, taken
#: back by a level below or the min-norm stage) left eps ||u|| along the working rows. The solve is
#: done again cold with each LSE step below working rows cut to ``CANCELLED (1 + ||u||)``
CANCELLED = COLD_AFTER_WARM
#: a met row's projection on ``Z`` under this fraction of its norm does not fix its multiplier (_met_force)
MET_DETERMINED = 1e-6
#: a level whose row norms span more than this ratio has its met rows' multipliers fitted at its end
#: (_met_force)
MET_SPREAD = 1e3


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def _norm(x):
    return math.sqrt(vdot(x, x))


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def _floor(rnorm_i, unorm, b, rtol):
    """``rtol (||a|| (1 + ||u||) + |b|)``, a floor of a row's residual ``a u - b``:
    with dual_rtol (1e-13) its rounding floor, a bound of the rounding errors
    of ``a u`` and ``b`` (a row within it of a bound is met there); with
    freeze_rtol (1e-11) the zero slack of a freeze."""
    return rtol * (rnorm_i * (1.0 + unorm) + abs(b))


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def _within(av, lo_i, up_i, rnorm_i, unorm, rtol):
    """``lo_i <= a u <= up_i`` (``av = a u``) to the rounding floor of the bound it
    passes (:func:`_floor` with ``rtol = dual_rtol``): the row is met."""
    if av > up_i:
        return av <= up_i + _floor(rnorm_i, unorm, up_i, rtol)
    if av < lo_i:
        return av >= lo_i - _floor(rnorm_i, unorm, lo_i, rtol)
    return True


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def _level_cod(Mr, Mf, nO, p, nf, thr, piv, diag, beta, rrt, Olist, rnorm):
    """The COD (19) from scratch of the level's nO objective rows projected on
    Z (``Mf[:nO, p:]``, copied to ``Mr``; ``piv`` starts as the identity;
    ``rrt``: the row-by-row rank test of a wide level, 0 if not, see
    :func:`._linalg.cod`). Returns (r, flops)."""
    for j in range(nO):
        piv[j] = j
        mrj = Mr[j, :nf]
        mfj = Mf[j, p:]
        for c in range(nf):
            mrj[c] = mfj[c]
    return cod(Mr, nO, nf, thr, piv, diag, beta, rrt, Olist, rnorm)


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def _level_cod_append(lse, j0, nO, p, nf, thr, r, rrt, Olist, rnorm):
    """The level's COD of rank r over its objective rows ``:j0`` updated for
    the rows ``j0:nO`` that entered since (:func:`._linalg.cod_append`, one
    row at a time, copied from ``Mf[j, p:]``). Returns (r, flops, weak: a new
    pivot has a small diagonal). ``lse``: the level's COD and LSE blocks
    (:func:`._workspace.lse_blocks`)."""
    Mr, Mf, piv, diag, beta, bvec, Lb, y = lse
    fl = 0
    weak = False
    for j in range(j0, nO):
        piv[j] = j
        mrj = Mr[j, :nf]
        mfj = Mf[j, p:]
        for c in range(nf):
            mrj[c] = mfj[c]
        r, f, w = cod_append(Mr, j, nf, thr, r, piv, diag, beta, rrt, Olist, rnorm)
        fl += f
        weak = weak or w
    return r, fl, weak


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def _release_dependent(state, s0):
    """DEPENDENT rows of the levels above (rows < s0) become INACTIVE; returns 0."""
    for i in range(s0):
        if state[i] == DEPENDENT:
            state[i] = INACTIVE
    return 0


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def _levels_met(A, bcol, bval, kind, lo, up, rnorm, i0, i1, u, dual_rtol):
    """Every row i0 <= i < i1 met at u (:func:`_within`; free rows aside):
    the levels holding them have a zero objective at u (eq. 33: all slacks
    w = 0)."""
    unorm = _norm(u)
    for i in range(i0, i1):
        if kind[i] != 2 and not _within(row_dot(A[i], bcol[i], bval[i], u), lo[i], up[i], rnorm[i], unorm,
                                         dual_rtol):
            return False
    return True


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def _leave_objective(j, Olist, nO, Mf, mf_valid, state):
    """The objective row at position j of Olist leaves (INACTIVE): the last
    one takes its place, in Mf too (whole rows: the freeze reads
    ``Mf[:, :p]``). Returns the new nO (the COD is to be redone)."""
    state[Olist[j]] = INACTIVE
    Olist[j] = Olist[nO - 1]
    if mf_valid:
        Mf[j, :] = Mf[nO - 1, :]
    return nO - 1


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def _lse_residual(A, Olist, piv, nO, target, bcol, bval, u, bvec):
    """The right-hand side of the level's LSE (28) in the COD's pivot order:
    ``bvec[j] = e_i - J_i u`` for the objective row ``i = Olist[piv[j]]``,
    ``j < nO``."""
    for j in range(nO):
        i = Olist[piv[j]]
        bvec[j] = target[i] - row_dot(A[i], bcol[i], bval[i], u)


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def _lse_direction(Mr, beta, r, nf, y, z, ps, p, n, lazy, basis):
    """The LSE step of eqs. (30)-(31), ``ps = Z Y [y; 0]`` (n,), from the COD's
    solution ``y`` (r,): Y's reflectors (in ``Mr``, ``beta``) on ``z`` (nf,),
    then Z = the columns p: of W. Returns the multiply-add count."""
    Wt, qv, qi, sv, sv2 = basis
    for c in range(nf):
        z[c] = y[c] if c < r else 0.0
    fl = apply_reflectors(Mr, beta, r, nf, z)
    ps[p:] = z[:nf]
    return fl + basis_n(lazy, Wt, qv, qi, ps, p, n, sv, sv2)


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def _step_length(has_ineq, prob, state, s0, s1, u, ps, rank_rtol, feas_rtol, bland):
    """The step length tau (sec. VIII) of ``u + tau ps``: 1, or the ratio of the
    first inactive inequality row of the levels ``< s1`` the step takes to its
    bound. ``bland``: a row already past it blocks at 0 (the anti-cycling rule,
    then the first such row). Returns (tau, the blocking row or -1, its side
    +1 / -1, whether the step moves u past rounding, ||u||, multiply-adds)."""
    A, lo, up, bcol, bval, kind, rnorm = prob
    tau = 1.0
    blk = -1
    bsd = 0
    un = 0.0
    moved = False
    if not has_ineq:
        return tau, blk, bsd, moved, un, 0
    pn = _norm(ps)
    # a step at rounding level (a warm re-solve: the recorded optimum) moves no row by more
    # than the feasibility tolerance: no scan
    un = _norm(u)
    moved = pn > 1e-15 * (1.0 + un)
    if not moved:
        return tau, blk, bsd, moved, un, 0
    for i in range(s1):
        if state[i] != INACTIVE or kind[i] != 1:
            continue
        ap = row_dot(A[i], bcol[i], bval[i], ps)
        # rows the step leaves in place: the step is orthogonal to them, or they lie in the span
        # of the working rows to the rank threshold at their own norm and the step moves them by
        # less than 1e-3 of the feasibility tolerance (a row held at its bound by the working
        # rows, rounding aside, must not block: it could not enter W)
        if abs(ap) <= 1e-13 * rnorm[i] * pn or (
                abs(ap) <= rank_rtol * rnorm[i] * pn
                and abs(ap) <= 1e-3 * feas_rtol * (rnorm[i] * (1.0 + un) + 1.0)):
            continue
        av = row_dot(A[i], bcol[i], bval[i], u)
        if ap > 0.0 and up[i] < np.inf:
            rt = (up[i] - av) / ap
            sd = 1
        elif ap < 0.0 and lo[i] > -np.inf:
            rt = (lo[i] - av) / ap
            sd = -1
        else:
            continue
        if rt < 0.0 and bland:
            rt = 0.0  # (Bland: of the rows at ratio 0, the first)
        if rt < tau:
            tau = max(rt, 0.0)
            blk = i
            bsd = sd
    return tau, blk, bsd, moved, un, 2 * u.shape[0] * (s1 - s0)


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def _level_spread(rnorm, s0, s1, rank_rtol):
    """Whether the nonzero row norms ``||a_i||`` of the level's rows ``s0:s1``
    span more than MET_SPREAD (``wide``: its met rows' multipliers are fitted
    at its end, :func:`_met_force`), and the row-by-row rank tolerance of its
    COD (19) (``rrt``; 0: none, see :func:`._linalg.cod`). Returns (wide, rrt)."""
    rmax = 0.0
    rmin = math.inf
    for i in range(s0, s1):
        if rnorm[i] > 0.0:
            rmax = max(rmax, rnorm[i])
            rmin = min(rmin, rnorm[i])
    wide = rmax > MET_SPREAD * rmin  # (rows of norms far apart: _met_force at the level's end)
    rrt = max(ROW_RANK_RTOL, rank_rtol) if wide else 0.0  # (the COD's rank: row by row too)
    return wide, rrt
