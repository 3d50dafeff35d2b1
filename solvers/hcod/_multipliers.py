"""Phase 4 of a level of the inequality kernel (:mod:`._kernel`), the
multipliers at a full step (sec. VIII): ``mu = w`` (eq. 38) of the objective
rows, ``lambda`` (eq. 39, from ``R``) of the working rows, each against its
noise floor (docs/hcod.md, "Tolerances"), and, at the end of a badly scaled
level or where a multiplier is negative within the met rows' part of that
floor, the met rows held at their bounds with their multipliers fitted on
``Z`` (:func:`_met_force`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from hikbench.solvers.hcod import _cache  # noqa: F401  (before any @njit: cache stamps over every hcod file)
from hikbench.solvers.hcod._basis import (
    basis_t,
    multipliers,
)
from hikbench.solvers.hcod._linalg import (
    FASTMATH,
    row_axpy,
    row_dot,
)
from hikbench.solvers.hcod._rows import (
    BLAND_AFTER,
    G_ROUNDING,
    MET_DETERMINED,
    _floor,
    _leave_objective,
    _norm,
)

_FM = set(FASTMATH)


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def _met_force(lazy, force, nO, p, n, unorm, dual_rtol, prob, basis, aset, u):
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
    A, lo, up, bcol, bval, kind, rnorm = prob
    Wt, qv, qi, sv, sv2 = basis
    state, side, target, Olist, widx, wside = aset
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
def _working_multipliers(n, wset, degen, unorm, dual_rtol, prob, basis, aset, R, vec):
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
    and its value, amb: a multiplier below -gtol_r; flops). ``wset = (p, nO,
    lazy)``; ``vec``: the vectors (n,) of :func:`._workspace.vector_blocks`."""
    p, nO, lazy = wset
    u, ps, z, g, hv, nu, q = vec
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
def _fitted_multipliers(n, wset, degen, unorm, dual_rtol, force, anydel, prob, basis, aset, R, vec):
    """Phase 4d, at a badly scaled level's end: the met rows held at their
    bounds as constraints, their mu fitted (:func:`_met_force`, g3 the
    gradient with them). A met row pulled to the feasible side of its bound
    leaves the objective (mu = w, eq. 38: jo, its position in Olist), else a
    working row whose multiplier (39) from g3 is negative beyond the unmet
    rows' rounding ftol (jw, its position in widx). Returns (jo, jw, flops);
    -1: none. ``wset``, ``vec`` as in :func:`_working_multipliers`."""
    p, nO, lazy = wset
    u, ps, z, g, hv, nu, q = vec
    A, lo, up, bcol, bval, kind, rnorm = prob
    Wt, qv, qi, sv, sv2 = basis
    state, side, target, Olist, widx, wside = aset
    jw = -1
    fl, jo, ftol, g3 = _met_force(lazy, force, nO, p, n, unorm, dual_rtol, prob, basis, aset, u)
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
