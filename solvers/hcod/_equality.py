"""Equality-only hierarchies: the HCOD recursion (ICRA 2010, sec. V-VI) with
an implicit basis.

The basis ``[Y_bar_{k-1}, Z_{k-1}] = H^(0) ... H^(k-1)`` (eq. 23) is never
formed: the rows of the levels below are carried in the rotated coordinates
``xi = [Y_bar, Z]^T x`` instead. Level k's block ``At[rows_k]`` holds, when k
is reached, ``[J_k Y_bar_{k-1}, J_k Z_{k-1}]`` (the ``M_k, N_k`` of eq. 22 and
the projected level of eq. 19), shape (m_k, n). Then

1. ``b = e_k - J_k Y_bar_{k-1} xi[:p]``  (``e_k - J_k u_{k-1}``, eq. 31);
2. pivoted Householder QR of ``(J_k Z_{k-1})^T`` with rank r (COD (19), first
   half; rank threshold ``rank_rtol * ||A_k||_F``), reflectors stored in the
   level's own rows;
3. ``xi[p:p+r] = L_k^-1 V_k^T b`` (eq. 31; second half of the COD when
   r < m_k, least squares);
4. ``p += r``; the level's reflectors stay in its rows. They are applied to
   the rows of a level below only when that level is reached with ``nf > 0``
   (lazily), so levels after saturation cost nothing; four at a time on long
   rows (``QUAD_MIN``), with the products of each four reflectors computed once
   per level (:func:`._linalg.quad_gram`), and two at a time on short ones.

At the end ``x = H^(0) ... H^(N-1) xi``. Cost per level: the reflectors of
the levels above applied once to the level's rows, i.e. ``2 m_k sum_j r_j
nf_j``, the COD ``~3 m_k^2 nf``: the shape of the paper's count (sec. VI),
and nothing once ``Z`` is empty (saturation).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from hikbench.solvers.hcod import _cache  # noqa: F401  (before any @njit: cache stamps over every hcod file)
from hikbench.solvers.hcod._linalg import (
    FASTMATH,
    NEAR_RANK,
    NEAR_RANK_STEP,
    householder,
    level_scale,
    near_rank_cut,
    quad_gram,
    reflect_pair,
    reflect_pair4,
    reflect_quad,
    reflect_quad2,
    reflect_rows,
    unowned,
    vdot,
    vreflect,
)

__all__ = ["eq_solve"]


_FM = set(FASTMATH)
#: the reflectors of a level above are applied four at a time (:func:`._linalg.reflect_quad2`) to
#: rows of at least this many columns (measured on four rows at once: equality n=120 8x12 in
#: `hikbench run`, hcod alone, alternated with the two-at-a-time loops: 57.4-59.4 -> 47.7-48.8 us), two at a time below:
#: from 40 columns n=50 5x8 read 12.3-13.3 us against 12.2-12.3, from 16 columns n=36 6x6 7.9
#: -> 8.9 us in-process (shorter rows lose to the four-way loops' set-up)
QUAD_MIN = 56


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def eq_solve(A, e, starts, rank_rtol, At, beta, cn, gm, xi, x, lev_p, lev_r, itl):
    """Minimum-norm lexicographic solution of ``A_k x = e_k``, k = 0..N-1.

    Parameters
    ----------
    A : (m, n) rows, level k = ``starts[k]:starts[k+1]``; e : (m,) targets.
    At : (m, n) scratch (the rotated rows, then the reflectors).
    beta, cn : (m,) scratch (reflector scalars, pivot norms).
    gm : (m, 6) scratch (the products of each four reflectors of a level,
    :func:`._linalg.quad_gram`, in the row of the first).
    xi, x : (n,) scratch / output (x is the solution).
    lev_p, lev_r, itl : (N,) int scratch / output (p and rank of each level,
    iterations = 1 per nonempty level).

    Returns the multiply-add count, or -1 when x is not finite (breakdown),
    and the number of steps cut at a pivot near the rank threshold (._linalg.NEAR_RANK).
    """
    # (unowned: no reference counting of the row views taken in the loops below)
    A = unowned(A)
    At = unowned(At)
    beta = unowned(beta)
    cn = unowned(cn)
    xi = unowned(xi)
    x = unowned(x)
    _m, n = A.shape
    D = starts.shape[0] - 1
    fl = 0
    cuts = 0
    for c in range(n):
        xi[c] = 0.0
    p = 0
    for k in range(D):
        s0 = starts[k]
        s1 = starts[k + 1]
        mk = s1 - s0
        lev_p[k] = p
        lev_r[k] = 0
        itl[k] = 0
        if mk == 0:
            continue
        itl[k] = 1
        nf = n - p
        if nf == 0:
            continue
        # the level is scaled by 1 / ||A_k||_F (computed without overflow): the same
        # minimisers, O(1) numbers in the reflectors, and the rank threshold relative to
        # the unprojected level becomes rank_rtol. Copy the scaled rows, then project them
        # on Z_{k-1}: apply the reflectors of the levels above (lazily, only now: a level
        # reached with nf = 0 costs nothing)
        sc = level_scale(A, s0, s1, n)
        for i in range(s0, s1):
            ra = A[i]
            rt = At[i]
            for c in range(n):
                rt[c] = ra[c] * sc
        thr = rank_rtol
        for j in range(k):
            pj = lev_p[j]
            rj = lev_r[j]
            t = 0
            if n - pj >= QUAD_MIN:  # four reflectors at a time while the rows are long
                t, f = _apply_quads(At, beta, gm, starts[j], rj, pj, s0, s1)
                fl += f
            while t + 2 <= rj:  # two reflectors at a time
                it = starts[j] + t
                c0 = pj + t
                v1 = At[it, c0:]
                v2 = At[it + 1, c0 + 1:]
                b1 = beta[it]
                b2 = beta[it + 1]
                d12 = vdot(v2, v1[1:])
                i = s0
                while i + 4 <= s1:
                    reflect_pair4(b1, v1, b2, v2, d12, At[i, c0:], At[i + 1, c0:], At[i + 2, c0:],
                                   At[i + 3, c0:])
                    i += 4
                while i < s1:
                    reflect_pair(b1, v1, b2, v2, d12, At[i, c0:])
                    i += 1
                fl += 2 * mk * (2 * (n - c0) - 1) + n - c0
                t += 2
            if t < rj:
                it = starts[j] + t
                c0 = pj + t
                reflect_rows(beta[it], At[it, c0:], At, s0, s1, c0)
                fl += 2 * mk * (n - c0)
        # b = e_k - J_k Y_bar xi[:p]; column norms of the projected rows
        xp = xi[:p]
        for i in range(s0, s1):
            cn[i] = e[i] * sc - vdot(At[i, :p], xp)  # b, permuted with the rows below
        fl += mk * (n + p)
        b = cn  # alias: b lives in cn[s0:s1]; the norms in beta[] until used
        for i in range(s0, s1):
            ri = At[i, p:]
            beta[i] = vdot(ri, ri)
        fl += mk * nf
        r = 0
        kmax = min(mk, nf)
        for t in range(kmax):
            it = s0 + t
            # pivot: largest remaining norm (downdated), recomputed when it looks unreliable
            jb = it
            best = -1.0
            for j in range(it, s1):
                if beta[j] > best:
                    best = beta[j]
                    jb = j
            rj = At[jb, p + t:]
            best = vdot(rj, rj)
            fl += nf - t
            nrm = math.sqrt(best)
            if not nrm > thr:
                break
            if jb != it:  # (columns < p are no longer needed: b is computed)
                for c in range(p, n):
                    tmp = At[it, c]
                    At[it, c] = At[jb, c]
                    At[jb, c] = tmp
                tmp = b[it]
                b[it] = b[jb]
                b[jb] = tmp
                beta[jb] = beta[it]
            c0 = p + t
            v = At[it, c0:]
            alpha, bt = householder(v, nrm)
            reflect_rows(bt, v, At, it + 1, s1, c0)
            for j in range(it + 1, s1):
                # downdate the remaining norm of row j
                d = beta[j] - At[j, c0] * At[j, c0]
                if d > 1e-3 * beta[j]:
                    beta[j] = d
                else:
                    rj = At[j, c0 + 1:]
                    beta[j] = vdot(rj, rj)
            fl += 2 * (s1 - it - 1) * (n - c0)
            beta[it] = bt
            xi[c0] = alpha  # R1[t, t], kept in xi until the solve
            r = t + 1
        # forward / least-squares solve of L y = b (L[j, l] = At[s0 + j, p + l], l < j; diag in xi)
        if r == mk:
            for t in range(r):
                sv = b[s0 + t]
                for l in range(t):
                    sv -= At[s0 + t, p + l] * x[l]
                x[t] = sv / xi[p + t]
            fl += r * r // 2
        elif r > 0:
            # L (mk, r) of full column rank: least squares by Givens rotations (_lsq_lower)
            fl += _lsq_lower(At, s0, s1, p, r, xi, b, x)
        if p > 0 and r > 0 and abs(xi[p + r - 1]) <= NEAR_RANK * thr:
            # (the pivots decrease: the last is the smallest) a step through a pivot near the
            # rank threshold: see _near_rank_cut
            r2, f = _near_rank_cut(At, s0, s1, p, r, thr, xi, b, x)
            fl += f
            if r2 < r:
                r = r2
                cuts += 1
        for t in range(r):
            xi[p + t] = x[t]
        for c in range(p + r, n):
            xi[c] = 0.0
        # the coupling products of the level's reflectors, four at a time (reflect_quad)
        for t in range(0, r - 3, 4):
            it = s0 + t
            c0 = p + t
            if n - c0 < QUAD_MIN:
                break
            g = quad_gram(At[it, c0:], At[it + 1, c0 + 1:], At[it + 2, c0 + 2:], At[it + 3, c0 + 3:])
            for l in range(6):
                gm[it, l] = g[l]
            fl += 6 * (n - c0 - 3) + 4
        lev_r[k] = r
        p += r
    # x = H^(0) ... H^(N-1) xi
    for c in range(n):
        x[c] = xi[c]
    for k in range(D - 1, -1, -1):
        pk = lev_p[k]
        for t in range(lev_r[k] - 1, -1, -1):
            it = starts[k] + t
            c0 = pk + t
            vreflect(beta[it], At[it, c0:], x[c0:])
            fl += 2 * (n - c0)
    for c in range(n):
        if not math.isfinite(x[c]):
            return -1, cuts
    return fl, cuts


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def _apply_quads(At, beta, gm, it0, rj, pj, s0, s1):
    """The reflectors of a level above (rows ``it0:it0+rj`` of At, the first
    at column pj) applied four at a time (:func:`._linalg.reflect_quad2`) to
    the rows ``s0:s1`` while at least ``QUAD_MIN`` columns are left. Returns
    (the number applied, multiply-adds). (Not inlined: in eq_solve's body
    these loops cost the short rows of n = 36 7 % whether they ran or not.)"""
    At = unowned(At)
    n = At.shape[1]
    mk = s1 - s0
    fl = 0
    t = 0
    while t + 4 <= rj and n - pj - t >= QUAD_MIN:
        it = it0 + t
        c0 = pj + t
        v1 = At[it, c0:]
        v2 = At[it + 1, c0 + 1:]
        v3 = At[it + 2, c0 + 2:]
        v4 = At[it + 3, c0 + 3:]
        bq = (beta[it], beta[it + 1], beta[it + 2], beta[it + 3])
        gq = (gm[it, 0], gm[it, 1], gm[it, 2], gm[it, 3], gm[it, 4], gm[it, 5])
        i = s0
        while i + 2 <= s1:
            reflect_quad2(bq, gq, v1, v2, v3, v4, At[i, c0:], At[i + 1, c0:])
            i += 2
        while i < s1:  # (the last row of an odd level)
            reflect_quad(bq, gq, v1, v2, v3, v4, At[i, c0:])
            i += 1
        fl += 2 * mk * (4 * (n - c0) - 6)
        t += 4
    return t, fl


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def _near_rank_cut(At, s0, s1, p, r, thr, xi, b, y):
    """A level's solution ``y`` (r,) of the COD (19) through a pivot near the rank
    threshold (._linalg.NEAR_RANK) past ``NEAR_RANK_STEP (1 + ||u||)``, ``||u|| =
    ||xi[:p]||``: the level's rank is taken as the t pivots before that one, and y[:t]
    solved again by least squares on them (:func:`_lsq_lower`; the pivots' reflectors act
    on later columns only, so ``L[:, :t]`` is intact); the columns it leaves go back to Z
    for the levels below. Returns (the rank, flops). (Not inlined: in eq_solve's body its
    loops cost registers where they never run.)"""
    t = near_rank_cut(y, xi[p:p + r], r, thr, NEAR_RANK_STEP * (1.0 + math.sqrt(vdot(xi[:p], xi[:p]))))
    if t < 0:
        return r, 0
    return t, _lsq_lower(At, s0, s1, p, t, xi, b, y) if t > 0 else 0


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def _lsq_lower(At, s0, s1, p, r, xi, b, y):
    """``y = argmin ||L y - b[s0:s1]||`` for the lower-trapezoidal ``L``
    (mk, r) of the COD (``L[j, l] = At[s0+j, p+l]`` for l < j, ``L[l, l] =
    xi[p+l]``, zero above): the second half of the COD (19), ``L = V_k [L_k;
    0]``, by Givens rotations that zero the rows r..mk-1 of L (kept in a
    small scratch). Returns flops."""
    mk = s1 - s0
    Lr = np.zeros((mk, r))
    for j in range(mk):
        for l in range(min(j, r)):
            Lr[j, l] = At[s0 + j, p + l]
        if j < r:
            Lr[j, j] = xi[p + j]
    c_ = np.empty(mk)
    for j in range(mk):
        c_[j] = b[s0 + j]
    fl = 0
    # rotate row j (>= r) into the triangle, column by column from the right? L[:r] is lower
    # triangular; zero L[j, l] for l = r-1 .. 0 against row l of the triangle, keeping it lower.
    for j in range(r, mk):
        for l in range(r - 1, -1, -1):
            a = Lr[l, l]
            bb = Lr[j, l]
            if bb == 0.0:
                continue
            h = math.hypot(a, bb)
            cs = a / h
            sn = bb / h
            for c in range(l + 1):
                v1 = Lr[l, c]
                v2 = Lr[j, c]
                Lr[l, c] = cs * v1 + sn * v2
                Lr[j, c] = -sn * v1 + cs * v2
            v1 = c_[l]
            v2 = c_[j]
            c_[l] = cs * v1 + sn * v2
            c_[j] = -sn * v1 + cs * v2
            fl += 4 * (l + 2)
    for t in range(r):
        sv = c_[t]
        for l in range(t):
            sv -= Lr[t, l] * y[l]
        y[t] = sv / Lr[t, t]
    return fl + r * r // 2


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def eq_run(A, e, starts, rank_rtol):
    """:func:`eq_solve` with its workspaces allocated here (one compiled call
    per solve, no Python-side set-up). Returns (x (n,), iterations per level
    (N,), flops, steps cut at a pivot near the rank threshold)."""
    m, n = A.shape
    D = starts.shape[0] - 1
    # At on a 64-byte boundary (numba's allocations guarantee 32): its rows are then aligned
    # whenever 8 divides n (equality n=120: 84 us aligned, 92 us on a 32-byte boundary)
    buf = np.empty(m * n + 8)
    a0 = (-buf.ctypes.data % 64) // 8
    At = buf[a0:a0 + m * n].reshape((m, n))
    beta = np.empty(m)
    cn = np.empty(m)
    gm = np.empty((m, 6))
    xi = np.empty(n)
    x = np.empty(n)
    lev_p = np.empty(D, np.int64)
    lev_r = np.empty(D, np.int64)
    itl = np.empty(D, np.int64)
    fl, cuts = eq_solve(A, e, starts, rank_rtol, At, beta, cn, gm, xi, x, lev_p, lev_r, itl)
    return x, itl, fl, cuts
