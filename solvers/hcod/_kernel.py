"""The compiled solve: the sequence of LSIs (33)-(35), level by level, by a
primal active set on the HCOD (ICRA 2010, sec. VII-XI). One call per solve.

The row states (INACTIVE, WORK, IMPLIED, OBJECTIVE, DEPENDENT) and their
sides are described in :mod:`._rows`.

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
   fitted on ``Z`` (:func:`._multipliers._met_force`): their residuals, under the floors,
   would hide the force of the small rows.
3. freeze: objective rows with nonzero slack become equality constraints at
   their achieved value (bounds propagated by eq. 36), zero-slack inequality
   rows become working inequality constraints.

The phases live in their own modules, each a set of numba functions
inlined here: :mod:`._warm` (1, the level's start and the warm start, and
the record of "time"), :mod:`._iterations` (2-4, the active-set
iterations), :mod:`._multipliers` (4, mu and lambda, eqs. 38-39, and the
fitted multipliers of badly scaled levels), :mod:`._rows` (the row states,
the tolerances' floors, the level's COD (19) and the step length, shared by
all of them); this module holds the freeze (5) and :func:`hcod_solve`, the
loop over the levels, which reads its blocks through :mod:`._workspace`.
The basis ``W`` and the updates of the decomposition are behind
:mod:`._basis` (explicit, or factored as ``W0`` times a queue of reflectors
and rotations). Flops are multiply-adds counted in the kernels.
"""

from __future__ import annotations

import math

from numba import njit

from hikbench.solvers.hcod import _cache  # noqa: F401  (before any @njit: cache stamps over every hcod file)
from hikbench.solvers.hcod._basis import (
    LAZY_MIN_N,
    basis_head,
    basis_reset,
    insert_row,
    push_reflectors,
)
from hikbench.solvers.hcod._iterations import (
    _level_iterations,
)
from hikbench.solvers.hcod._layout import (
    F_BQ,
    F_LNORM,
    F_QB,
    F_R,
    F_UPREV,
    I_CAND,
    I_COK,
    I_IP,
    I_LEVID,
    I_OUT,
    I_STARTS,
    IP_D,
    IP_HAS_INEQ,
    IP_MAX_ITER,
    IP_MMAX,
    IP_MT,
    IP_N,
    IP_WARM,
    O_CAPPED,
    O_COLD,
    O_FLOPS,
    O_LEVEL,
    O_STATUS,
    O_WARMFAIL,
    WARM_TIME,
)
from hikbench.solvers.hcod._linalg import (
    FASTMATH,
    matrix_view,
    row_dot,
    unowned,
)
from hikbench.solvers.hcod._rows import (
    CANCELLED,
    COLD_AFTER_WARM,
    IMPLIED,
    INACTIVE,
    ST_NUMERICAL,
    ST_OPTIMAL,
    WORK,
    _floor,
    _level_cod,
    _level_spread,
    _norm,
)
from hikbench.solvers.hcod._setup import N_OUT
from hikbench.solvers.hcod._warm import (
    _level_start,
    _record_level,
)
from hikbench.solvers.hcod._workspace import (
    active_set_blocks,
    basis_blocks,
    fblock,
    iblock,
    lse_blocks,
    problem_blocks,
    record_blocks,
    tolerances,
    vector_blocks,
)

