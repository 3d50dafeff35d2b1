"""The compiled solve: the sequence of LSIs (33)-(35), level by level, by a
primal active set on the HCOD (ICRA 2010, sec. VII-XI). One call per solve.

Row states (``state``): INACTIVE (a constraint with zero slack, inside its
bounds), WORK (in the working set of constraints ``J_bar`` of the levels above,
its row in the decomposition ``W``/``R``), IMPLIED (a frozen row that is a
combination of working rows: not in ``W``, kept implicitly; it re-enters ``W``
when a working row leaves and its projection on ``Z`` is beyond the rank
threshold at its own norm), OBJECTIVE (a row
of the current level in the least-squares objective ``J_hat_k``, eq. 43),
DEPENDENT (an inequality row above that blocked a step but is a combination of
the working rows to the rank threshold at its own norm: it cannot enter ``W``,
and a step in ``Z`` moves it by at most that threshold times the step; it blocks no more
until a working row leaves or the level ends, then it is INACTIVE again).
``side``: +1 upper bound, -1 lower bound, 0 equality / frozen (never leaves).

Level k (``starts[k] <= i < starts[k+1]``):

1. start from the optimum ``u_{k-1}`` of the previous level with its working
   set (sec. X); rows of level k violated at ``u_{k-1}`` and the equality rows
   enter the objective (eq. 45). With warm start "time" (sec. XI) the working
   set recorded at the previous call is applied and ``u`` moves by
   ``tau * Delta u_k`` (eq. 46).
2. iterate: LSE step by the COD of ``J_hat_k Z`` (eqs. 19, 30-31); step length
   tau to the first blocking constraint (an inactive row of levels <= k);
   activation (a level-k row joins the objective, a higher row is inserted in
   ``W``); at a full step, deactivation by the sign of the multipliers:
   ``mu_k = w_k`` (eq. 38) for objective rows, ``lambda`` (eq. 39) from
   ``R`` for working rows. At the end of a level whose row norms span more
   than MET_SPREAD, or where a working row's multiplier is negative within
   the part of its noise floor that the met rows' residuals make, the rows
   met to their rounding floors are held as constraints with multipliers
   fitted on ``Z`` (:func:`_met_force`): their residuals, under the floors,
   would hide the force of the small rows.
3. freeze: objective rows with nonzero slack become equality constraints at
   their achieved value (bounds propagated by eq. 36), zero-slack inequality
   rows become working inequality constraints.

The basis ``W`` and the updates of the decomposition are behind :mod:`._basis`
(explicit, or factored as ``W0`` times a queue of reflectors and rotations).
Flops are multiply-adds counted in the kernels.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from hikbench.solvers.hcod import _cache  # noqa: F401  (before any @njit: cache stamps over every hcod file)
from hikbench.solvers.hcod._basis import (
    LAZY_MAX_ITER,
    LAZY_MIN_N,
    basis_explicit,
    basis_head,
    basis_n,
    basis_permuted,
    basis_reset,
    basis_rows,
    basis_t,
    delete_row,
    insert_row,
    insert_rows,
    multipliers,
    push_reflectors,
)
from hikbench.solvers.hcod._linalg import (
    FASTMATH,
    NEAR_RANK,
    NEAR_RANK_STEP,
    ROW_RANK_RTOL,
    apply_reflectors,
    cod,
    cod_append,
    matrix_view,
    mf_reflect,
    near_rank_cut,
    row_axpy,
    row_dot,
    solve_lower,
    unowned,
    vaxpy,
    vdot,
)
from hikbench.solvers.hcod._setup import FEND0, IOFF0, N_HEAD, N_OUT

from ._layout import (
    F_A,
    F_BETA,
    F_BQ,
    F_BVAL,
    F_BVEC,
    F_DIAG,
    F_G,
    F_HIST_DU,
    F_HV,
    F_LB,
    F_LNORM,
    F_LO,
    F_MF,
    F_MR,
    F_NU,
    F_PRM,
    F_PS,
    F_Q,
    F_QB,
    F_QV,
    F_R,
    F_RNORM,
    F_SV,
    F_TARGET,
    F_U,
    F_UP,
    F_UPREV,
    F_W,
    F_Y,
    F_Z,
    I_BCOL,
    I_CAND,
    I_COK,
    I_HIST_SIDE,
    I_HIST_STATE,
    I_HIST_VALID,
    I_IP,
    I_KIND,
    I_LEVID,
    I_OLIST,
    I_OUT,
    I_PIV,
    I_QI,
    I_SIDE,
    I_STARTS,
    I_STATE,
    I_WIDX,
    I_WSIDE,
    IP_D,
    IP_HAS_INEQ,
    IP_MAX_ITER,
    IP_MMAX,
    IP_MT,
    IP_N,
    IP_WARM,
    O_ACT,
    O_CAPPED,
    O_COLD,
    O_DEACT,
    O_FLOPS,
    O_ITERS,
    O_LEVEL,
    O_NEARCUT,
    O_STATUS,
    O_WARMFAIL,
    PRM_DUAL_RTOL,
    PRM_FEAS_RTOL,
    PRM_FREEZE_RTOL,
    PRM_RANK_RTOL,
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
#: a level whose row norms span more than this ratio has its met rows' multipliers fitted at its end (_met_force)
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
def _level_cod_append(Mr, Mf, j0, nO, p, nf, thr, r, piv, diag, beta, rrt, Olist, rnorm):
    """The level's COD of rank r over its objective rows ``:j0`` updated for
    the rows ``j0:nO`` that entered since (:func:`._linalg.cod_append`, one
    row at a time, copied from ``Mf[j, p:]``). Returns (r, flops, weak: a new
    pivot has a small diagonal)."""
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
def _met_force(lazy, A, bcol, bval, Olist, nO, target, rnorm, kind, side, unorm, dual_rtol, u, p, n,
               Wt, qv, qi, sv, sv2, force):
    """The level's gradient with its met rows held at their bounds as
    constraints: ``g3 = sum_unmet w_j a_j + sum_met mu_j a_j`` (g3 (n,)), mu
    the least squares fit of ``Z^T g3 = 0`` (the LSE optimum of a full step,
    eq. 31; Z = ``W[:, p:]``), sign-bounded like ``mu = w`` (eq. 38:
    ``side mu >= 0`` on an inequality row). A met row (``|w_j|`` within its
    rounding floor, :func:`_floor`) passes the force of the level's unmet
    rows on to the working rows wherever its projection on ``Z`` fixes its
    mu: its measured w_j is then that force up to u's error, which its floor
    hides where the unmet rows are ~1e-8 its size. A met row whose
    projection, less those of the met rows before it, is under
    MET_DETERMINED of ``||a_j||`` gets mu = 0 (its w_j is u's error along
    the working rows), and so does a row whose fitted mu has the wrong sign
    (the fit is done again without it).

    Only where a row is met and either ``force`` (a working row's
    multiplier is negative within the met rows' part of its noise floor) or
    the unmet rows' force (``sum |w_j| ||a_j||``, a bound of
    ``||g_unmet||``) is within the met rows' floors (``sum f_j ||a_j||``);
    otherwise returns ``(flops, -1, -1.0)`` and an empty
    g3 after one pass over the rows. Returns ``(flops, jo, ftol, g3)``:
    ftol the rounding of g_unmet (``G_ROUNDING`` of the unmet rows'
    floors), the noise floor of the multipliers from g3; jo the position in Olist of the met
    inequality row whose fitted mu (times its projection) has the wrong
    sign beyond ftol, the most so, its w not beyond its rounding
    (``G_ROUNDING`` of its floor) on the violated side (it leaves the
    objective; a w of exactly 0 cannot tell the sign, its mu can); -1:
    none."""
    fl = 0
    m = 0
    fu = 0.0  # the unmet rows' force (a bound of ||g_unmet||) ..
    ftol = 0.0  # .. and its rounding
    fmet = 0.0  # the met rows' floors
    for j in range(nO):
        i = Olist[j]
        w = row_dot(A[i], bcol[i], bval[i], u) - target[i]
        f = _floor(rnorm[i], unorm, target[i], dual_rtol)
        if abs(w) <= f:
            m += 1
            fmet += rnorm[i] * f
        else:
            fu += rnorm[i] * abs(w)
            ftol += rnorm[i] * G_ROUNDING * f
    fl += nO * n
    if m == 0 or (fu > fmet and not force):
        return fl, -1, -1.0, np.empty(0)
    g3 = np.zeros(n)
    nz = n - p
    mi = np.empty(m, np.int64)
    P = np.empty((m, nz))  # the met rows' projections Z^T a_j
    mj = np.empty(m, np.int64)  # (their positions in Olist)
    x = np.empty(n)
    t = 0
    for j in range(nO):
        i = Olist[j]
        w = row_dot(A[i], bcol[i], bval[i], u) - target[i]
        if abs(w) > _floor(rnorm[i], unorm, target[i], dual_rtol):
            row_axpy(w, A[i], bcol[i], bval[i], g3)
            continue
        mi[t] = i
        mj[t] = j
        for c in range(n):
            x[c] = 0.0
        row_axpy(1.0, A[i], bcol[i], bval[i], x)
        fl += basis_t(lazy, Wt, qv, qi, x, p, n, sv, sv2)
        for c in range(nz):
            P[t, c] = x[p + c]
        t += 1
    fl += nO * n
    for c in range(n):
        x[c] = g3[c]
    fl += basis_t(lazy, Wt, qv, qi, x, p, n, sv, sv2)  # x[p:] = Z^T g_unmet
    keep = np.ones(m, np.bool_)
    Q = np.empty((m, nz))
    Rm = np.zeros((m, m))
    mu = np.zeros(m)
    jo = -1
    worst = 0.0
    for it in range(m + 1):
        # Q R = the kept projections, in order (modified Gram-Schmidt, twice); an undetermined one
        # leaves the fit for good
        for t in range(m):
            if not keep[t]:
                continue
            for c in range(nz):
                Q[t, c] = P[t, c]
            for s in range(t):
                Rm[s, t] = 0.0
                if keep[s]:
                    for _r in range(2):
                        d = 0.0
                        for c in range(nz):
                            d += Q[s, c] * Q[t, c]
                        Rm[s, t] += d
                        for c in range(nz):
                            Q[t, c] -= d * Q[s, c]
            d = 0.0
            for c in range(nz):
                d += Q[t, c] * Q[t, c]
            d = math.sqrt(d)
            fl += 4 * t * nz + 2 * nz
            if d <= MET_DETERMINED * rnorm[mi[t]]:
                keep[t] = False
                continue
            Rm[t, t] = d
            for c in range(nz):
                Q[t, c] /= d
        # R mu = -Q^T Z^T g_unmet
        for t in range(m - 1, -1, -1):
            mu[t] = 0.0
            if not keep[t]:
                continue
            d = 0.0
            for c in range(nz):
                d -= Q[t, c] * x[p + c]
            for s in range(t + 1, m):
                if keep[s]:
                    d -= Rm[t, s] * mu[s]
            mu[t] = d / Rm[t, t]
        wrong = False
        for t in range(m):
            i = mi[t]
            if keep[t] and kind[i] == 1 and side[i] * mu[t] < 0.0:
                if it == 0:
                    val = side[i] * mu[t] * Rm[t, t]
                    if (val < -ftol and side[i] * (row_dot(A[i], bcol[i], bval[i], u) - target[i])
                            < G_ROUNDING * _floor(rnorm[i], unorm, target[i], dual_rtol) and val < worst):
                        worst = val
                        jo = mj[t]
                keep[t] = False
                wrong = True
        if jo >= 0 or not wrong:
            break
    for t in range(m):
        if keep[t]:
            i = mi[t]
            row_axpy(mu[t], A[i], bcol[i], bval[i], g3)
    return fl, jo, ftol, g3


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def _lse_residual(A, Olist, piv, nO, target, bcol, bval, u, bvec):
    """The right-hand side of the level's LSE (28) in the COD's pivot order:
    ``bvec[j] = e_i - J_i u`` for the objective row ``i = Olist[piv[j]]``,
    ``j < nO``."""
    for j in range(nO):
        i = Olist[piv[j]]
        bvec[j] = target[i] - row_dot(A[i], bcol[i], bval[i], u)


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def _lse_direction(Mr, beta, r, nf, y, z, ps, p, n, lazy, Wt, qv, qi, sv, sv2):
    """The LSE step of eqs. (30)-(31), ``ps = Z Y [y; 0]`` (n,), from the COD's
    solution ``y`` (r,): Y's reflectors (in ``Mr``, ``beta``) on ``z`` (nf,),
    then Z = the columns p: of W. Returns the multiply-add count."""
    for c in range(nf):
        z[c] = y[c] if c < r else 0.0
    fl = apply_reflectors(Mr, beta, r, nf, z)
    ps[p:] = z[:nf]
    return fl + basis_n(lazy, Wt, qv, qi, ps, p, n, sv, sv2)


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def _step_length(has_ineq, A, bcol, bval, kind, lo, up, rnorm, state, s0, s1, u, ps,
                 rank_rtol, feas_rtol, bland):
    """The step length tau (sec. VIII) of ``u + tau ps``: 1, or the ratio of the
    first inactive inequality row of the levels ``< s1`` the step takes to its
    bound. ``bland``: a row already past it blocks at 0 (the anti-cycling rule,
    then the first such row). Returns (tau, the blocking row or -1, its side
    +1 / -1, whether the step moves u past rounding, ||u||, multiply-adds)."""
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


# ---- the phases of a level (inlined into hcod_solve: numba splices their code in, no calls) ------


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


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def _jump_end(k, n, D, starts, prob, hist, u, ps, z, dual_rtol):
    """Warm start "time" over a run of exactly met levels (sec. XI). The levels
    k..m-1 met their objectives exactly at the last call (every row at or
    within its bounds: a zero objective) and the run ended at level m
    (``hist_valid[k] = 2 + m``). When the point of the last call's level m,
    ``u_{k-1} + sum_{l=k..m} Delta u_l`` (eq. 46 with tau = 1; left in ``ps``
    as the step), still meets every row of levels k..m-1, it is an optimum of
    each of them whatever their working sets: the re-solve jumps there at
    level k, with level m's working set for the rows above each level. It no
    longer inserts the rows these levels activated on their way and a level
    below deleted; their records stay those of the last call that did not
    jump. Returns (m, flops); m = -1: no jump."""
    A, lo, up, bcol, bval, kind, rnorm = prob
    hist_state, hist_side, hist_valid, hist_du = hist
    fl = 0
    s0 = starts[k]
    m = hist_valid[k] - 2
    ok = k < m < D
    for kk in range(k + 1, m + 1):
        ok = ok and hist_valid[kk] == 1
    if ok:
        for c in range(n):
            ps[c] = 0.0
        for kk in range(k, m + 1):
            vaxpy(1.0, hist_du[kk], ps)
        for c in range(n):
            z[c] = u[c] + ps[c]
        fl += n * (m - k + 1)
        ok = _levels_met(A, bcol, bval, kind, lo, up, rnorm, s0, starts[m], z, dual_rtol)
        fl += n * (starts[m] - s0)
    return (m if ok else -1), fl


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def _drop_working(warm, rk, s0, p, lazy, rank_rtol, prob, basis, aset, hist, R, q, Mf):
    """Working inequality rows dropped at the start of a level: all of them
    (warm start "none"), or those the level deactivated at the previous call
    (``Delta^- A``, sec. XI: not WORK in the record ``rk``); each leaves ``W``
    by Givens rotations (sec. IX). Then the IMPLIED rows above re-enter ``W``
    where their projection on ``Z`` passes the rank threshold at their own
    norm. Returns (p, flops)."""
    A, lo, up, bcol, bval, kind, rnorm = prob
    Wt, qv, qi, sv, sv2 = basis
    state, side, target, Olist, widx, wside = aset
    hist_state, hist_side, hist_valid, hist_du = hist
    fl = 0
    dropped = False
    for j in range(p - 1, -1, -1):
        i = widx[j]
        if wside[j] != 0 and (warm == 0 or hist_state[rk, i] != WORK):
            fl += delete_row(lazy, j, R, p, widx, wside, Mf, 0, Wt, qv, qi, sv, sv2)
            p -= 1
            state[i] = INACTIVE
            dropped = True
    if dropped:
        for i in range(s0):
            if state[i] == IMPLIED:  # (its rank threshold: see _delete_working)
                ok, f, bt = insert_row(lazy, A, i, bcol, bval, R, p, rank_rtol * rnorm[i], q,
                                       Wt, qv, qi, sv, sv2)
                fl += f
                if ok:
                    widx[p] = i
                    wside[p] = 0
                    p += 1
                    state[i] = WORK
    return p, fl


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def _warm_shift(k, jrun, jm, jump, rk, s0, n, p, lazy, prob, basis, state, hist, u, ps):
    """Eq. (46): ``u_hat = u_{k-1} + tau Delta u_k``, tau in [0, 1] keeping the
    inactive inequality rows above (not WORK in the record ``rk``) feasible.
    Delta u_k (n,) is first projected on Z, ``ps <- Z Z^T ps`` (the problem
    may have changed since it was recorded: the step must keep the rows
    frozen above). At the start of a jump (``k == jrun``) ``ps`` holds its
    step (:func:`_jump_end`); at its other levels and its end the step is 0.
    Returns (at_jump: u_hat is the point _jump_end accepted, flops)."""
    A, lo, up, bcol, bval, kind, rnorm = prob
    Wt, qv, qi, sv, sv2 = basis
    hist_state, hist_side, hist_valid, hist_du = hist
    fl = 0
    dun = 0.0
    if k != jrun:  # (jrun: ps holds the jump; the other levels of it and jm: no step)
        for c in range(n):
            ps[c] = 0.0 if jump or k == jm else hist_du[k, c]
    for c in range(n):
        dun += abs(ps[c])
    at_jump = k == jrun  # (u_hat is the point _levels_met accepted, u + ps, so far)
    if p > 0 and dun > 0.0:  # (p = 0: Z spans everything): ps <- Z Z^T ps
        at_jump = False
        fl += basis_t(lazy, Wt, qv, qi, ps, p, n, sv, sv2)
        ps[:p] = 0.0
        fl += basis_n(lazy, Wt, qv, qi, ps, p, n, sv, sv2)
    tau = 1.0
    # (a zero step, the levels of a jump and its end: every a_i ps is 0, no row to scan)
    for i in range(s0 if dun != 0.0 else 0):
        if state[i] != INACTIVE or kind[i] != 1 or hist_state[rk, i] == WORK:
            continue
        ap = row_dot(A[i], bcol[i], bval[i], ps)
        if ap == 0.0:
            continue
        av = row_dot(A[i], bcol[i], bval[i], u)
        if ap > 0.0 and up[i] < np.inf:
            rt = (up[i] - av) / ap
        elif ap < 0.0 and lo[i] > -np.inf:
            rt = (lo[i] - av) / ap
        else:
            continue
        if rt < tau:
            tau = max(rt, 0.0)
    at_jump = at_jump and tau == 1.0
    for c in range(n):
        u[c] += tau * ps[c]
    return at_jump, fl


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def _reactivate(jump, rk, s0, n, D, p, lazy, rank_rtol, dual_rtol, prob, basis, aset, hist, R, Qb, bq,
                cand, cok, u):
    """``Delta^+ A`` (sec. XI): the inequality rows above that the record
    ``rk`` has WORK and are inactive now enter ``W`` together (one blocked
    Householder QR, :func:`._basis.insert_rows`), at their recorded side. A
    level of a jump inserts none (level jm inserts its rows) but, while W is a
    permutation of the identity's columns, the bound rows of level jm's record
    that the jump point meets at their bound (to its rounding floor: their
    correction moves u by rounding only, and no row above can become
    infeasible): they enter by swaps of W's columns (._basis), and the levels
    down to jm then work on fewer columns. Returns (p, flops)."""
    A, lo, up, bcol, bval, kind, rnorm = prob
    Wt, qv, qi, sv, sv2 = basis
    state, side, target, Olist, widx, wside = aset
    hist_state, hist_side, hist_valid, hist_du = hist
    fl = 0
    pre = jump and basis_permuted(lazy, qi)
    unorm = _norm(u) if pre else 0.0
    m_in = 0
    for i in range(s0 if not jump or pre else 0):
        sd = hist_side[rk, i]
        if (hist_state[rk, i] == WORK and state[i] == INACTIVE and kind[i] == 1 and sd != 0
                and (up[i] < np.inf if sd > 0 else lo[i] > -np.inf) and m_in < n):  # (<= n: WORK rows)
            tg = up[i] if sd > 0 else lo[i]
            if jump and not (bcol[i] >= 0 and abs(bval[i] * u[bcol[i]] - tg)
                             <= _floor(rnorm[i], unorm, tg, dual_rtol)):
                continue
            # the level whose record drops the row (D: none); rows that leave
            # sooner enter later: a row deleted sits behind fewer rows (fewer
            # Givens rotations in delete_row). Insertion sort, descending, the keys
            # kept in cok until insert_rows overwrites it with its accept flags.
            dl = rk + 1
            while dl < D and hist_valid[dl] != 0 and hist_state[dl, i] == WORK:
                dl += 1
            j = m_in
            while j > 0 and cok[j - 1] < dl:
                cand[j] = cand[j - 1]
                cok[j] = cok[j - 1]
                j -= 1
            cand[j] = i
            cok[j] = dl
            m_in += 1
    if m_in > 0:
        _, f = insert_rows(lazy, A, cand, m_in, bcol, bval, R, p, rank_rtol, rnorm, Qb, bq, cok,
                           Wt, qv, qi, sv, sv2)
        fl += f
        for j in range(m_in):
            if cok[j]:
                i = cand[j]
                sd = hist_side[rk, i]
                widx[p] = i
                wside[p] = sd
                p += 1
                state[i] = WORK
                side[i] = sd
                target[i] = up[i] if sd > 0 else lo[i]
    return p, fl


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def _warm_correction(p, lazy, prob, basis, aset, R, u, z, hv, nu):
    """The warm point (eq. 46) moved onto the working rows' bounds: the
    least-squares correction ``u += W[:, :p] nu`` with ``R^T nu = hv``, hv (p,)
    the residuals ``e_i - a_i u`` of the working inequality rows (0 for the
    frozen ones), R (p, p) upper triangular (``C^T = W[:, :p] R``, sec. IX).
    Returns (whether u moved, flops)."""
    A, lo, up, bcol, bval, kind, rnorm = prob
    Wt, qv, qi, sv, sv2 = basis
    state, side, target, Olist, widx, wside = aset
    fl = 0
    big = 0.0
    for j in range(p):
        i = widx[j]
        hv[j] = 0.0 if wside[j] == 0 else target[i] - row_dot(A[i], bcol[i], bval[i], u)
        big = max(big, abs(hv[j]))
    if big > 0.0:
        # R^T nu = hv by columns of R^T (rows of R: contiguous)
        for l in range(p):
            nu[l] = hv[l] / R[l, l]
            vaxpy(-nu[l], R[l, l + 1:p], hv[l + 1:p])
        z[:] = 0.0
        z[:p] = nu[:p]
        fl += basis_n(lazy, Wt, qv, qi, z, 0, p, sv, sv2) + p * p // 2
        vaxpy(1.0, z, u)
    return big > 0.0, fl


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def _warm_feasible(s0, prob, state, u, unorm, feas_rtol):
    """Every inactive inequality row above (``< s0``) within its bounds at the
    warm point u (eq. 46, corrected), to ``feas_rtol (||a_i|| (1 + ||u||) +
    1)``, and finite: the level may start there (sec. XI)."""
    A, lo, up, bcol, bval, kind, rnorm = prob
    feasible = True
    for i in range(s0):
        if state[i] == INACTIVE and kind[i] == 1:
            av = row_dot(A[i], bcol[i], bval[i], u)
            tol = feas_rtol * (rnorm[i] * (1.0 + unorm) + 1.0)
            if av > up[i] + tol or av < lo[i] - tol or not math.isfinite(av):
                feasible = False
                break
    return feasible


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def _recorded_objective(k, s0, s1, nO, prob, aset, hist):
    """The rows of level k that were in its objective ``J_hat_k`` at the end
    of the last call enter it again (sec. XI), at their recorded side, unless
    their kind changed since (eq. 45 decides then). Returns nO."""
    A, lo, up, bcol, bval, kind, rnorm = prob
    state, side, target, Olist, widx, wside = aset
    hist_state, hist_side, hist_valid, hist_du = hist
    for i in range(s0, s1):
        if hist_state[k, i] == OBJECTIVE:
            sd = hist_side[k, i]
            if kind[i] == 0:
                sd = 0
            elif (kind[i] == 2 or sd == 0 or (sd > 0 and up[i] == np.inf)
                  or (sd < 0 and lo[i] == -np.inf)):
                continue  # (the row changed kind since the record: eq. 45 decides)
            state[i] = OBJECTIVE
            side[i] = sd
            target[i] = up[i] if sd > 0 else lo[i]
            Olist[nO] = i
            nO += 1
    return nO


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def _violated_objective(jump, s0, s1, nO, unorm, dual_rtol, prob, aset, u):
    """Eq. (45): the level's equality rows and its inequality rows violated at
    ``u_hat`` enter the objective ``J_hat_k`` (target: the violated bound); the
    others start INACTIVE. On a jump a row over its bound by its rounding
    floor only stays out. Returns nO."""
    A, lo, up, bcol, bval, kind, rnorm = prob
    state, side, target, Olist, widx, wside = aset
    for i in range(s0, s1):
        if state[i] == OBJECTIVE:
            continue
        state[i] = INACTIVE
        if kind[i] == 0:
            state[i] = OBJECTIVE
            side[i] = 0
            target[i] = lo[i]
            Olist[nO] = i
            nO += 1
        elif kind[i] == 1:
            av = row_dot(A[i], bcol[i], bval[i], u)
            if jump and _within(av, lo[i], up[i], rnorm[i], unorm, dual_rtol):
                # (a jump: a row over its bound by its rounding floor only, a row the jump
                # met, stays out: the same record at every call of a repeated problem;
                # unorm: ||u|| since the warm point's correction)
                continue
            if av > up[i]:
                state[i] = OBJECTIVE
                side[i] = 1
                target[i] = up[i]
                Olist[nO] = i
                nO += 1
            elif av < lo[i]:
                state[i] = OBJECTIVE
                side[i] = -1
                target[i] = lo[i]
                Olist[nO] = i
                nO += 1
    return nO


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def _level_start(k, warm, use_hist, n, D, p, lazy, jrun, jm, starts, tols, prob, basis, aset, hist, R, Mf, Qb,
                 bq, cand, cok, uprev, vec):
    """Phase 1 of level k: the start from the previous optimum ``u_{k-1}`` and
    its working set (sec. X), with warm start "time" (sec. XI) the working set
    recorded at the previous call (``Delta^- A`` dropped, ``Delta^+ A``
    inserted) and the warm point ``u_hat = u_{k-1} + tau Delta u_k`` (eq. 46)
    corrected onto the working rows; if it violates a row above, the level
    starts cold from ``u_{k-1}``. Then the objective ``J_hat_k``: the rows of
    the record (but on a level of a jump), and the equality and violated rows
    (eq. 45).

    Returns (p, nO, jrun, jm, jump, warm: 0 a cold start, 1 a feasible warm
    point, -1 an infeasible one, ||u_hat||, flops)."""
    A, lo, up, bcol, bval, kind, rnorm = prob
    u, ps, z, g, hv, nu, q = vec
    rank_rtol, feas_rtol, dual_rtol, freeze_rtol = tols
    state, side, target, Olist, widx, wside = aset
    hist_state, hist_side, hist_valid, hist_du = hist
    fl = 0
    s0 = starts[k]
    s1 = starts[k + 1]
    nO = 0
    warm_level = use_hist and hist_valid[k] != 0
    if warm_level and jm < 0 and hist_valid[k] >= 2:
        m, f = _jump_end(k, n, D, starts, prob, hist, u, ps, z, dual_rtol)
        fl += f
        if m >= 0:
            jrun = k
            jm = m
    jump = jrun <= k < jm  # (a level of the jump: its record is level jm's for the rows above)
    rk = jm if jump else k
    if (warm == 0 and k > 0) or warm_level:
        p, f = _drop_working(warm, rk, s0, p, lazy, rank_rtol, prob, basis, aset, hist, R, q, Mf)
        fl += f
    outcome = 0
    unorm = 0.0  # (read by eq. 45 on a jump only, which is a warm level)
    if warm_level:
        at_jump, f = _warm_shift(k, jrun, jm, jump, rk, s0, n, p, lazy, prob, basis, state, hist, u, ps)
        fl += f
        p_in = p
        p, f = _reactivate(jump, rk, s0, n, D, p, lazy, rank_rtol, dual_rtol, prob, basis, aset, hist, R, Qb,
                           bq, cand, cok, u)
        fl += f
        moved, f = _warm_correction(p, lazy, prob, basis, aset, R, u, z, hv, nu)
        fl += f
        if moved:
            at_jump = False
        unorm = _norm(u)
        feasible = _warm_feasible(s0, prob, state, u, unorm, feas_rtol)
        if feasible and k == jrun and not at_jump:
            feasible = _levels_met(A, bcol, bval, kind, lo, up, rnorm, s0, starts[jm], u, dual_rtol)
            fl += n * (starts[jm] - s0)
        if not feasible and jump:
            # the levels after this one re-enter with their own records; those before it
            # kept theirs from the last call that did not jump: no run marked any more
            hist_valid[jrun] = 1
            jrun = -1
            jm = -1
            jump = False
        if not feasible:
            # the shifted point violates a row above: this level starts cold from
            # u_{k-1} (feasible) without the rows just inserted (they were appended
            # last: dropping the trailing columns of R leaves W R unchanged)
            outcome = -1
            for j in range(p - 1, p_in - 1, -1):
                state[widx[j]] = INACTIVE
            p = p_in
            for c in range(n):
                u[c] = uprev[c]
        else:
            outcome = 1
        if not jump:
            # (a level of a jump is at a zero objective: its equality rows enter it by eq. 45, its
            # inequality rows, met at the jump point, stay inactive, kept met by the step lengths
            # of the levels below; those active at u_jm enter at level jm with its record)
            nO = _recorded_objective(k, s0, s1, nO, prob, aset, hist)
    nO = _violated_objective(jump, s0, s1, nO, unorm, dual_rtol, prob, aset, u)
    return p, nO, jrun, jm, jump, outcome, unorm, fl


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def _identity_lse(n, p, nO, lazy, bcol, bval, basis, Olist, target, u, g, ps):
    """The LSE step of an identity-like level (``levid``: J_k = d S, S a
    permutation, all n rows in the objective): ``J_k Z`` has orthogonal
    columns, so the solution of eq. (28) is ``z = (J_k Z)^T b / d^2``, i.e.
    ``ps = Z Z^T J_k^T (e_k - J_k u) / d^2``, the gradient gathered in g (n,)
    first. Returns flops."""
    Wt, qv, qi, sv, sv2 = basis
    fl = 0
    g[:] = 0.0
    for j in range(nO):
        i = Olist[j]
        g[bcol[i]] += (target[i] - bval[i] * u[bcol[i]]) * bval[i]
    d2 = bval[Olist[0]] * bval[Olist[0]]
    fl += basis_t(lazy, Wt, qv, qi, g, p, n, sv, sv2)
    for c in range(p, n):
        ps[c] = g[c] / d2
    fl += basis_n(lazy, Wt, qv, qi, ps, p, n, sv, sv2)
    return fl


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def _step_cap(cap_on, p, r, thr_k, u, y, diag):
    """A cut of the LSE solution y (r,) of eq. (30) below working rows. After a
    cancellation (``cap_on``, see CANCELLED) the pivots from the first that
    takes ``||y||`` past ``CANCELLED (1 + ||u||)`` are left out (``||ps|| =
    ||y||``: orthogonal reflectors, orthonormal Z; y[:c] solves the first c
    pivot rows). Otherwise, from a pivot within NEAR_RANK of the rank
    threshold on, :func:`._linalg.near_rank_cut` at ``NEAR_RANK_STEP (1 +
    ||u||)``; the step taken (tau ||ps||, after the blocking rows) is checked
    against it after the step length. Returns (wc: that pivot or -1, the cap)."""
    wc = -1  # (a near-rank pivot where the LSE step passes NEAR_RANK_STEP)
    ycap = 0.0
    if cap_on and p > 0:
        ycap = CANCELLED * (1.0 + _norm(u))
        acc = 0.0
        for c in range(r):
            acc += y[c] * y[c]
            if acc > ycap * ycap:
                for c2 in range(c, r):
                    y[c2] = 0.0
                break
    elif p > 0:
        for c in range(r):
            if abs(diag[c]) <= NEAR_RANK * thr_k:
                wc = c
                break
        if wc >= 0:
            ycap = NEAR_RANK_STEP * (1.0 + _norm(u))
            wc = near_rank_cut(y, diag, r, thr_k, ycap)
    return wc, ycap


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def _lse_step(k, n, p, nO, r, ncod, mf_valid, cod_weak, has_ineq, cap_on, lazy, thr_k, rrt_k, levid,
              prob, basis, Olist, target, u, ps, z, g, lse):
    """Phase 2, the LSE step (eqs. 43-44) of the objective rows ``J_hat_k``
    (``Olist[:nO]``) under the working rows: ``ps`` (n,) minimises
    ``||J_hat_k (u + ps) - e||`` over ``ps = Z z``, Z = ``W[:, p:]`` (nf = n -
    p columns). By the COD (19) of ``J_hat_k Z`` (Mf (nO, n) holds the
    projections ``W^T a_j``; the COD, rank r, in Mr): from scratch
    (``ncod = 0``) or updated for the rows that entered since (``ncod`` rows
    in it), then ``ps = Z Y L^-1 V^T (e - J_hat_k u)`` (eqs. 30-31), possibly
    cut (:func:`_step_cap`). Identity-like levels: :func:`_identity_lse`.

    Returns (r, ncod, mf_valid, cod_done, cod_weak, wc, ycap, flops)."""
    A, lo, up, bcol, bval, kind, rnorm = prob
    Wt, qv, qi, sv, sv2 = basis
    Mr, Mf, piv, diag, beta, bvec, Lb, y = lse
    fl = 0
    nf = n - p
    for c in range(n):
        ps[c] = 0.0
    if ncod == 0:  # (piv: the identity unless a COD below pivots; the freeze reads it)
        r = 0
        for j in range(nO):
            piv[j] = j
    cod_done = False
    wc = -1
    ycap = 0.0
    if has_ineq and nf > 0 and nO == n and levid[k] != 0:
        fl += _identity_lse(n, p, nO, lazy, bcol, bval, basis, Olist, target, u, g, ps)
        r = nf
        if ncod > 0:
            ncod = 0
            for j in range(nO):
                piv[j] = j
    elif nf > 0 and nO > 0:
        if not mf_valid:
            fl += basis_rows(lazy, A, Olist, 0, nO, bcol, bval, Wt, qv, qi, Mf, p, sv, sv2)
            mf_valid = True
        if ncod == 0:
            # the COD (19) of the projected objective rows, from scratch
            r, f = _level_cod(Mr, Mf, nO, p, nf, thr_k, piv, diag, beta, rrt_k, Olist, rnorm)
            fl += f
            cod_weak = False
        else:
            # only objective rows entered since the last COD (Z is the same): it is
            # updated, one reflector per independent row (sec. IX)
            r, f, weak = _level_cod_append(Mr, Mf, ncod, nO, p, nf, thr_k, r, piv, diag, beta,
                                           rrt_k, Olist, rnorm)
            fl += f
            cod_weak = cod_weak or weak
        ncod = nO
        cod_done = True
        _lse_residual(A, Olist, piv, nO, target, bcol, bval, u, bvec)
        if r > 0:
            fl += solve_lower(Mr, diag, nO, r, bvec, Lb, y)
            wc, ycap = _step_cap(cap_on, p, r, thr_k, u, y, diag)
            fl += _lse_direction(Mr, beta, r, nf, y, z, ps, p, n, lazy, Wt, qv, qi, sv, sv2)
    return r, ncod, mf_valid, cod_done, cod_weak, wc, ycap, fl


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def _near_rank_retry(wc, r, n, p, nO, s0, s1, lazy, has_ineq, bland, rank_rtol, feas_rtol, prob, basis,
                     state, Olist, target, u, ps, z, lse):
    """The step through a pivot near the rank threshold was taken past
    NEAR_RANK_STEP (1 + ||u||): the pivots from wc on are left out, y solved
    again by least squares on the ones before (the first wc columns of L), the
    step ps (eqs. 30-31) and its length (sec. VIII) found again. Returns
    (tau, blk, bsd, moved, ||u||, flops) as :func:`_step_length`."""
    A, lo, up, bcol, bval, kind, rnorm = prob
    Wt, qv, qi, sv, sv2 = basis
    Mr, Mf, piv, diag, beta, bvec, Lb, y = lse
    fl = 0
    if wc > 0:
        _lse_residual(A, Olist, piv, nO, target, bcol, bval, u, bvec)
        fl += solve_lower(Mr, diag, nO, wc, bvec, Lb, y)
    for c in range(wc, r):
        y[c] = 0.0
    fl += _lse_direction(Mr, beta, r, n - p, y, z, ps, p, n, lazy, Wt, qv, qi, sv, sv2)
    tau, blk, bsd, moved, un, f = _step_length(has_ineq, A, bcol, bval, kind, lo, up, rnorm,
                                               state, s0, s1, u, ps, rank_rtol, feas_rtol, bland)
    fl += f
    return tau, blk, bsd, moved, un, fl


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def _activate(blk, bsd, s0, p, nO, ncod, ndep, mf_valid, lazy, rank_rtol, prob, basis, aset, R, q, Mf):
    """Phase 3, activation (sec. VIII): the blocking row blk at its bound bsd
    (+1 upper, -1 lower). A row of level k joins the objective ``J_hat_k``
    (its projection appended to Mf: the COD is updated at the next
    iteration); a row above enters ``W`` by a Householder reflector (sec.
    IX), which Mf follows, or, in the span of the working rows to the rank
    threshold at its own norm, becomes DEPENDENT (not activated; it blocks no
    more while W keeps its rows). Returns (p, nO, ncod, ndep, activated, flops)."""
    A, lo, up, bcol, bval, kind, rnorm = prob
    Wt, qv, qi, sv, sv2 = basis
    state, side, target, Olist, widx, wside = aset
    fl = 0
    activated = True
    side[blk] = bsd
    target[blk] = up[blk] if bsd > 0 else lo[blk]
    if blk >= s0:
        state[blk] = OBJECTIVE
        Olist[nO] = blk
        if mf_valid:
            fl += basis_rows(lazy, A, Olist, nO, nO + 1, bcol, bval, Wt, qv, qi, Mf, p, sv, sv2)
        nO += 1
    else:
        ok, f, bt = insert_row(lazy, A, blk, bcol, bval, R, p, rank_rtol * rnorm[blk], q,
                               Wt, qv, qi, sv, sv2)
        fl += f
        if not ok:
            # in the span of the working rows to the rank threshold at its own norm
            # (at its level's, a row 1e-6 the size of its level's others was moved
            # past its bound by 1e-4 of itself: badly_scaled n = 12 seed 528): the
            # rank rule does not tell it from one of them (a row x0 <= 1 under a
            # working row x0 + 1e-12 x1 >= 1); it is not activated and blocks no
            # more while W keeps its rows (it was a numerical failure)
            state[blk] = DEPENDENT
            ndep += 1
            activated = False
        else:
            if mf_valid:
                fl += mf_reflect(Mf, nO, p, q, bt)
            ncod = 0
            widx[p] = blk
            wside[p] = bsd
            p += 1
            state[blk] = WORK
    return p, nO, ncod, ndep, activated, fl


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def _objective_multipliers(nO, degen, unorm, dual_rtol, prob, aset, u):
    """Phase 4a, the multipliers of the objective rows at a full step: ``mu =
    w = a_i u - e_i`` (eq. 38), of the wrong sign when ``side w < 0``. Returns
    (jw: the position in Olist of the row most below zero beyond its rounding
    floor (:func:`_floor`), per unit norm (Bland's rule: the smallest row), ja
    and wa: the row most below zero within that floor but beyond G_ROUNDING of
    it, and its side w, metneg: a met row's mu of the wrong sign within its
    floor); -1: none."""
    A, lo, up, bcol, bval, kind, rnorm = prob
    state, side, target, Olist, widx, wside = aset
    worst = 0.0
    jw = -1
    ja = -1  # the row most below zero within its rounding floor, beyond G_ROUNDING of it
    wa = 0.0
    metneg = False  # a met row's mu = w of the wrong sign, within its floor
    for j in range(nO):
        i = Olist[j]
        if kind[i] != 1:
            continue
        w = row_dot(A[i], bcol[i], bval[i], u) - target[i]  # eq. (38): mu = w
        val = side[i] * w
        tol = _floor(rnorm[i], unorm, target[i], dual_rtol)
        metneg = metneg or -tol <= val < 0.0
        if val < -tol and (val / rnorm[i] < worst if degen < BLAND_AFTER
                           else (jw < 0 or i < Olist[jw])):
            worst = val / rnorm[i]
            jw = j
        elif val < -G_ROUNDING * tol and (ja < 0 or val / rnorm[i] < wa / rnorm[Olist[ja]]):
            ja = j
            wa = val
    return jw, ja, wa, metneg


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def _objective_row_leaves(jw, nO, mf_valid, prob, aset, Mf, u):
    """Phase 4b, deactivation of the objective row at position jw of Olist
    (mu = w of the wrong sign, eq. 38): it leaves the objective (the COD is to
    be redone), or, a two-sided row that crossed its interval, stays with the
    other bound as target (w = a u - lo, feasible). Returns (nO, switched: it
    changed side)."""
    A, lo, up, bcol, bval, kind, rnorm = prob
    state, side, target, Olist, widx, wside = aset
    i = Olist[jw]
    av = row_dot(A[i], bcol[i], bval[i], u)
    switched = True
    if side[i] > 0 and av < lo[i]:
        # a two-sided row that crossed its interval: the other side is violated,
        # it stays in the objective with that target (w = a u - lo, feasible)
        side[i] = -1
        target[i] = lo[i]
    elif side[i] < 0 and av > up[i]:
        side[i] = 1
        target[i] = up[i]
    else:
        switched = False
        nO = _leave_objective(jw, Olist, nO, Mf, mf_valid, state)
    return nO, switched


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def _working_multipliers(n, p, nO, degen, unorm, dual_rtol, lazy, prob, basis, aset, R, u, g, nu, hv):
    """Phase 4c, the multipliers ``lambda`` of the working inequality rows
    (eq. 39): ``R nu = W[:, :p]^T g`` with ``g = J_hat_k^T w`` (n,), the
    level's gradient, when ``||g||`` passes its noise floor gtol: per
    objective row, ``||a_j||`` times the error of its residual w_j, G_ROUNDING
    of its rounding floor (:func:`_floor`: the rounding of ``a_j u - e_j``)
    plus, for a row met to within that floor, its measured |w_j| (the
    projection of u's error on a_j, which makes its term of g). An unmet row's
    residual is not u's error, only its rounding counts: counting it at its
    whole floor let a level's large rows hide the force of its small ones.

    Returns (anydel: a working row may leave, jw: the position in widx of the
    row most below -gtol (Bland's rule: the smallest row), jb and wb: the row
    most below zero within gtol, beyond G_ROUNDING of its rounding part gtol_r,
    and its value, amb: a multiplier below -gtol_r; flops)."""
    A, lo, up, bcol, bval, kind, rnorm = prob
    Wt, qv, qi, sv, sv2 = basis
    state, side, target, Olist, widx, wside = aset
    fl = 0
    jw = -1
    anydel = False
    for j in range(p):
        if wside[j] != 0:
            anydel = True
            break
    amb = False  # a multiplier below the rounding, within the met rows' part
    jb = -1  # the working row most below zero within gtol, beyond G_ROUNDING of its rounding part
    wb = 0.0
    if anydel and nO > 0:
        for c in range(n):
            g[c] = 0.0
        gtol = 0.0
        gtol_r = 0.0  # (the rounding part of gtol alone)
        for j in range(nO):
            i = Olist[j]
            w = row_dot(A[i], bcol[i], bval[i], u) - target[i]
            row_axpy(w, A[i], bcol[i], bval[i], g)
            fj = _floor(rnorm[i], unorm, target[i], dual_rtol)
            gtol_r += rnorm[i] * G_ROUNDING * fj
            gtol += rnorm[i] * (G_ROUNDING * fj + (abs(w) if abs(w) <= fj else 0.0))
        gn = _norm(g)
        if gn > gtol:
            fl += multipliers(lazy, R, p, g, nu, hv, Wt, qv, qi, sv, sv2)  # eq. (39)
            worst = 0.0
            for j in range(p):
                if wside[j] != 0:
                    val = wside[j] * nu[j] * rnorm[widx[j]]
                    amb = amb or val < -gtol_r
                    if val < -gtol and (val < worst if degen < BLAND_AFTER
                                        else (jw < 0 or widx[j] < widx[jw])):
                        worst = val
                        jw = j
                    elif val < -G_ROUNDING * gtol_r and (jb < 0 or val < wb):
                        jb = j
                        wb = val
    return anydel, jw, jb, wb, amb, fl


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def _fitted_multipliers(n, p, nO, degen, unorm, dual_rtol, lazy, force, anydel, prob, basis, aset, R, u, hv):
    """Phase 4d, at a badly scaled level's end: the met rows held at their
    bounds as constraints, their mu fitted (:func:`_met_force`, g3 the
    gradient with them). A met row pulled to the feasible side of its bound
    leaves the objective (mu = w, eq. 38: jo, its position in Olist), else a
    working row whose multiplier (39) from g3 is negative beyond the unmet
    rows' rounding ftol (jw, its position in widx). Returns (jo, jw, flops);
    -1: none."""
    A, lo, up, bcol, bval, kind, rnorm = prob
    Wt, qv, qi, sv, sv2 = basis
    state, side, target, Olist, widx, wside = aset
    jw = -1
    fl, jo, ftol, g3 = _met_force(lazy, A, bcol, bval, Olist, nO, target, rnorm, kind, side,
                                  unorm, dual_rtol, u, p, n, Wt, qv, qi, sv, sv2, force)
    if jo < 0 and ftol >= 0.0 and anydel:
        nu3 = np.empty(n)
        fl += multipliers(lazy, R, p, g3, nu3, hv, Wt, qv, qi, sv, sv2)
        worst = 0.0
        for j in range(p):
            if wside[j] != 0:
                val = wside[j] * nu3[j] * rnorm[widx[j]]
                if val < -ftol and (val < worst if degen < BLAND_AFTER
                                    else (jw < 0 or widx[j] < widx[jw])):
                    worst = val
                    jw = j
    return jo, jw, fl


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def _delete_working(jw, n, p, nO, ndep, s0, mf_valid, lazy, rank_rtol, prob, basis, aset, R, q, Mf):
    """Phase 4e, deactivation of the working row at position jw (its
    multiplier lambda of the wrong sign, eq. 39): it leaves ``W`` by Givens
    rotations (sec. IX); the projected objective rows ``Mf = W^T a_j`` follow
    (lazy: the rotations are applied to them too; explicit W: the new column
    p of Z is projected). DEPENDENT rows above move freely again, and an
    IMPLIED row re-enters W where its projection on Z is beyond the rank
    threshold at its own norm (at its level's, a row 1e-7 the size of the
    others, met beside it, so implied at the freeze, stayed out, and the step
    moved its residual by 6e-5 of itself: badly_scaled n = 12 seed 964).
    Returns (p, ndep, flops)."""
    A, lo, up, bcol, bval, kind, rnorm = prob
    Wt, qv, qi, sv, sv2 = basis
    state, side, target, Olist, widx, wside = aset
    i = widx[jw]
    fl = delete_row(lazy, jw, R, p, widx, wside, Mf, nO if mf_valid and lazy else 0, Wt,
                    qv, qi, sv, sv2)
    p -= 1
    state[i] = INACTIVE
    if ndep > 0:  # (W lost a row: a DEPENDENT row may move freely again)
        ndep = _release_dependent(state, s0)
    if mf_valid and not lazy:
        wp = Wt[p]
        for j in range(nO):
            io = Olist[j]
            Mf[j, p] = row_dot(A[io], bcol[io], bval[io], wp)
        fl += nO * n
    for i2 in range(s0):
        if state[i2] == IMPLIED:
            ok, f, bt = insert_row(lazy, A, i2, bcol, bval, R, p, rank_rtol * rnorm[i2],
                                   q, Wt, qv, qi, sv, sv2)
            fl += f
            if ok and mf_valid:
                fl += mf_reflect(Mf, nO, p, q, bt)
            if ok:
                widx[p] = i2
                wside[p] = 0
                p += 1
                state[i2] = WORK
    return p, ndep, fl


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def _level_iterations(k, s0, s1, n, p, nO, lazy, total, max_iter, acts, deacts, nearcut, upeak, has_ineq,
                      cap_on, wide, thr_k, rrt_k, tols, levid, itl, prob, basis, aset, R, vec, lse):
    """Phases 2-4 of level k, the active-set iterations (sec. VIII): the LSE
    step (:func:`_lse_step`), its length tau to the first blocking row
    (:func:`_step_length`) and the activation of that row
    (:func:`_activate`); at a full step, deactivation by the sign of the
    multipliers: ``mu = w`` (eq. 38) of the objective rows, ``lambda`` (eq.
    39) of the working rows, fitted at a badly scaled level's end
    (:func:`_fitted_multipliers`), a sign within its noise floor confirmed by
    one step of iterative refinement. After BLAND_AFTER iterations that leave
    u where it is, Bland's rule against cycling. Ends at a full step with no
    row to deactivate, or at the iteration cap (status ST_MAXIT).

    Returns (status, p, nO, r, cod_done, cod_weak, lazy, total, acts, deacts,
    nearcut, upeak, flops): cod_done, the last iteration computed the COD of
    the objective rows (rank r; Mr, piv, diag, beta), which the freeze reads."""
    A, lo, up, bcol, bval, kind, rnorm = prob
    Wt, qv, qi, sv, sv2 = basis
    state, side, target, Olist, widx, wside = aset
    u, ps, z, g, hv, nu, q = vec
    Mr, Mf, piv, diag, beta, bvec, Lb, y = lse
    rank_rtol, feas_rtol, dual_rtol, freeze_rtol = tols
    status = ST_OPTIMAL
    fl = 0
    r = 0
    cod_done = False
    mf_valid = False
    ncod = 0  # objective rows the level's COD in Mr holds (0: none valid)
    cod_weak = False  # a pivot appended with a small diagonal (cod_append)
    degen = 0
    ref_row = -1  # (refinement: the objective row whose residual it measures, its side * w,
    ref_val = 0.0  # and acts + deacts when it was recorded)
    ref_ad = -1
    wref_row = -1  # (the same for a working row's multiplier: its row, side * nu * norm, ad)
    wref_val = 0.0
    wref_ad = -1
    ndep = 0  # rows of levels above DEPENDENT in this level
    while True:
        if total >= max_iter:
            status = ST_MAXIT
            break
        total += 1
        itl[k] += 1
        if lazy and itl[k] > LAZY_MAX_ITER:
            # a level iterating like a cold one (a trajectory that drifted): W goes
            # explicit for the rest of the solve (see ._basis)
            fl += basis_explicit(Wt, qv, qi, sv, sv2)
            lazy = False
        # -- phase 2: the LSE step (eqs. 43-44)
        r, ncod, mf_valid, cod_done, cod_weak, wc, ycap, f = _lse_step(
            k, n, p, nO, r, ncod, mf_valid, cod_weak, has_ineq, cap_on, lazy, thr_k, rrt_k, levid, prob,
            basis, Olist, target, u, ps, z, g, lse)
        fl += f
        # -- phase 3: the step length (sec. VIII) and the activation
        bland = degen >= BLAND_AFTER
        tau, blk, bsd, moved, un, f = _step_length(has_ineq, A, bcol, bval, kind, lo, up, rnorm,
                                                   state, s0, s1, u, ps, rank_rtol, feas_rtol, bland)
        fl += f
        upeak = max(upeak, un)
        if wc >= 0 and tau * _norm(ps) > ycap:
            nearcut += 1
            tau, blk, bsd, moved, un, f = _near_rank_retry(wc, r, n, p, nO, s0, s1, lazy, has_ineq, bland,
                                                           rank_rtol, feas_rtol, prob, basis, state, Olist,
                                                           target, u, ps, z, lse)
            fl += f
        for c in range(n):
            u[c] += tau * ps[c]
        # anti-cycling: after a run of iterations that leave u where it is (degenerate
        # steps, tau = 0, and deactivations at a vertex, where the step is zero),
        # Bland's rule -- the blocking row of smallest index and the deactivation of
        # the smallest row index
        if moved and tau > 0.0:
            degen = 0
        else:
            degen += 1
        if blk >= 0:
            p, nO, ncod, ndep, activated, f = _activate(blk, bsd, s0, p, nO, ncod, ndep, mf_valid, lazy,
                                                        rank_rtol, prob, basis, aset, R, q, Mf)
            fl += f
            if activated:
                acts += 1
            continue
        if not has_ineq:
            break
        # -- phase 4: at a full step, deactivation by the sign of the multipliers
        unorm = _norm(u)
        jw, ja, wa, metneg = _objective_multipliers(nO, degen, unorm, dual_rtol, prob, aset, u)
        ad = acts + deacts
        if jw < 0 and ja >= 0:
            # a row negative under its rounding floor: the floor bounds the rounding of
            # w, not the error of u, which one step more from u (iterative refinement,
            # same working set and COD) measures: w's change. Beyond twice that the
            # sign is the optimum's and the row leaves. (A large row met at one bound
            # of its interval, pushed by a level's small rows, -2e-13 against a floor
            # of 4e-13 scaled, otherwise held them off their optimum.) After the
            # refinement, the same ad: this full step either releases a row or ends the
            # level (one refinement per working set)
            if ref_ad != ad:
                ref_row = Olist[ja]
                ref_val = wa
                ref_ad = ad
                continue
            if ref_row == Olist[ja] and wa < -2.0 * abs(wa - ref_val):
                jw = ja
        if jw >= 0:
            nO, switched = _objective_row_leaves(jw, nO, mf_valid, prob, aset, Mf, u)
            deacts += 1
            if switched:
                acts += 1
            else:
                ncod = 0
            continue
        anydel, jw, jb, wb, amb, f = _working_multipliers(n, p, nO, degen, unorm, dual_rtol, lazy, prob,
                                                          basis, aset, R, u, g, nu, hv)
        fl += f
        if jw < 0 and nO > 0 and p < n and (wide or amb):
            # a badly scaled level's end, where the force of its unmet rows is within the
            # floors of its met rows, or a multiplier negative within the met rows' part of
            # gtol (amb: their measured w is either u's error or the optimum's residual;
            # badly_scaled n = 12 seed 281: a met row's w, 2.3e-14 scaled, under its floor
            # but the LSE's own, put 2.2e-15 in gtol, above a box row's -7.9e-16)
            jo, jw, f = _fitted_multipliers(n, p, nO, degen, unorm, dual_rtol, lazy, amb or (wide and metneg),
                                            anydel, prob, basis, aset, R, u, hv)
            fl += f
            if jo >= 0:
                deacts += 1
                nO = _leave_objective(jo, Olist, nO, Mf, mf_valid, state)
                ncod = 0
                continue
        if jw < 0 and jb >= 0 and not amb and degen < BLAND_AFTER:
            # a working row's multiplier negative beyond G_ROUNDING of gtol's rounding part
            # but within it: that part bounds the rounding of g, not the error of u, which
            # one step more from u (iterative refinement, same W and COD) measures as the
            # multiplier's change; beyond twice that the sign is the optimum's and the row
            # leaves (badly_scaled n = 12 seed 1232: a box row's -2.8e-15 scaled, under a
            # rounding part of 3.8e-15 set by a row of norm 1.4e4, held level 3 at
            # 1.0449e-2 against its optimum 1.0428e-2). One refinement per working set
            if wref_ad != ad:
                wref_row = widx[jb]
                wref_val = wb
                wref_ad = ad
                continue
            if wref_row == widx[jb] and wb < -2.0 * abs(wb - wref_val):
                jw = jb
        if jw >= 0:
            p, ndep, f = _delete_working(jw, n, p, nO, ndep, s0, mf_valid, lazy, rank_rtol, prob, basis, aset,
                                         R, q, Mf)
            fl += f
            deacts += 1
            ncod = 0
            continue
        break
    if ndep > 0:
        ndep = _release_dependent(state, s0)
    return status, p, nO, r, cod_done, cod_weak, lazy, total, acts, deacts, nearcut, upeak, fl


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def _record_level(k, n, s1, nO, last, jrun, jm, run0, dual_rtol, prob, aset, hist, u, uprev):
    """Warm start "time" (sec. XI): the record of level k for the next call --
    the states and sides of the rows down to it, its step ``Delta u_k = u_k -
    u_{k-1}`` (eq. 46; at the end of a jump, added to the jump's), and the
    runs of levels whose objective rows are all met exactly (each within its
    rounding floor: a zero objective; per row, a floor summed over the level
    would hide the residual of a row 1e-8 the size of the others), marked
    ``hist_valid[first] = 2 + the level after the run`` (:func:`_jump_end`).
    Returns (jrun, jm, run0, flops)."""
    A, lo, up, bcol, bval, kind, rnorm = prob
    state, side, target, Olist, widx, wside = aset
    hist_state, hist_side, hist_valid, hist_du = hist
    fl = 0
    for i in range(s1):
        hist_state[k, i] = state[i]
        hist_side[k, i] = side[i]
    if k == jm:
        # the jump's end: the steps of levels jrun..jm still sum to u_jm - u_{jrun-1}
        for c in range(n):
            hist_du[k, c] += u[c] - uprev[c]
        jrun = -1
        jm = -1
        run0 = -1
        exact = False
    else:
        for c in range(n):
            hist_du[k, c] = u[c] - uprev[c]
        unorm = _norm(u)
        exact = True
        for j in range(nO):
            i = Olist[j]
            w = row_dot(A[i], bcol[i], bval[i], u) - target[i]
            if abs(w) > _floor(rnorm[i], unorm, target[i], dual_rtol):
                exact = False
                break
        fl += n * nO
    hist_valid[k] = 1
    if run0 >= 0 and (not exact or last):
        hist_valid[run0] = 2 + k
        run0 = -1
    if exact and run0 < 0 and not last:
        run0 = k
    return jrun, jm, run0, fl


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def _freeze(n, p, r, nO, cod_done, cod_weak, lazy, thr_k, rrt_k, freeze_rtol, prob, basis, aset, R, q, u, lse,
            Qbf):
    """Phase 5, the freeze of level k (eq. 36) through its last COD (19): its
    r pivot rows enter W by the COD's reflectors (``W[:, p:] <- W[:, p:] H``,
    eq. 23, pushed), their R columns ``(W[:, :p]^T a, R_cod[:, t])``; the other
    objective rows are combinations of them (IMPLIED). Rows with a nonzero
    slack become equalities at their achieved value (target ``a u``, side 0),
    zero-slack inequality rows stay (removable) inequality constraints; the
    zero slack is ``freeze_rtol`` times the row's floor (:func:`_floor`) plus
    the level's residual ``||w||`` (the rounding of an LSE with a conflict
    leaks into its met rows in proportion to it). Without a COD of the last
    iteration the rows are inserted one by one. Returns (p, flops)."""
    A, lo, up, bcol, bval, kind, rnorm = prob
    Wt, qv, qi, sv, sv2 = basis
    state, side, target, Olist, widx, wside = aset
    Mr, Mf, piv, diag, beta, bvec, Lb, y = lse
    fl = 0
    unorm = _norm(u)
    if cod_done and cod_weak:
        # the pivots become working rows: pivoting picks them (see cod_append)
        r, f = _level_cod(Mr, Mf, nO, p, n - p, thr_k, piv, diag, beta, rrt_k, Olist, rnorm)
        fl += f
    if cod_done:
        # the COD (19) of the last iteration is the update: its r pivot rows enter
        # W by its reflectors (W[:, p:] <- W[:, p:] H, eq. 23, pushed), their R columns
        # are (W[:, :p]^T a, R_cod[:, t]), the first from the projected rows kept in
        # Mf (Mf[j] = W^T a_j); the other rows are combinations of them
        for t in range(r):
            mt_ = Mf[piv[t]]
            # (explicit: Mf holds the projection on Z only, W[:, :p]^T a is computed)
            fl += basis_head(lazy, A, Olist[piv[t]], bcol, bval, Wt, qi, p, mt_)
            for l in range(p):
                R[l, p + t] = mt_[l]
            for l in range(t):
                R[p + l, p + t] = Mr[t, l]
            R[p + t, p + t] = diag[t]
        fl += push_reflectors(lazy, Wt, qv, qi, p, Mr, beta, r, Qbf, sv, sv2)
    # the level's residual ||w||: the rounding of an LSE with a conflict (nonzero w)
    # leaks into its met rows in proportion to it (a pair of parallel rows apart by
    # 4, the rows that meet them at zero left at 1e-11): it joins their zero slack
    wn = 0.0
    for j in range(nO):
        i = Olist[piv[j]]
        bvec[j] = row_dot(A[i], bcol[i], bval[i], u)
        w = bvec[j] - target[i]
        wn += w * w
    wn = math.sqrt(wn)
    for j in range(nO):
        i = Olist[piv[j]]
        av = bvec[j]
        w = av - target[i]
        sd = side[i]
        if kind[i] == 0 or abs(w) > _floor(rnorm[i], unorm, target[i], freeze_rtol) + freeze_rtol * wn:
            target[i] = av
            sd = 0
        if cod_done:
            ok = j < r
        else:
            ok, f, bt = insert_row(lazy, A, i, bcol, bval, R, p, thr_k, q, Wt, qv, qi, sv, sv2)
            fl += f
        side[i] = sd
        if ok:
            widx[p] = i
            wside[p] = sd
            p += 1
            state[i] = WORK
        else:
            state[i] = IMPLIED if sd == 0 else INACTIVE
    return p, fl


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def _pass_start(use_hist, n, mt, D, hist_valid, u, Wt, qi, state, side):
    """The cold initial state of a pass (sec. X): ``u_0 = 0``, ``W = I`` (eq.
    23 with no working row), nothing active. Returns lazy, the representation of W (._basis): factored for a
    warm re-solve of a large problem (few iterations per level: the queue is
    short), explicit otherwise (a cold solve iterates: products through a
    long queue or a dense W0 cost more than Z's columns)."""
    lazy = False
    if use_hist and n >= LAZY_MIN_N:
        for kk in range(D):
            lazy = lazy or hist_valid[kk] != 0
    u[:] = 0.0
    basis_reset(lazy, Wt, qi)
    for i in range(mt):
        state[i] = INACTIVE
        side[i] = 0
    return lazy


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def _write_out(out, status, total, acts, deacts, fl, fail_level, warm_failed, cold_again, capped, nearcut):
    """The counters of a call into their output slots (O_*, ._layout)."""
    out[O_STATUS] = status
    out[O_ITERS] = total
    out[O_ACT] = acts
    out[O_DEACT] = deacts
    out[O_FLOPS] = fl
    out[O_LEVEL] = fail_level
    out[O_WARMFAIL] = warm_failed
    out[O_COLD] = cold_again
    out[O_CAPPED] = capped
    out[O_NEARCUT] = nearcut


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def hcod_solve(fw, iw):
    """Solve the hierarchy held in the workspaces fw/iw (:mod:`._setup`: the
    int workspace starts with the offsets of the blocks of both, and the ends of
    the float blocks, which start on 64-byte boundaries; two array
    arguments keep the call overhead down). The blocks are named in
    :mod:`._layout`.

    Blocks read: A (mt, n), lo, up (mt,), starts (D+1,) and the per-row data,
    written by :func:`._setup.load`; ip (slots IP_*: n, mt, D, mmax,
    max_iter, warm_mode 0 none | 1 stage | 2 time, has_ineq); prm (slots
    PRM_*: rank_rtol, feas_rtol, dual_rtol, freeze_rtol). The solution is ``u``
    in fw, counters in ``out`` (slots O_*) followed by the iterations per level.

    Per level k, the phases (each a function inlined here): 1. its start and
    warm start (:func:`_level_start`); 2.-4. the active-set iterations
    (:func:`_level_iterations`: LSE step, step length and activation,
    multipliers and deactivation); the record of a "time" warm start
    (:func:`_record_level`); 5. the freeze (:func:`_freeze`). A second,
    cold pass follows a cancellation (COLD_AFTER_WARM, CANCELLED)."""
    fw = unowned(fw)  # (no reference counting of the block views and helper calls)
    iw = unowned(iw)
    foff = iw[:FEND0]
    fend = iw[FEND0:IOFF0]
    ioff = iw[IOFF0:N_HEAD]
    ip = iw[ioff[I_IP]:ioff[I_IP + 1]]
    n = ip[IP_N]
    mt = ip[IP_MT]
    D = ip[IP_D]
    mmax = max(ip[IP_MMAX], 1)
    max_iter = ip[IP_MAX_ITER]
    warm = ip[IP_WARM]
    has_ineq = ip[IP_HAS_INEQ] != 0
    prm = fw[foff[F_PRM]:fend[F_PRM]]
    rank_rtol = prm[PRM_RANK_RTOL]
    feas_rtol = prm[PRM_FEAS_RTOL]
    dual_rtol = prm[PRM_DUAL_RTOL]
    freeze_rtol = prm[PRM_FREEZE_RTOL]
    Wt = matrix_view(fw[foff[F_W]:fend[F_W]], n, n)  # W (factored: W0) stored by columns (._basis)
    qv = fw[foff[F_QV]:fend[F_QV]]  # the queue E_1 ... E_m
    qi = iw[ioff[I_QI]:ioff[I_QI + 1]]
    R = matrix_view(fw[foff[F_R]:fend[F_R]], n, n)
    u = fw[foff[F_U]:fend[F_U]]
    ps = fw[foff[F_PS]:fend[F_PS]]
    z = fw[foff[F_Z]:fend[F_Z]]
    g = fw[foff[F_G]:fend[F_G]]
    hv = fw[foff[F_HV]:fend[F_HV]]
    nu = fw[foff[F_NU]:fend[F_NU]]
    q = fw[foff[F_Q]:fend[F_Q]]
    uprev = fw[foff[F_UPREV]:fend[F_UPREV]]
    y = fw[foff[F_Y]:fend[F_Y]]
    Mr = matrix_view(fw[foff[F_MR]:fend[F_MR]], mmax, n)
    bvec = fw[foff[F_BVEC]:fend[F_BVEC]]
    diag = fw[foff[F_DIAG]:fend[F_DIAG]]
    beta = fw[foff[F_BETA]:fend[F_BETA]]
    Lb = matrix_view(fw[foff[F_LB]:fend[F_LB]], max(min(n, mmax), 1), mmax)
    target = fw[foff[F_TARGET]:fend[F_TARGET]]
    rnorm = fw[foff[F_RNORM]:fend[F_RNORM]]
    bval = fw[foff[F_BVAL]:fend[F_BVAL]]
    lnorm = fw[foff[F_LNORM]:fend[F_LNORM]]
    hist_du = matrix_view(fw[foff[F_HIST_DU]:fend[F_HIST_DU]], D, n)
    Mf = matrix_view(fw[foff[F_MF]:fend[F_MF]], mmax, n)
    Qbf = fw[foff[F_QB]:fend[F_QB]]  # (flat: scratch of push_reflectors too)
    Qb = matrix_view(Qbf, n, n)
    bq = fw[foff[F_BQ]:fend[F_BQ]]
    sv = fw[foff[F_SV]:foff[F_SV] + n]  # two scratch vectors (n,)
    sv2 = fw[foff[F_SV] + n:fend[F_SV]]
    A = matrix_view(fw[foff[F_A]:fend[F_A]], mt, n)
    lo = fw[foff[F_LO]:fend[F_LO]]
    up = fw[foff[F_UP]:fend[F_UP]]
    starts = iw[ioff[I_STARTS]:ioff[I_STARTS + 1]]
    state = iw[ioff[I_STATE]:ioff[I_STATE + 1]]
    side = iw[ioff[I_SIDE]:ioff[I_SIDE + 1]]
    kind = iw[ioff[I_KIND]:ioff[I_KIND + 1]]
    bcol = iw[ioff[I_BCOL]:ioff[I_BCOL + 1]]
    widx = iw[ioff[I_WIDX]:ioff[I_WIDX + 1]]
    wside = iw[ioff[I_WSIDE]:ioff[I_WSIDE + 1]]
    Olist = iw[ioff[I_OLIST]:ioff[I_OLIST + 1]]
    hist_state = matrix_view(iw[ioff[I_HIST_STATE]:ioff[I_HIST_STATE + 1]], D, mt)
    hist_side = matrix_view(iw[ioff[I_HIST_SIDE]:ioff[I_HIST_SIDE + 1]], D, mt)
    hist_valid = iw[ioff[I_HIST_VALID]:ioff[I_HIST_VALID + 1]]
    out = iw[ioff[I_OUT]:ioff[I_OUT + 1]]
    itl = out[N_OUT:N_OUT + D]  # iterations per level, read with the counters
    levid = iw[ioff[I_LEVID]:ioff[I_LEVID + 1]]
    piv = iw[ioff[I_PIV]:ioff[I_PIV + 1]]
    cand = iw[ioff[I_CAND]:ioff[I_CAND + 1]]
    cok = iw[ioff[I_COK]:ioff[I_COK + 1]]
    # the groups the phases take: the scaled problem, the basis W, the active set, the record
    prob = (A, lo, up, bcol, bval, kind, rnorm)
    basis = (Wt, qv, qi, sv, sv2)
    aset = (state, side, target, Olist, widx, wside)
    hist = (hist_state, hist_side, hist_valid, hist_du)
    vec = (u, ps, z, g, hv, nu, q)  # vectors (n,)
    lse = (Mr, Mf, piv, diag, beta, bvec, Lb, y)  # the level's COD (19) and LSE (28)
    tols = (rank_rtol, feas_rtol, dual_rtol, freeze_rtol)

    fl = 0
    acts = 0
    deacts = 0
    total = 0
    status = ST_OPTIMAL
    fail_level = -1
    warm_failed = 0
    cold_again = 0
    capped = 0
    nearcut = 0
    itl[:] = 0
    for attempt in range(2):  # (a block, left by break; a second pass: cold_again or capped below)
        use_hist = warm == 2 and attempt == 0
        uwarm = 0.0  # the largest ||u_hat|| of the warm points so far
        upeak = 0.0  # the largest ||u|| before a step so far
        cap_on = capped != 0  # (the second pass after a cancellation: LSE steps cut, see CANCELLED)
        lazy = _pass_start(use_hist, n, mt, D, hist_valid, u, Wt, qi, state, side)
        p = 0
        run0 = -1  # (time, recording) first level of the current run of exactly met levels, -1: none
        jrun = -1  # (time, re-solving) a jump over the levels jrun..jm-1 to u_jm: see _jump_end
        jm = -1
        for k in range(D):
            s0 = starts[k]
            s1 = starts[k + 1]
            for c in range(n):
                uprev[c] = u[c]
            if s1 == s0:
                if warm == 2:
                    for c in range(n):
                        hist_du[k, c] = 0.0
                    hist_valid[k] = 1
                continue
            thr_k = rank_rtol * lnorm[k]
            wide, rrt_k = _level_spread(rnorm, s0, s1, rank_rtol)
            # 1. the start of the level and the warm start (eqs. 45-46)
            p, nO, jrun, jm, jump, outcome, unorm, f = _level_start(
                k, warm, use_hist, n, D, p, lazy, jrun, jm, starts, tols, prob, basis, aset, hist, R, Mf, Qb,
                bq, cand, cok, uprev, vec)
            fl += f
            if outcome < 0:
                warm_failed += 1
            elif outcome > 0:
                uwarm = max(uwarm, unorm)
            # 2.-4. the active-set iterations
            it = _level_iterations(k, s0, s1, n, p, nO, lazy, total, max_iter, acts, deacts, nearcut, upeak,
                                   has_ineq, cap_on, wide, thr_k, rrt_k, tols, levid, itl, prob, basis, aset,
                                   R, vec, lse)
            status, p, nO, r, cod_done, cod_weak, lazy, total, acts, deacts, nearcut, upeak, f = it
            fl += f
            if status != ST_OPTIMAL:
                fail_level = k
                break
            if uwarm > COLD_AFTER_WARM and uwarm > COLD_AFTER_WARM * (1.0 + _norm(u)):
                # a warm point far from this level's optimum: the steps back cancelled and left
                # their rounding, eps ||u_hat||, along the working rows (levels above violated
                # by it). The call is done once more cold, its record rewritten
                cold_again = 1
                break
            if attempt == 0 and upeak > CANCELLED and upeak > CANCELLED * (1.0 + _norm(u)):
                # the same within the solve: a step out and back (CANCELLED)
                capped = 1
                break
            last = k == D - 1 or levid[k] == 2
            if warm == 2 and not jump:  # (a level of a jump keeps the record of the last call that did not)
                jrun, jm, run0, f = _record_level(k, n, s1, nO, last, jrun, jm, run0, dual_rtol, prob, aset,
                                                  hist, u, uprev)
                fl += f
            # 5. the freeze of level k (eq. 36); nothing to freeze below the last level, nor below
            # an identity-like equality level: its objective ||D x - e||^2 is strictly convex,
            # so x is unique after it and the levels below (the min-norm stage) change nothing
            if last:
                for kk in range(k + 1, D):
                    itl[kk] = 0
                    if warm == 2:
                        hist_valid[kk] = 0
                break
            elif not has_ineq:
                fl += push_reflectors(lazy, Wt, qv, qi, p, Mr, beta, r, Qbf, sv, sv2)
                for j in range(nO):
                    state[Olist[piv[j]]] = WORK if j < r else IMPLIED
                p += r
            else:
                p, f = _freeze(n, p, r, nO, cod_done, cod_weak, lazy, thr_k, rrt_k, freeze_rtol, prob, basis,
                               aset, R, q, u, lse, Qbf)
                fl += f
        if (cold_again or capped) and attempt == 0:
            continue  # (cold: u_0 = 0; the counters add both passes)
        break
    for c in range(n):
        if not math.isfinite(u[c]):
            status = ST_NUMERICAL
            break
    _write_out(out, status, total, acts, deacts, fl, fail_level, warm_failed, cold_again, capped, nearcut)
