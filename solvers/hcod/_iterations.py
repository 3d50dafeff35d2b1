"""Phases 2-4 of a level of the inequality kernel (:mod:`._kernel`), the
active-set iterations (sec. VIII): the LSE step (eqs. 43-44, by the COD (19)
of ``J_hat_k Z``; identity-like levels by a product with ``Z^T``), its cuts
(near-rank pivots, a cancelled pass), the step length to the first blocking
row and its activation, and at a full step the deactivation by the sign of
the multipliers (:mod:`._multipliers`): an objective row leaves ``J_hat_k``,
a working row leaves ``W`` by Givens rotations (sec. IX).
"""

from __future__ import annotations

from numba import njit

from hikbench.solvers.hcod import _cache  # noqa: F401  (before any @njit: cache stamps over every hcod file)
from hikbench.solvers.hcod._basis import (
    LAZY_MAX_ITER,
    basis_explicit,
    basis_n,
    basis_rows,
    basis_t,
    delete_row,
    insert_row,
)
from hikbench.solvers.hcod._layout import N_OUT, O_ACT, O_DEACT, O_FLOPS, O_ITERS, O_NEARCUT
from hikbench.solvers.hcod._linalg import (
    FASTMATH,
    NEAR_RANK,
    NEAR_RANK_STEP,
    mf_reflect,
    near_rank_cut,
    row_dot,
    solve_lower,
)
from hikbench.solvers.hcod._multipliers import (
    _fitted_multipliers,
    _objective_multipliers,
    _objective_row_leaves,
    _working_multipliers,
)
from hikbench.solvers.hcod._rows import (
    BLAND_AFTER,
    CANCELLED,
    DEPENDENT,
    IMPLIED,
    INACTIVE,
    OBJECTIVE,
    ST_MAXIT,
    ST_OPTIMAL,
    WORK,
    _leave_objective,
    _level_cod,
    _level_cod_append,
    _lse_direction,
    _lse_residual,
    _norm,
    _release_dependent,
    _step_length,
)

