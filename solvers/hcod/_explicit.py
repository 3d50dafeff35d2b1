"""The basis ``W`` of the inequality kernel kept explicit, and the updates of
the constraint decomposition on it (ICRA 2010, sec. VI and IX): the
representation of cold solves and of small problems (see :mod:`._basis`).

``W`` (n, n) is orthonormal; its first ``p`` columns span the rows of the
working (active) constraints of the levels above, its last ``nf = n - p``
columns are ``Z`` (the null-space basis, eq. 16). It is stored by columns, as
``Wt = W^T`` (row c of ``Wt`` is column c of ``W``): the updates (reflectors
from the right, Givens on two columns) and the products ``W^T a`` then run on
contiguous vectors of length n. ``R`` (n, n) holds, column j, the coordinates
of working row j in ``W``: ``C^T = W[:, :p] R[:p, :p]`` with ``R[:p, :p]``
upper triangular (rows enter in order). Every update is applied to ``W`` at
once (``2 n L`` multiply-adds per reflector of length L); on short vectors
this beats the queue of :mod:`._basis`, whose per-entry overheads dominate.
The products read only the columns they need (``Z`` for the projections).
Every routine returns its multiply-adds (the flop counter of
:class:`~hikbench.solvers.base.SolveResult`).

Rows are read from ``A`` (m, n); a *bound row* (one nonzero, e.g. a box row
``e_i``) has ``bcol[i] >= 0`` and coefficient ``bval[i]``: its products cost
O(1) instead of O(n). ``W = I`` at a solve's start, and bound rows entering
it keep it a permutation of the identity's columns (:func:`_swap_in`): until
the first general update the products gather and scatter (flag
``W_PERMUTED``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from hikbench.solvers.hcod import _cache  # noqa: F401  (before any @njit: cache stamps over every hcod file)
from hikbench.solvers.hcod._factored import Q_ID, QH
from hikbench.solvers.hcod._linalg import (
    BLAS_MIN_N,
    BLAS_MIN_ROWS,
    BLAS_MIN_WORK,
    FASTMATH,
    householder,
    matrix_view,
    qr_rows,
    reflect_cols,
    retriangulate,
    solve_upper,
    vaxpy,
    vdot,
)

__all__ = [
    "apply_reflectors_to_basis",
    "basis_n",
    "basis_t",
    "delete_row",
    "insert_row",
    "insert_rows",
    "multipliers",
    "project_into",
    "push_reflectors",
    "reset",
]

_FM = set(FASTMATH)
#: ``qi[Q_ID]``: 1 while ``W`` is a permutation of the identity's columns (the identity of a solve's
#: start, then bound rows entered by swaps, :func:`_swap_in`), with ``perm`` at ``qi[QH:QH + n]``
#: (column j of W is ``e_perm[j]``) and its inverse at ``qi[QH + n:QH + 2 n]``; 0 otherwise
W_PERMUTED = 1


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def reset(Wt, qi):
    """``W = I`` (a solve's start), written and flagged a permutation (the
    identity's, ``qi[Q_ID]``: the products gather and scatter until the first
    general update clears it)."""
    n = Wt.shape[0]
    Wt[:, :] = 0.0
    for c in range(n):
        Wt[c, c] = 1.0
        qi[QH + c] = c
        qi[QH + n + c] = c
    qi[Q_ID] = W_PERMUTED


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def _swap_in(Wt, qi, R, i, bcol, bval, p, thr):
    """The bound row i (on variable ``c = bcol[i]``) enters at column p of ``W``
    while ``W`` is a permutation of the identity's columns (``qi[Q_ID]`` !=
    0): ``W^T a = bval e_pos`` with ``pos = perm^-1(c)``, and the Householder
    reflector that maps it to ``e_p`` can be the swap of W's columns p and pos
    (``v = e_p - e_pos``, ``beta = 1``), which keeps W a permutation; R's
    column is ``(0, bval)``. Returns pos (W's columns swapped when pos > p),
    or -1 when the row is refused, as :func:`insert_row`'s rank test would:
    ``|bval| <= thr``, or ``pos < p`` (a combination of the working rows)."""
    n = Wt.shape[0]
    c = bcol[i]
    b = bval[i]
    if not abs(b) > thr:
        return -1
    pos = qi[QH + n + c]
    if pos < p:
        return -1
    if pos > p:
        cp = qi[QH + p]
        # (rows p and pos of Wt are the unit vectors e_cp and e_c)
        Wt[p, cp] = 0.0
        Wt[p, c] = 1.0
        Wt[pos, c] = 0.0
        Wt[pos, cp] = 1.0
        qi[QH + p] = c
        qi[QH + pos] = cp
        qi[QH + n + c] = p
        qi[QH + n + cp] = pos
    for r in range(p):
        R[r, p] = 0.0
    R[p, p] = b
    return pos


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def wt_times_row(A, i, bcol, bval, Wt, out, m):
    """``out[:m] = W[:, :m]^T a`` for the row ``a = A[i]`` (``out[c] = Wt[c] @
    a``; a gather of column ``bcol[i]`` of ``Wt`` for a bound row). Returns
    flops."""
    b = bcol[i]
    if b >= 0:
        v = bval[i]
        for c in range(m):
            out[c] = v * Wt[c, b]
        return m
    ra = A[i]
    for c in range(m):
        out[c] = vdot(Wt[c], ra)
    return Wt.shape[0] * m


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def head(A, i, bcol, bval, Wt, qi, p, out):
    """``out[:p] = W[:, :p]^T a`` for the row ``a = A[i]`` (a gather while W
    is a permutation). Returns flops."""
    b = bcol[i]
    if qi[Q_ID] != 0:
        for l in range(p):
            c = qi[QH + l]
            out[l] = A[i, c] if b < 0 else (bval[i] if c == b else 0.0)
        return 0
    return wt_times_row(A, i, bcol, bval, Wt, out, p)


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def basis_t(Wt, qi, x, c0, c1, sv):
    """``x[c0:c1] <- (W^T x)[c0:c1]`` (x (n,); the columns ``W[:, c0:c1]``
    only, the other entries of x are left as they were; a gather while W
    is a permutation). sv (n,) scratch. Returns flops."""
    if qi[Q_ID] != 0:
        for c in range(c0, c1):
            sv[c] = x[qi[QH + c]]
        for c in range(c0, c1):
            x[c] = sv[c]
        return 0
    for c in range(c0, c1):
        sv[c] = vdot(Wt[c], x)
    for c in range(c0, c1):
        x[c] = sv[c]
    return Wt.shape[0] * (c1 - c0)


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def basis_n(Wt, qi, x, c0, c1, sv):
    """``x <- W[:, c0:c1] x[c0:c1]`` (x (n,), zero outside ``c0:c1``), e.g.
    ``Z z`` for ``c0 = p``; a scatter while W is a permutation. sv (n,)
    scratch. Returns flops."""
    if qi[Q_ID] != 0:
        sv[:] = 0.0
        for c in range(c0, c1):
            sv[qi[QH + c]] = x[c]
        x[:] = sv
        return 0
    sv[:] = 0.0
    for c in range(c0, c1):
        vaxpy(x[c], Wt[c], sv)
    x[:] = sv
    return Wt.shape[0] * (c1 - c0)


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def apply_reflectors_to_basis(Wt, qi, p, Mr, beta, r, sv, sv2):
    """``W[:, p:] <- W[:, p:] H`` (eq. 23: ``[Y_bar_k, Z_k] = Z_{k-1} H``) with
    ``H = H_0 ... H_{r-1}``, reflector i = ``I - beta[i] v v^T`` on the
    columns ``p + i:`` (``v = Mr[i, i:nf]``). On ``Wt = W^T``: ``s = sum_c v_c
    Wt[p + i + c]``, then ``Wt[p + i + c] -= beta_i v_c s`` (vectors of length n).
    Two reflectors at a time: one pass over the rows of ``Wt`` for both sums,
    ``s2 -= beta_i (v_{i+1} . v_i) s1`` (reflector i acts first), one pass for
    the update (:func:`._linalg.reflect_cols_pair` does the same on a pair of
    vectors; this loop on the rows of Mr, the product ``v_{i+1} . v_i`` taken
    in the first pass, is ~0.3 us faster on IK-like warm n=20). Four rows of
    ``Wt`` per pass over ``s`` (one load and store of s per four rows: IK-like
    cold n=80 ~4 % faster in ``hikbench run``). After it,
    ``W[:, p:p+r]`` spans the projected level and ``W[:, p+r:]`` is ``Z_k``.
    Clears the permutation flag ``qi[Q_ID]`` when r > 0. sv, sv2 (n,) are scratch. Returns flops."""
    n = Wt.shape[0]
    nf = n - p
    if r > 0:
        qi[Q_ID] = 0
    i = 0
    while i + 2 <= r:
        v1 = Mr[i]
        v2 = Mr[i + 1]
        b1 = beta[i]
        b2 = beta[i + 1]
        a = v1[i]
        for e in range(n):
            sv[e] = a * Wt[p + i, e]
        sv2[:] = 0.0
        d12 = 0.0
        c = i + 1
        while c + 4 <= nf:  # four rows of Wt per pass over sv, sv2
            a0, a1, a2, a3 = v1[c], v1[c + 1], v1[c + 2], v1[c + 3]
            q0, q1, q2, q3 = v2[c], v2[c + 1], v2[c + 2], v2[c + 3]
            d12 += a0 * q0 + a1 * q1 + a2 * q2 + a3 * q3
            w0, w1, w2, w3 = Wt[p + c], Wt[p + c + 1], Wt[p + c + 2], Wt[p + c + 3]
            for e in range(n):
                x0, x1, x2, x3 = w0[e], w1[e], w2[e], w3[e]
                sv[e] += (a0 * x0 + a1 * x1) + (a2 * x2 + a3 * x3)
                sv2[e] += (q0 * x0 + q1 * x1) + (q2 * x2 + q3 * x3)
            c += 4
        while c < nf:
            a = v1[c]
            b = v2[c]
            d12 += a * b
            w = Wt[p + c]
            for e in range(n):
                x = w[e]
                sv[e] += a * x
                sv2[e] += b * x
            c += 1
        g = b1 * d12
        for e in range(n):
            sv2[e] -= g * sv[e]
        vaxpy(-b1 * v1[i], sv, Wt[p + i])
        c = i + 1
        while c + 4 <= nf:
            a0, a1, a2, a3 = b1 * v1[c], b1 * v1[c + 1], b1 * v1[c + 2], b1 * v1[c + 3]
            q0, q1, q2, q3 = b2 * v2[c], b2 * v2[c + 1], b2 * v2[c + 2], b2 * v2[c + 3]
            w0, w1, w2, w3 = Wt[p + c], Wt[p + c + 1], Wt[p + c + 2], Wt[p + c + 3]
            for e in range(n):
                s1 = sv[e]
                s2 = sv2[e]
                w0[e] -= a0 * s1 + q0 * s2
                w1[e] -= a1 * s1 + q1 * s2
                w2[e] -= a2 * s1 + q2 * s2
                w3[e] -= a3 * s1 + q3 * s2
            c += 4
        while c < nf:
            a = b1 * v1[c]
            b = b2 * v2[c]
            w = Wt[p + c]
            for e in range(n):
                w[e] -= a * sv[e] + b * sv2[e]
            c += 1
        i += 2
    if i < r:
        reflect_cols(Wt, p + i, beta[i], Mr[i, i:nf], sv)
    return 2 * n * nf * r


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def apply_reflectors_to_permuted(Wt, qi, p, Mr, beta, r, qbf, sv, sv2):
    """:func:`apply_reflectors_to_basis` while ``W`` is a permutation (see
    :func:`_swap_in`): ``W[:, p:]`` is zero but for the identity on its rows
    ``perm[p:]``, so ``W[:, p:] H`` is H on those rows. H is accumulated on the
    identity of order ``nf = n - p`` (the flat scratch ``qbf``, >= nf^2; 2 nf^2
    multiply-adds per reflector instead of 2 n nf) and scattered. Returns flops."""
    n = Wt.shape[0]
    nf = n - p
    C = matrix_view(qbf, nf, nf)
    C[:, :] = 0.0
    for c in range(nf):
        C[c, c] = 1.0
    fl = apply_reflectors_to_basis(C, qi, 0, Mr, beta, r, sv[:nf], sv2[:nf])  # C = H^T (clears the flag)
    perm = qi[QH + p:QH + n]
    for j in range(nf):
        w = Wt[p + j]
        w[:] = 0.0
        cj = C[j]
        for e in range(nf):
            w[perm[e]] = cj[e]
    return fl


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def push_reflectors(Wt, qi, p, Mr, beta, r, qbf, sv, sv2):
    """``W[:, p:] <- W[:, p:] H_0 ... H_{r-1}`` (eq. 23) by the cheaper of the
    two routines: accumulated on order ``n - p`` and scattered
    (:func:`apply_reflectors_to_permuted`) while ``W`` is a permutation with
    working rows (p > 0); else on ``W`` itself
    (:func:`apply_reflectors_to_basis`). With p = 0 a permuted ``W`` is the
    identity, updated in place at the same cost without the accumulation's
    copy and scatter. qbf (>= (n - p)^2) flat scratch. Returns flops."""
    if qi[Q_ID] != 0 and r > 0 and p > 0:
        return apply_reflectors_to_permuted(Wt, qi, p, Mr, beta, r, qbf, sv, sv2)
    return apply_reflectors_to_basis(Wt, qi, p, Mr, beta, r, sv, sv2)


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def insert_row(A, i, bcol, bval, Wt, qi, R, p, thr, q, sv):
    """Add row ``a = A[i]`` to the working constraints by one Householder
    update of ``W`` (sec. IX: the decomposition is updated, not recomputed):
    ``q = W^T a``; the reflector that maps ``q[p:]`` to ``alpha e_1`` is
    applied to ``W[:, p:]`` from the right; ``R[:, p] = (q[:p], alpha)``.

    The row is refused (returns False) when ``||q[p:]|| <= thr``: it is a
    combination of the working rows (rank detection), and at once when ``p = n``
    (no room left). On success the reflector vector stays in ``q[p:]``. sv (n,)
    is scratch. Returns (ok, flops, beta)."""
    n = Wt.shape[0]
    if p >= n:
        return False, 0, 0.0
    if qi[Q_ID] != 0 and bcol[i] >= 0:
        # W a permutation, a bound row: the swap (_swap_in), its reflector left in q[p:]
        pos = _swap_in(Wt, qi, R, i, bcol, bval, p, thr)
        if pos < 0:
            return False, 0, 0.0
        qz = q[p:]
        qz[:] = 0.0
        if pos == p:
            return True, 0, 0.0
        qz[0] = 1.0
        qz[pos - p] = -1.0
        return True, 0, 1.0
    fl = wt_times_row(A, i, bcol, bval, Wt, q, n)
    qz = q[p:]
    nrm = math.sqrt(vdot(qz, qz))
    if not nrm > thr:
        return False, fl, 0.0
    alpha, bt = householder(qz, nrm)
    fl += reflect_cols(Wt, p, bt, qz, sv)
    qi[Q_ID] = 0
    for c in range(p):
        R[c, p] = q[c]
    R[p, p] = alpha
    return True, fl, bt


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def insert_rows(A, cand, m, bcol, bval, Wt, qi, R, p, rank_rtol, rnorm, Qb, bq, cok, sv, sv2):
    """Add the rows ``A[cand[:m]]`` to the working constraints, in order, as m
    calls of :func:`insert_row` would (same rank test, same ``W`` and ``R``),
    but blocked: ``Q = A_cand W`` at once (gathers while W is a permutation), the QR of ``Q[:, p:]``
    (:func:`._linalg.qr_rows`), then the t accepted reflectors applied to
    ``W[:, p:]`` together (:func:`apply_reflectors_to_basis`). ``cok[j]`` = 1 when row j entered.
    Shapes: Qb (>= m, n), bq (>= m), sv, sv2 (n,) scratch. Returns (t, flops)."""
    fl = 0
    if qi[Q_ID] != 0:
        allb = True
        for j in range(m):
            allb = allb and bcol[cand[j]] >= 0
        if allb:
            # W a permutation, bound rows: swaps (_swap_in)
            t = 0
            for j in range(m):
                i = cand[j]
                cok[j] = _swap_in(Wt, qi, R, i, bcol, bval, p + t, rank_rtol * rnorm[i]) >= 0
                t += cok[j]
            return t, 0
    for j in range(m):  # (gathers while W is a permutation)
        fl += head(A, cand[j], bcol, bval, Wt, qi, Wt.shape[0], Qb[j])
    t, f = qr_rows(Qb, cand, m, p, rank_rtol, rnorm, R, bq, cok)
    fl += f
    if t > 0:
        fl += apply_reflectors_to_basis(Wt, qi, p, Qb[:, p:], bq, t, sv, sv2)
    return t, fl


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def delete_row(j, Wt, qi, R, p, widx, wside, cs):
    """Remove working row j (0 <= j < p): drop column j of R and restore the
    triangle by Givens rotations of R's rows (:func:`._linalg.retriangulate`),
    applied to W's columns too (``W R`` is unchanged). ``widx``/``wside``
    shift; cs (>= 2 p) scratch. Clears the permutation flag ``qi[Q_ID]``.
    Returns flops; the caller decrements p."""
    qi[Q_ID] = 0
    if j >= p - 1:
        return 0
    return retriangulate(j, R, p, widx, wside, cs, Wt, True)


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def multipliers(Wt, qi, R, p, g, h, nu):
    """Multipliers of the working constraints (eq. 39):
    ``C^T nu = -g`` solved as ``R nu = -W[:, :p]^T g``; g (n,) is the gradient
    ``J_k^T w_k`` of the level's objective. Returns flops."""
    n = Wt.shape[0]
    fl = p * p // 2
    if qi[Q_ID] != 0:
        for c in range(p):
            h[c] = -g[qi[QH + c]]
    else:
        for c in range(p):
            h[c] = -vdot(Wt[c], g)
        fl += n * p
    solve_upper(R, p, h, nu)
    return fl


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def project_into(A, Olist, j0, j1, bcol, bval, Wt, qi, p, Mf):
    """``Mf[j, p:] = A[Olist[j]] @ W[:, p:]`` for j0 <= j < j1: the objective rows
    projected on Z (eq. 19), kept up to date across iterations; gathers of
    ``A[Olist[j]]`` while ``W`` is flagged a permutation (``qi[Q_ID]``: the
    identity at a solve's start, cleared by every general update above).
    Returns flops."""
    n = Wt.shape[0]
    fl = 0
    if qi[Q_ID] != 0:
        perm = qi[QH + p:QH + n]  # (column p + c of W is e_perm[c])
        for j in range(j0, j1):
            i = Olist[j]
            mj = Mf[j, p:]
            b = bcol[i]
            if b >= 0:
                v = bval[i]
                for c in range(n - p):
                    mj[c] = v if perm[c] == b else 0.0
            else:
                ra = A[i]
                for c in range(n - p):
                    mj[c] = ra[perm[c]]
        return 0
    ng = 0
    for j in range(j0, j1):
        if bcol[Olist[j]] < 0:
            ng += 1
    blas = n >= BLAS_MIN_N and ng >= BLAS_MIN_ROWS and ng * n * (n - p) >= BLAS_MIN_WORK
    if blas:
        # the general rows by one BLAS product (A_O gathered) @ Z
        G = np.empty((ng, n))
        gi = 0
        for j in range(j0, j1):
            i = Olist[j]
            if bcol[i] < 0:
                G[gi, :] = A[i, :]
                gi += 1
        P = G @ Wt[p:].T
        gi = 0
        for j in range(j0, j1):
            if bcol[Olist[j]] < 0:
                Mf[j, p:] = P[gi]
                gi += 1
        fl += ng * n * (n - p)
    for j in range(j0, j1):
        i = Olist[j]
        b = bcol[i]
        mj = Mf[j, p:]
        if b >= 0:
            v = bval[i]
            for c in range(n - p):
                mj[c] = v * Wt[p + c, b]
            fl += n - p
        elif not blas:
            ra = A[i]
            for c in range(n - p):
                mj[c] = vdot(Wt[p + c], ra)
            fl += n * (n - p)
    return fl
