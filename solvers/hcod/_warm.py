"""Phase 1 of a level of the inequality kernel (:mod:`._kernel`): its start
from the previous level's optimum and working set (sec. X, eq. 45) and the
warm start "time" (sec. XI): the working set recorded at the last call
(``Delta^- A`` dropped, ``Delta^+ A`` inserted), the shift ``u_hat = u_{k-1} +
tau Delta u_k`` (eq. 46) and its correction onto the working rows, the jump
over a run of levels met exactly, and the record a level leaves for the next
call (:func:`_record_level`). See docs/hcod.md, "Warm start (sec. XI)".
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from hikbench.solvers.hcod import _cache  # noqa: F401  (before any @njit: cache stamps over every hcod file)
from hikbench.solvers.hcod._basis import (
    basis_n,
    basis_permuted,
    basis_t,
    delete_row,
    insert_row,
    insert_rows,
)
from hikbench.solvers.hcod._layout import WARM_NONE
from hikbench.solvers.hcod._linalg import (
    FASTMATH,
    row_dot,
    vaxpy,
)
from hikbench.solvers.hcod._rows import (
    IMPLIED,
    INACTIVE,
    OBJECTIVE,
    WORK,
    _floor,
    _levels_met,
    _norm,
    _within,
)

_FM = set(FASTMATH)


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
def _drop_working(warm, rk, s0, p, lazy, rank_rtol, prob, basis, aset, hist, wr):
    """Working inequality rows dropped at the start of a level: all of them
    (warm start "none"), or those the level deactivated at the previous call
    (``Delta^- A``, sec. XI: not WORK in the record ``rk``); each leaves ``W``
    by Givens rotations (sec. IX). Then the IMPLIED rows above re-enter ``W``
    where their projection on ``Z`` passes the rank threshold at their own
    norm. ``wr = (R, q, Mf)`` as in :func:`._iterations._activate`. Returns
    (p, flops)."""
    R, q, Mf = wr
    A, lo, up, bcol, bval, kind, rnorm = prob
    Wt, qv, qi, sv, sv2 = basis
    state, side, target, Olist, widx, wside = aset
    hist_state, hist_side, hist_valid, hist_du = hist
    fl = 0
    dropped = False
    for j in range(p - 1, -1, -1):
        i = widx[j]
        if wside[j] != 0 and (warm == WARM_NONE or hist_state[rk, i] != WORK):
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
def _warm_shift(k, jmp, jump, rk, s0, p, lazy, prob, basis, aset, hist, vec):
    """Eq. (46): ``u_hat = u_{k-1} + tau Delta u_k``, tau in [0, 1] keeping the
    inactive inequality rows above (not WORK in the record ``rk``) feasible.
    Delta u_k (n,) is first projected on Z, ``ps <- Z Z^T ps`` (the problem
    may have changed since it was recorded: the step must keep the rows
    frozen above). At the start of a jump (``k == jrun``) ``ps`` holds its
    step (:func:`_jump_end`); at its other levels and its end the step is 0.
    ``jmp = (jrun, jm)``, the jump under way; ``vec`` the vectors (n,) of
    :func:`._workspace.vector_blocks`. Returns (at_jump: u_hat is the point
    _jump_end accepted, flops)."""
    jrun, jm = jmp
    state = aset[0]
    u, ps, z, g, hv, nu, q = vec
    n = u.shape[0]
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
def _reactivate(jump, rk, s0, p, lazy, tols, prob, basis, aset, hist, ins, u):
    """``Delta^+ A`` (sec. XI): the inequality rows above that the record
    ``rk`` has WORK and are inactive now enter ``W`` together (one blocked
    Householder QR, :func:`._basis.insert_rows`), at their recorded side. A
    level of a jump inserts none (level jm inserts its rows) but, while W is a
    permutation of the identity's columns, the bound rows of level jm's record
    that the jump point meets at their bound (to its rounding floor: their
    correction moves u by rounding only, and no row above can become
    infeasible): they enter by swaps of W's columns (._basis), and the levels
    down to jm then work on fewer columns. ``ins = (R, Mf, Qb, bq, cand,
    cok)`` as in :func:`_level_start`. Returns (p, flops)."""
    rank_rtol, feas_rtol, dual_rtol, freeze_rtol = tols
    R, Mf, Qb, bq, cand, cok = ins
    n = u.shape[0]
    D = hist[2].shape[0]
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
def _level_start(k, mode, p, lazy, jmp, prob, basis, aset, hist, ins, uprev, vec):
    """Phase 1 of level k: the start from the previous optimum ``u_{k-1}`` and
    its working set (sec. X), with warm start "time" (sec. XI) the working set
    recorded at the previous call (``Delta^- A`` dropped, ``Delta^+ A``
    inserted) and the warm point ``u_hat = u_{k-1} + tau Delta u_k`` (eq. 46)
    corrected onto the working rows; if it violates a row above, the level
    starts cold from ``u_{k-1}``. Then the objective ``J_hat_k``: the rows of
    the record (but on a level of a jump), and the equality and violated rows
    (eq. 45). ``mode = (warm, use_hist, n, D, starts, tols)``: the warm start
    (WARM_*), whether this pass reads the record, the problem's size and
    levels, the tolerances; ``jmp = (jrun, jm)``: the jump under way
    (:func:`_jump_end`; -1: none); ``ins = (R, Mf, Qb, bq, cand, cok)``: the
    working rows' factor, the projected objective rows and the scratch of a
    blocked insertion.

    Returns (p, nO, jmp, jump, (outcome: 0 a cold start, 1 a feasible warm
    point, -1 an infeasible one, ||u_hat||), flops)."""
    warm, use_hist, n, D, starts, tols = mode
    jrun, jm = jmp
    R, Mf, Qb, bq, cand, cok = ins
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
    if (warm == WARM_NONE and k > 0) or warm_level:
        p, f = _drop_working(warm, rk, s0, p, lazy, rank_rtol, prob, basis, aset, hist, (R, q, Mf))
        fl += f
    outcome = 0
    unorm = 0.0  # (read by eq. 45 on a jump only, which is a warm level)
    if warm_level:
        at_jump, f = _warm_shift(k, (jrun, jm), jump, rk, s0, p, lazy, prob, basis, aset, hist, vec)
        fl += f
        p_in = p
        p, f = _reactivate(jump, rk, s0, p, lazy, tols, prob, basis, aset, hist, ins, u)
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
    return p, nO, (jrun, jm), jump, (outcome, unorm), fl


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def _record_level(lev, n, nO, last, run, dual_rtol, prob, aset, hist, u, uprev):
    """Warm start "time" (sec. XI): the record of level k for the next call --
    the states and sides of the rows down to it, its step ``Delta u_k = u_k -
    u_{k-1}`` (eq. 46; at the end of a jump, added to the jump's), and the
    runs of levels whose objective rows are all met exactly (each within its
    rounding floor: a zero objective; per row, a floor summed over the level
    would hide the residual of a row 1e-8 the size of the others), marked
    ``hist_valid[first] = 2 + the level after the run`` (:func:`_jump_end`).
    ``lev`` as in :func:`._iterations._level_iterations`; ``run = (jrun, jm,
    run0)``: the jump under way and the first level of the run being recorded
    (-1: none). Returns (run, flops)."""
    k, s0, s1, thr_k, rrt_k, wide = lev
    jrun, jm, run0 = run
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
    return (jrun, jm, run0), fl