_FM = set(FASTMATH)


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
def _lse_step(lev, cfg, wset, cod, prob, basis, aset, vec, lse):
    """Phase 2, the LSE step (eqs. 43-44) of the objective rows ``J_hat_k``
    (``Olist[:nO]``) under the working rows: ``ps`` (n,) minimises
    ``||J_hat_k (u + ps) - e||`` over ``ps = Z z``, Z = ``W[:, p:]`` (nf = n -
    p columns). By the COD (19) of ``J_hat_k Z`` (Mf (nO, n) holds the
    projections ``W^T a_j``; the COD, rank r, in Mr): from scratch
    (``ncod = 0``) or updated for the rows that entered since (``ncod`` rows
    in it), then ``ps = Z Y L^-1 V^T (e - J_hat_k u)`` (eqs. 30-31), possibly
    cut (:func:`_step_cap`). Identity-like levels: :func:`_identity_lse`.
    ``cod = (r, ncod, mf_valid, cod_weak)``: the level's COD so far (its rank,
    the objective rows it holds, whether Mf holds their projections, whether a
    pivot was appended with a small diagonal); ``lev``, ``cfg`` and ``wset``
    as in :func:`_level_iterations`.

    Returns (cod, cod_done, wc, ycap, flops)."""
    k, s0, s1, thr_k, rrt_k, wide = lev
    n, max_iter, has_ineq, cap_on, levid, tols = cfg
    p, nO, lazy = wset
    r, ncod, mf_valid, cod_weak = cod
    A, lo, up, bcol, bval, kind, rnorm = prob
    Wt, qv, qi, sv, sv2 = basis
    state, side, target, Olist, widx, wside = aset
    u, ps, z, g, hv, nu, q = vec
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
            r, f, weak = _level_cod_append(lse, ncod, nO, p, nf, thr_k, r, rrt_k, Olist, rnorm)
            fl += f
            cod_weak = cod_weak or weak
        ncod = nO
        cod_done = True
        _lse_residual(A, Olist, piv, nO, target, bcol, bval, u, bvec)
        if r > 0:
            fl += solve_lower(Mr, diag, nO, r, bvec, Lb, y)
            wc, ycap = _step_cap(cap_on, p, r, thr_k, u, y, diag)
            fl += _lse_direction(Mr, beta, r, nf, y, z, ps, p, n, lazy, basis)
    return (r, ncod, mf_valid, cod_weak), cod_done, wc, ycap, fl


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def _near_rank_retry(wc, r, bland, lev, cfg, wset, prob, basis, aset, vec, lse):
    """The step through a pivot near the rank threshold was taken past
    NEAR_RANK_STEP (1 + ||u||): the pivots from wc on are left out, y solved
    again by least squares on the ones before (the first wc columns of L), the
    step ps (eqs. 30-31) and its length (sec. VIII) found again. Returns
    (tau, blk, bsd, moved, ||u||, flops) as :func:`_step_length`."""
    k, s0, s1, thr_k, rrt_k, wide = lev
    n, max_iter, has_ineq, cap_on, levid, tols = cfg
    rank_rtol, feas_rtol, dual_rtol, freeze_rtol = tols
    p, nO, lazy = wset
    A, lo, up, bcol, bval, kind, rnorm = prob
    Wt, qv, qi, sv, sv2 = basis
    state, side, target, Olist, widx, wside = aset
    u, ps, z, g, hv, nu, q = vec
    Mr, Mf, piv, diag, beta, bvec, Lb, y = lse
    fl = 0
    if wc > 0:
        _lse_residual(A, Olist, piv, nO, target, bcol, bval, u, bvec)
        fl += solve_lower(Mr, diag, nO, wc, bvec, Lb, y)
    for c in range(wc, r):
        y[c] = 0.0
    fl += _lse_direction(Mr, beta, r, n - p, y, z, ps, p, n, lazy, basis)
    tau, blk, bsd, moved, un, f = _step_length(has_ineq, prob, state, s0, s1, u, ps, rank_rtol, feas_rtol,
                                               bland)
    fl += f
    return tau, blk, bsd, moved, un, fl


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def _activate(blk, bsd, s0, wset, ncod, ndep, mf_valid, rank_rtol, prob, basis, aset, wr):
    """Phase 3, activation (sec. VIII): the blocking row blk at its bound bsd
    (+1 upper, -1 lower). A row of level k joins the objective ``J_hat_k``
    (its projection appended to Mf: the COD is updated at the next
    iteration); a row above enters ``W`` by a Householder reflector (sec.
    IX), which Mf follows, or, in the span of the working rows to the rank
    threshold at its own norm, becomes DEPENDENT (not activated; it blocks no
    more while W keeps its rows). ``wset = (p, nO, lazy)``, ``wr = (R, q,
    Mf)``: the working rows' factor, the reflector of a row entering W, the
    projected objective rows. Returns (p, nO, ncod, ndep, activated, flops)."""
    p, nO, lazy = wset
    R, q, Mf = wr
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
def _delete_working(jw, n, s0, wset, ndep, mf_valid, rank_rtol, prob, basis, aset, wr):
    """Phase 4e, deactivation of the working row at position jw (its
    multiplier lambda of the wrong sign, eq. 39): it leaves ``W`` by Givens
    rotations (sec. IX); the projected objective rows ``Mf = W^T a_j`` follow
    (lazy: the rotations are applied to them too; explicit W: the new column
    p of Z is projected). DEPENDENT rows above move freely again, and an
    IMPLIED row re-enters W where its projection on Z is beyond the rank
    threshold at its own norm (at its level's, a row 1e-7 the size of the
    others, met beside it, so implied at the freeze, stayed out, and the step
    moved its residual by 6e-5 of itself: badly_scaled n = 12 seed 964).
    ``wset``, ``wr`` as in :func:`_activate`. Returns (p, ndep, flops)."""
    p, nO, lazy = wset
    R, q, Mf = wr
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
def _level_iterations(lev, cfg, wset, upeak, out, prob, basis, aset, R, vec, lse):
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

    ``lev = (k, s0, s1, thr_k, rrt_k, wide)``: the level, its rows s0:s1, its
    rank thresholds (:func:`_level_spread`); ``cfg = (n, max_iter, has_ineq,
    cap_on, levid, tols)``: the pass; ``wset = (p, nO, lazy)``: the working
    rows, the objective rows and the form of W; upeak: the largest ||u|| so
    far. The counters (iterations, per level too, activations, deactivations,
    near-rank cuts, flops) are added into ``out`` (slots O_*, ._layout).

    Returns (status, wset, upeak, (r, cod_done, cod_weak)): cod_done, the last
    iteration computed the COD of the objective rows (rank r; Mr, piv, diag,
    beta), which the freeze reads."""
    k, s0, s1, thr_k, rrt_k, wide = lev
    n, max_iter, has_ineq, cap_on, levid, tols = cfg
    p, nO, lazy = wset
    A, lo, up, bcol, bval, kind, rnorm = prob
    Wt, qv, qi, sv, sv2 = basis
    state, side, target, Olist, widx, wside = aset
    u, ps, z, g, hv, nu, q = vec
    Mr, Mf, piv, diag, beta, bvec, Lb, y = lse
    rank_rtol, feas_rtol, dual_rtol, freeze_rtol = tols
    wr = (R, q, Mf)  # (what a row entering or leaving W updates)
    # the call's counters, in registers through the loop (their slots in out: written back at its end)
    total = out[O_ITERS]
    acts = out[O_ACT]
    deacts = out[O_DEACT]
    nearcut = out[O_NEARCUT]
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
        out[N_OUT + k] += 1  # (the level's iterations)
        if lazy and out[N_OUT + k] > LAZY_MAX_ITER:
            # a level iterating like a cold one (a trajectory that drifted): W goes
            # explicit for the rest of the solve (see ._basis)
            fl += basis_explicit(Wt, qv, qi, sv, sv2)
            lazy = False
        # -- phase 2: the LSE step (eqs. 43-44)
        cod, cod_done, wc, ycap, f = _lse_step(lev, cfg, (p, nO, lazy), (r, ncod, mf_valid, cod_weak), prob,
                                               basis, aset, vec, lse)
        r, ncod, mf_valid, cod_weak = cod
        fl += f
        # -- phase 3: the step length (sec. VIII) and the activation
        bland = degen >= BLAND_AFTER
        tau, blk, bsd, moved, un, f = _step_length(has_ineq, prob, state, s0, s1, u, ps, rank_rtol, feas_rtol,
                                                   bland)
        fl += f
        upeak = max(upeak, un)
        if wc >= 0 and tau * _norm(ps) > ycap:
            nearcut += 1
            tau, blk, bsd, moved, un, f = _near_rank_retry(wc, r, bland, lev, cfg, (p, nO, lazy), prob, basis,
                                                           aset, vec, lse)
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
            p, nO, ncod, ndep, activated, f = _activate(blk, bsd, s0, (p, nO, lazy), ncod, ndep, mf_valid,
                                                        rank_rtol, prob, basis, aset, wr)
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
        anydel, jw, jb, wb, amb, f = _working_multipliers(n, (p, nO, lazy), degen, unorm, dual_rtol, prob,
                                                          basis, aset, R, vec)
        fl += f
        if jw < 0 and nO > 0 and p < n and (wide or amb):
            # a badly scaled level's end, where the force of its unmet rows is within the
            # floors of its met rows, or a multiplier negative within the met rows' part of
            # gtol (amb: their measured w is either u's error or the optimum's residual;
            # badly_scaled n = 12 seed 281: a met row's w, 2.3e-14 scaled, under its floor
            # but the LSE's own, put 2.2e-15 in gtol, above a box row's -7.9e-16)
            force = amb or (wide and metneg)
            jo, jw, f = _fitted_multipliers(n, (p, nO, lazy), degen, unorm, dual_rtol, force, anydel, prob,
                                            basis, aset, R, vec)
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
            p, ndep, f = _delete_working(jw, n, s0, (p, nO, lazy), ndep, mf_valid, rank_rtol, prob, basis,
                                         aset, wr)
            fl += f
            deacts += 1
            ncod = 0
            continue
        break
    if ndep > 0:
        ndep = _release_dependent(state, s0)
    out[O_ITERS] = total
    out[O_ACT] = acts
    out[O_DEACT] = deacts
    out[O_NEARCUT] = nearcut
    out[O_FLOPS] += fl
    return status, (p, nO, lazy), upeak, (r, cod_done, cod_weak)