_FM = set(FASTMATH)


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def _freeze(lev, cfg, wset, cod, prob, basis, aset, R, vec, lse, Qbf):
    """Phase 5, the freeze of level k (eq. 36) through its last COD (19): its
    r pivot rows enter W by the COD's reflectors (``W[:, p:] <- W[:, p:] H``,
    eq. 23, pushed), their R columns ``(W[:, :p]^T a, R_cod[:, t])``; the other
    objective rows are combinations of them (IMPLIED). Rows with a nonzero
    slack become equalities at their achieved value (target ``a u``, side 0),
    zero-slack inequality rows stay (removable) inequality constraints; the
    zero slack is ``freeze_rtol`` times the row's floor (:func:`_floor`) plus
    the level's residual ``||w||`` (the rounding of an LSE with a conflict
    leaks into its met rows in proportion to it). Without a COD of the last
    iteration the rows are inserted one by one. ``lev``, ``cfg``, ``wset`` as in
    :func:`._iterations._level_iterations`, ``cod = (r, cod_done, cod_weak)``
    as it returns. Returns (p, flops)."""
    k, s0, s1, thr_k, rrt_k, wide = lev
    n, max_iter, has_ineq, cap_on, levid, tols = cfg
    rank_rtol, feas_rtol, dual_rtol, freeze_rtol = tols
    p, nO, lazy = wset
    r, cod_done, cod_weak = cod
    u, ps, z, g, hv, nu, q = vec
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


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def hcod_solve(fw, iw):
    """Solve the hierarchy held in the workspaces fw/iw (:mod:`._setup`: the
    int workspace starts with the offsets of the blocks of both, and the ends of
    the float blocks, which start on 64-byte boundaries; two array
    arguments keep the call overhead down). The blocks are named in
    :mod:`._layout`.

    Blocks read: A (mt, n), lo, up (mt,), starts (D+1,) and the per-row data,
    written by :func:`._setup.load`; ip (slots IP_*: n, mt, D, mmax,
    max_iter, warm: one of WARM_*, has_ineq); prm (slots
    PRM_*: rank_rtol, feas_rtol, dual_rtol, freeze_rtol). The solution is ``u``
    in fw, counters in ``out`` (slots O_*) followed by the iterations per level.

    Per level k, the phases (each a function inlined here): 1. its start and
    warm start (:func:`._warm._level_start`); 2.-4. the active-set iterations
    (:func:`._iterations._level_iterations`: LSE step, step length and
    activation, multipliers and deactivation); the record of a "time" warm
    start (:func:`._warm._record_level`); 5. the freeze (:func:`_freeze`).
    The counters are kept in their output slots throughout. A second, cold
    pass follows a cancellation (COLD_AFTER_WARM, CANCELLED)."""
    fw = unowned(fw)  # (no reference counting of the block views and helper calls)
    iw = unowned(iw)
    ip = iblock(iw, I_IP)
    n = ip[IP_N]
    mt = ip[IP_MT]
    D = ip[IP_D]
    max_iter = ip[IP_MAX_ITER]
    warm = ip[IP_WARM]
    has_ineq = ip[IP_HAS_INEQ] != 0
    # the groups the phases take (._workspace): the scaled problem, the basis W, the active set,
    # the record, the vectors (n,), the level's COD (19) and LSE (28), the tolerances
    prob = problem_blocks(fw, iw, mt, n)
    basis = basis_blocks(fw, iw, n)
    aset = active_set_blocks(fw, iw)
    hist = record_blocks(fw, iw, D, mt, n)
    vec = vector_blocks(fw, iw)
    lse = lse_blocks(fw, iw, max(ip[IP_MMAX], 1), n)
    tols = tolerances(fw, iw)
    rank_rtol, feas_rtol, dual_rtol, freeze_rtol = tols
    rnorm = prob[6]
    Wt, qv, qi, sv, sv2 = basis
    state, side, target, Olist, widx, wside = aset
    hist_state, hist_side, hist_valid, hist_du = hist
    u, ps, z, g, hv, nu, q = vec
    Mr, Mf, piv, diag, beta, bvec, Lb, y = lse
    # the blocks hcod_solve reads itself or hands to one phase
    R = matrix_view(fblock(fw, iw, F_R), n, n)
    uprev = fblock(fw, iw, F_UPREV)
    lnorm = fblock(fw, iw, F_LNORM)
    Qbf = fblock(fw, iw, F_QB)  # (flat: scratch of push_reflectors too)
    Qb = matrix_view(Qbf, n, n)
    bq = fblock(fw, iw, F_BQ)
    starts = iblock(iw, I_STARTS)
    levid = iblock(iw, I_LEVID)
    cand = iblock(iw, I_CAND)
    cok = iblock(iw, I_COK)
    out = iblock(iw, I_OUT)
    itl = out[N_OUT:N_OUT + D]  # iterations per level, read with the counters

    # the counters live in their output slots (O_*, ._layout) through the call
    out[:] = 0
    out[O_LEVEL] = -1
    status = ST_OPTIMAL
    for attempt in range(2):  # (a block, left by break; a second pass: O_COLD or O_CAPPED below)
        use_hist = warm == WARM_TIME and attempt == 0
        uwarm = 0.0  # the largest ||u_hat|| of the warm points so far
        upeak = 0.0  # the largest ||u|| before a step so far
        # (the second pass after a cancellation: LSE steps cut, see CANCELLED)
        cfg = (n, max_iter, has_ineq, out[O_CAPPED] != 0, levid, tols)
        mode = (warm, use_hist, n, D, starts, tols)
        lazy = _pass_start(use_hist, n, mt, D, hist_valid, u, Wt, qi, state, side)
        p = 0
        run0 = -1  # (time, recording) first level of the current run of exactly met levels, -1: none
        jmp = (-1, -1)  # (time, re-solving) a jump over the levels jrun..jm-1 to u_jm: see _jump_end
        for k in range(D):
            s0 = starts[k]
            s1 = starts[k + 1]
            for c in range(n):
                uprev[c] = u[c]
            if s1 == s0:
                if warm == WARM_TIME:
                    for c in range(n):
                        hist_du[k, c] = 0.0
                    hist_valid[k] = 1
                continue
            wide, rrt_k = _level_spread(rnorm, s0, s1, rank_rtol)
            lev = (k, s0, s1, rank_rtol * lnorm[k], rrt_k, wide)
            # 1. the start of the level and the warm start (eqs. 45-46)
            p, nO, jmp, jump, warm_point, f = _level_start(k, mode, p, lazy, jmp, prob, basis, aset, hist,
                                                           (R, Mf, Qb, bq, cand, cok), uprev, vec)
            out[O_FLOPS] += f
            outcome, unorm = warm_point
            if outcome < 0:
                out[O_WARMFAIL] += 1
            elif outcome > 0:
                uwarm = max(uwarm, unorm)
            # 2.-4. the active-set iterations
            status, wset, upeak, cod = _level_iterations(lev, cfg, (p, nO, lazy), upeak, out, prob, basis,
                                                         aset, R, vec, lse)
            p, nO, lazy = wset
            if status != ST_OPTIMAL:
                out[O_LEVEL] = k
                break
            if uwarm > COLD_AFTER_WARM and uwarm > COLD_AFTER_WARM * (1.0 + _norm(u)):
                # a warm point far from this level's optimum: the steps back cancelled and left
                # their rounding, eps ||u_hat||, along the working rows (levels above violated
                # by it). The call is done once more cold, its record rewritten
                out[O_COLD] = 1
                break
            if attempt == 0 and upeak > CANCELLED and upeak > CANCELLED * (1.0 + _norm(u)):
                # the same within the solve: a step out and back (CANCELLED)
                out[O_CAPPED] = 1
                break
            last = k == D - 1 or levid[k] == 2
            if warm == WARM_TIME and not jump:  # (a level of a jump keeps the last record that did not jump)
                run, f = _record_level(lev, n, nO, last, (jmp[0], jmp[1], run0), dual_rtol, prob, aset, hist,
                                       u, uprev)
                out[O_FLOPS] += f
                jrun, jm, run0 = run
                jmp = (jrun, jm)
            # 5. the freeze of level k (eq. 36); nothing to freeze below the last level, nor below
            # an identity-like equality level: its objective ||D x - e||^2 is strictly convex,
            # so x is unique after it and the levels below (the min-norm stage) change nothing
            if last:
                for kk in range(k + 1, D):
                    itl[kk] = 0
                    if warm == WARM_TIME:
                        hist_valid[kk] = 0
                break
            elif not has_ineq:
                r = cod[0]
                out[O_FLOPS] += push_reflectors(lazy, Wt, qv, qi, p, Mr, beta, r, Qbf, sv, sv2)
                for j in range(nO):
                    state[Olist[piv[j]]] = WORK if j < r else IMPLIED
                p += r
            else:
                p, f = _freeze(lev, cfg, (p, nO, lazy), cod, prob, basis, aset, R, vec, lse, Qbf)
                out[O_FLOPS] += f
        if (out[O_COLD] or out[O_CAPPED]) and attempt == 0:
            continue  # (cold: u_0 = 0; the counters add both passes)
        break
    for c in range(n):
        if not math.isfinite(u[c]):
            status = ST_NUMERICAL
            break
    out[O_STATUS] = status
