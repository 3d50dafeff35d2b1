"""The basis ``W`` of the inequality kernel kept factored, partly implicit,
and the updates of the constraint decomposition on it (ICRA 2010, sec. VI
and IX): the representation of warm re-solves of large problems (see
:mod:`._basis`).

``W`` (n, n) is orthonormal; its first ``p`` columns span the rows of the
working (active) constraints of the levels above, its last ``nf = n - p``
columns are ``Z`` (the null-space basis, eq. 16). ``R`` (n, n) holds, column
j, the coordinates of working row j in ``W``: ``C^T = W[:, :p] R[:p, :p]`` with
``R[:p, :p]`` upper triangular (rows enter in order).

``W = W0 E_1 ... E_m``: an explicit orthonormal ``W0``, stored by columns as
``Wt = W0^T`` (row c of ``Wt`` is column c of ``W0``), or the identity (a
flag: the state of every solve's start), times a queue of pending orthogonal
factors acting on columns:

- Householder reflectors ``I - beta v v^T`` on the columns ``o .. n-1``: the
  reflectors of a level's COD at its freeze (eq. 23, ``[Y_bar_k, Z_k] =
  Z_{k-1} H``) and those of rows entering the working set (sec. IX);
- sequences of Givens rotations on the columns ``(i, i + 1)``, ``i = o ..
  o + t - 1``: a row leaving the working set (sec. IX).

Pushing a factor stores it (the paper's implicit form of ``W``, like the
equality kernel's): the products ``W^T a`` and ``W x`` apply the queue to the
vector, ``2 L`` multiply-adds per reflector of length L, instead of ``2 n L``
to update an explicit ``W``. The queue is *flushed* into ``W0`` (n times the
cost of one product) by a ski-rental rule: once the products have spent,
beyond what they would cost with an explicit ``W``, ``FLUSH_RATIO`` times the
cost of a flush, or when its storage is full. A warm re-solve of IK-like
n=80 (seeds 0-4) never flushes: the reflectors of its levels and the rotations of
its deletions are applied to ~60 vectors instead of the 80 columns of W.

Storage: ``qv`` (floats): per reflector ``[beta, d, v_0 .. v_{L-1}]`` (``d =
v_prev[1:] . v`` when the entry before is a reflector one column to the left,
for the pair kernels), per rotation sequence ``[c_0, s_0, c_1, s_1, ...]``;
``qi`` (ints): a head of ``QH`` counters (entries, floats used, W0 is the
identity, madds of one product, madds spent), then per entry ``(o, L, f)``
with ``L > 0`` a reflector of length L, ``L = -t`` a sequence of t rotations,
f its start in ``qv``. Every routine returns its multiply-adds (the flop
counter of :class:`~hikbench.solvers.base.SolveResult`).

Rows are read from ``A`` (m, n); a *bound row* (one nonzero, e.g. a box row
``e_i``) has ``bcol[i] >= 0`` and coefficient ``bval[i]``: its products cost
O(1) instead of O(n) with an explicit ``W0``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from hikbench.solvers.hcod import _cache  # noqa: F401  (before any @njit: cache stamps over every hcod file)
from hikbench.solvers.hcod._linalg import (
    BLAS_MIN_N,
    BLAS_MIN_ROWS,
    BLAS_MIN_WORK,
    FASTMATH,
    householder,
    qr_rows,
    reflect_cols,
    reflect_cols_pair,
    reflect_pair,
    reflect_pair4,
    reflect_rows,
    retriangulate,
    rotate_cols,
    solve_upper,
    vaxpy,
    vdot,
    vreflect,
)

__all__ = [
    "FLUSH_RATIO",
    "QH",
    "basis_n",
    "basis_reset",
    "basis_row",
    "basis_rows",
    "basis_t",
    "delete_row",
    "flush",
    "insert_row",
    "insert_rows",
    "multipliers",
    "push_reflector",
    "queue_sizes",
]

#: flush the queue once the products have spent this fraction of a flush's cost more than an
#: explicit W would have (the flush runs ~2x more multiply-adds per ns than single vectors)
FLUSH_RATIO = 0.5
QH = 8  #: head of qi
Q_M, Q_F, Q_ID, Q_COST, Q_SPENT = range(5)
_FM = set(FASTMATH)


def queue_sizes(n: int):
    """Sizes of (qv, qi) for n variables: room for one level's COD (n
    reflectors) and the rotations of n deletions before a forced flush."""
    return 2 * n * n + 4 * n + 64, QH + 3 * (4 * n + 64)


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def basis_reset(qi):
    """``W = I``, queue empty (the start of a solve; ``Wt`` is not read)."""
    qi[Q_M] = 0
    qi[Q_F] = 0
    qi[Q_ID] = 1
    qi[Q_COST] = 0
    qi[Q_SPENT] = 0


# -- the queue applied to vectors -----------------------------------------------------------------
@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def _pairable(qi, e, m):
    """Entries e and e + 1 are reflectors, the second one column to the right."""
    b = QH + 3 * e
    return e + 1 < m and qi[b + 1] > 0 and qi[b + 4] == qi[b + 1] - 1 and qi[b + 3] == qi[b] + 1


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def _rot_t(qv, f, o, t, x):
    """``x <- G^T x`` for the rotation sequence (c, s) at qv[f:], columns o.."""
    a1 = x[o]
    for k in range(t):
        c = qv[f + 2 * k]
        s = qv[f + 2 * k + 1]
        a2 = x[o + k + 1]
        x[o + k] = c * a1 + s * a2
        a1 = -s * a1 + c * a2
    x[o + t] = a1


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def _rot_n(qv, f, o, t, x):
    """``x <- G x`` (the sequence's rotations in reverse order, transposed)."""
    a2 = x[o + t]
    for k in range(t - 1, -1, -1):
        c = qv[f + 2 * k]
        s = qv[f + 2 * k + 1]
        a1 = x[o + k]
        x[o + k + 1] = s * a1 + c * a2
        a2 = c * a1 - s * a2
    x[o] = a2


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def queue_t(qv, qi, x, e0):
    """``x <- E_m^T ... E_{e0+1}^T x`` (x (n,); the entries from e0 on, in
    order). Returns flops."""
    m = qi[Q_M]
    fl = 0
    e = e0
    while e < m:
        b = QH + 3 * e
        o = qi[b]
        L = qi[b + 1]
        f = qi[b + 2]
        if L > 0:
            if _pairable(qi, e, m):
                f2 = qi[b + 5]
                reflect_pair(qv[f], qv[f + 2:f + 2 + L], qv[f2], qv[f2 + 2:f2 + 1 + L], qv[f2 + 1], x[o:])
                fl += 4 * L
                e += 2
                continue
            vreflect(qv[f], qv[f + 2:f + 2 + L], x[o:o + L])
            fl += 2 * L
        else:
            _rot_t(qv, f, o, -L, x)
            fl -= 4 * L
        e += 1
    return fl


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def queue_n(qv, qi, x):
    """``x <- E_1 ... E_m x`` (x (n,); the entries in reverse order).
    Returns flops."""
    m = qi[Q_M]
    fl = 0
    e = m - 1
    while e >= 0:
        b = QH + 3 * e
        o = qi[b]
        L = qi[b + 1]
        f = qi[b + 2]
        if L > 0:
            if e > 0 and _pairable(qi, e - 1, m):
                # E_{e-1} E_e x: E_e first, then E_{e-1} with the correction d
                o1 = qi[b - 3]
                L1 = qi[b - 2]
                f1 = qi[b - 1]
                v1 = qv[f1 + 2:f1 + 2 + L1]
                v2 = qv[f + 2:f + 2 + L]
                xs = x[o1:]
                x2 = xs[1:]
                s1 = 0.0
                s2 = 0.0
                v1s = v1[1:]
                for c in range(L):
                    s1 += v1s[c] * x2[c]
                    s2 += v2[c] * x2[c]
                s2 *= qv[f]
                s1 = qv[f1] * (s1 + v1[0] * xs[0] - s2 * qv[f + 1])
                xs[0] -= s1 * v1[0]
                for c in range(L):
                    x2[c] -= s1 * v1s[c] + s2 * v2[c]
                fl += 4 * L1
                e -= 2
                continue
            vreflect(qv[f], qv[f + 2:f + 2 + L], x[o:o + L])
            fl += 2 * L
        else:
            _rot_n(qv, f, o, -L, x)
            fl -= 4 * L
        e -= 1
    return fl


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def queue_t_rows(qv, qi, M, j0, j1, e0):
    """:func:`queue_t` on the rows ``M[j0:j1]`` (each a vector (n,)), one
    entry at a time over all rows (four rows per pass). Returns flops."""
    m = qi[Q_M]
    nr = j1 - j0
    fl = 0
    e = e0
    while e < m:
        b = QH + 3 * e
        o = qi[b]
        L = qi[b + 1]
        f = qi[b + 2]
        if L > 0:
            if _pairable(qi, e, m):
                f2 = qi[b + 5]
                b1 = qv[f]
                v1 = qv[f + 2:f + 2 + L]
                b2 = qv[f2]
                v2 = qv[f2 + 2:f2 + 1 + L]
                d = qv[f2 + 1]
                j = j0
                while j + 4 <= j1:
                    reflect_pair4(b1, v1, b2, v2, d, M[j, o:], M[j + 1, o:], M[j + 2, o:], M[j + 3, o:])
                    j += 4
                while j < j1:
                    reflect_pair(b1, v1, b2, v2, d, M[j, o:])
                    j += 1
                fl += 4 * L * nr
                e += 2
                continue
            reflect_rows(qv[f], qv[f + 2:f + 2 + L], M, j0, j1, o)
            fl += 2 * L * nr
        else:
            for j in range(j0, j1):
                _rot_t(qv, f, o, -L, M[j])
            fl -= 4 * L * nr
        e += 1
    return fl


# -- flush: W0 <- W0 E_1 ... E_m -------------------------------------------------------------------
@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def flush(Wt, qv, qi, sv, sv2):
    """Apply the queue to ``W0`` (``W0 <- W0 E_1 ... E_m``; W0 = I first when
    flagged so) and empty it. sv, sv2 (n,) scratch. Returns flops."""
    n = Wt.shape[0]
    if qi[Q_ID] != 0:
        Wt[:, :] = 0.0
        for c in range(n):
            Wt[c, c] = 1.0
        qi[Q_ID] = 0
    m = qi[Q_M]
    fl = 0
    e = 0
    while e < m:
        b = QH + 3 * e
        o = qi[b]
        L = qi[b + 1]
        f = qi[b + 2]
        if L > 0:
            if _pairable(qi, e, m):
                f2 = qi[b + 5]
                fl += reflect_cols_pair(Wt, o, qv[f], qv[f + 2:f + 2 + L], qv[f2], qv[f2 + 2:f2 + 1 + L], qv[f2 + 1],
                                        sv, sv2)
                e += 2
                continue
            fl += reflect_cols(Wt, o, qv[f], qv[f + 2:f + 2 + L], sv)
        else:
            for k in range(-L):
                rotate_cols(qv[f + 2 * k], qv[f + 2 * k + 1], Wt[o + k], Wt[o + k + 1])
            fl -= 4 * n * L
        e += 1
    qi[Q_M] = 0
    qi[Q_F] = 0
    qi[Q_COST] = 0
    qi[Q_SPENT] = 0
    return fl


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def _charge(Wt, qv, qi, nvec, sv, sv2):
    """Account for nvec products through the queue; flush first when they
    have spent, beyond an explicit W, FLUSH_RATIO times a flush (rent or buy).
    Returns flops (of the flush, if any)."""
    cost = qi[Q_COST]
    if cost == 0:
        return 0
    n = Wt.shape[0]
    gain = cost - (n * n if qi[Q_ID] != 0 else 0)
    if gain <= 0:
        return 0
    qi[Q_SPENT] += nvec * gain
    if qi[Q_SPENT] >= FLUSH_RATIO * n * cost:
        return flush(Wt, qv, qi, sv, sv2)
    return 0


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def push_reflector(Wt, qv, qi, o, v, bt, sv, sv2):
    """Append the reflector ``I - bt v v^T`` on the columns ``o:o+len(v)``
    (``W <- W E``). Flushes first when the storage is full. Returns flops."""
    L = v.shape[0]
    fl = 0
    if qi[Q_M] + 1 > (qi.shape[0] - QH) // 3 or qi[Q_F] + L + 2 > qv.shape[0]:
        fl += flush(Wt, qv, qi, sv, sv2)
    m = qi[Q_M]
    f = qi[Q_F]
    b = QH + 3 * m
    qi[b] = o
    qi[b + 1] = L
    qi[b + 2] = f
    qv[f] = bt
    qv[f + 1] = 0.0
    dst = qv[f + 2:f + 2 + L]
    for c in range(L):
        dst[c] = v[c]
    if m > 0 and qi[b - 2] == L + 1 and qi[b - 3] == o - 1:  # d = v_prev[1:] . v (pair kernels)
        fp = qi[b - 1]
        qv[f + 1] = vdot(qv[fp + 3:fp + 3 + L], dst)
        fl += L
    qi[Q_M] = m + 1
    qi[Q_F] = f + L + 2
    qi[Q_COST] += 2 * L
    return fl


# -- products with W --------------------------------------------------------------------------------
@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def basis_t(Wt, qv, qi, x, c0, c1, sv, sv2):
    """``x[c0:c1] <- (W^T x)[c0:c1]`` (x (n,); the other entries of x are
    left undefined: only ``W[:, c0:c1]`` is read when the queue is empty).
    Returns flops."""
    fl = _charge(Wt, qv, qi, 1, sv, sv2)
    n = Wt.shape[0]
    if qi[Q_ID] == 0:
        if qi[Q_M] == 0:
            for c in range(c0, c1):
                sv[c] = vdot(Wt[c], x)
            for c in range(c0, c1):
                x[c] = sv[c]
            return fl + n * (c1 - c0)
        for c in range(n):
            sv[c] = vdot(Wt[c], x)
        x[:] = sv
        fl += n * n
    return fl + queue_t(qv, qi, x, 0)


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def basis_n(Wt, qv, qi, x, c0, c1, sv, sv2):
    """``x <- W x`` for x (n,) zero outside ``c0:c1`` (only ``W[:, c0:c1]`` is
    read when the queue is empty). Returns flops."""
    fl = _charge(Wt, qv, qi, 1, sv, sv2)
    n = Wt.shape[0]
    if qi[Q_M] > 0:
        fl += queue_n(qv, qi, x)
        c0 = 0
        c1 = n
    if qi[Q_ID] == 0:
        sv[:] = 0.0
        for c in range(c0, c1):
            vaxpy(x[c], Wt[c], sv)
        x[:] = sv
        fl += n * (c1 - c0)
    return fl


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def _w0_row(A, i, bcol, bval, Wt, ident, out):
    """``out = W0^T a`` for the row ``a = A[i]`` (a gather of column
    ``bcol[i]`` of Wt for a bound row). Returns flops."""
    n = Wt.shape[0]
    b = bcol[i]
    if b >= 0:
        v = bval[i]
        if ident:
            out[:] = 0.0
            out[b] = v
            return 0
        for c in range(n):
            out[c] = v * Wt[c, b]
        return n
    ra = A[i]
    if ident:
        for c in range(n):
            out[c] = ra[c]
        return 0
    for c in range(n):
        out[c] = vdot(Wt[c], ra)
    return n * n


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def basis_row(A, i, bcol, bval, Wt, qv, qi, out, sv, sv2):
    """``out = W^T a`` for the row ``a = A[i]`` (out (n,)). Returns flops."""
    fl = _charge(Wt, qv, qi, 1, sv, sv2)
    fl += _w0_row(A, i, bcol, bval, Wt, qi[Q_ID] != 0, out)
    return fl + queue_t(qv, qi, out, 0)


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def basis_rows(A, rows, j0, j1, bcol, bval, Wt, qv, qi, M, sv, sv2):
    """``M[j] = W^T A[rows[j]]`` for j0 <= j < j1 (M (>= j1, n)): the rows
    projected on the basis (eq. 19 takes ``M[j, p:]``, the projection on Z);
    the general rows by one BLAS product with W0 when there are many.
    Returns flops."""
    n = Wt.shape[0]
    fl = _charge(Wt, qv, qi, j1 - j0, sv, sv2)
    ident = qi[Q_ID] != 0
    ng = 0
    if not ident:
        for j in range(j0, j1):
            if bcol[rows[j]] < 0:
                ng += 1
    if ng >= BLAS_MIN_ROWS and n >= BLAS_MIN_N and ng * n * n >= BLAS_MIN_WORK:
        G = np.empty((ng, n))
        gi = 0
        for j in range(j0, j1):
            i = rows[j]
            if bcol[i] < 0:
                G[gi, :] = A[i, :]
                gi += 1
        P = G @ Wt.T
        gi = 0
        for j in range(j0, j1):
            i = rows[j]
            if bcol[i] < 0:
                M[j, :] = P[gi]
                gi += 1
            else:
                fl += _w0_row(A, i, bcol, bval, Wt, False, M[j])
        fl += ng * n * n
    else:
        for j in range(j0, j1):
            fl += _w0_row(A, rows[j], bcol, bval, Wt, ident, M[j])
    return fl + queue_t_rows(qv, qi, M, j0, j1, 0)


# -- updates of the decomposition (sec. IX) -----------------------------------------------------------
@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def insert_row(A, i, bcol, bval, R, p, thr, q, Wt, qv, qi, sv, sv2):
    """Add row ``a = A[i]`` to the working constraints by one Householder
    update of ``W`` (sec. IX: the decomposition is updated, not recomputed):
    ``q = W^T a``; the reflector that maps ``q[p:]`` to ``alpha e_1`` is
    pushed on ``W[:, p:]``; ``R[:, p] = (q[:p], alpha)``.

    The row is refused (returns False) when ``||q[p:]|| <= thr``: it is a
    combination of the working rows (rank detection), and at once when ``p = n``
    (no room left). On success the reflector vector stays in ``q[p:]``.
    Returns (ok, flops, beta)."""
    n = Wt.shape[0]
    if p >= n:
        return False, 0, 0.0
    fl = basis_row(A, i, bcol, bval, Wt, qv, qi, q, sv, sv2)
    qz = q[p:]
    nrm = math.sqrt(vdot(qz, qz))
    if not nrm > thr:
        return False, fl, 0.0
    alpha, bt = householder(qz, nrm)
    fl += push_reflector(Wt, qv, qi, p, qz, bt, sv, sv2)
    for c in range(p):
        R[c, p] = q[c]
    R[p, p] = alpha
    return True, fl, bt


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def insert_rows(A, cand, m, bcol, bval, R, p, rank_rtol, rnorm, Qb, bq, cok, Wt, qv, qi, sv, sv2):
    """Add the rows ``A[cand[:m]]`` to the working constraints, in order, as m
    calls of :func:`insert_row` would (same rank test, same ``W`` and ``R``),
    but blocked: ``Q = A_cand W`` at once, then the QR of ``Q[:, p:]``
    (:func:`._linalg.qr_rows`); the accepted reflectors are pushed in order.
    ``cok[j]`` = 1 when row j entered. Qb (>= m, n), bq (>= m) scratch.
    Returns (t, flops)."""
    n = Wt.shape[0]
    fl = basis_rows(A, cand, 0, m, bcol, bval, Wt, qv, qi, Qb, sv, sv2)
    t, f = qr_rows(Qb, cand, m, p, rank_rtol, rnorm, R, bq, cok)
    fl += f
    for s in range(t):
        fl += push_reflector(Wt, qv, qi, p + s, Qb[s, p + s:n], bq[s], sv, sv2)
    return t, fl


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def delete_row(j, R, p, widx, wside, M, nM, Wt, qv, qi, sv, sv2):
    """Remove working row j (0 <= j < p): drop column j of R and restore the
    triangle by Givens rotations of R's rows (:func:`._linalg.retriangulate`);
    the same rotations of W's columns ``(i, i + 1)``, i = j .. p - 2 (``W R``
    is unchanged), are pushed as one sequence, and applied to the rows
    ``M[:nM]`` (kept as ``W^T a``: the projected objective rows).
    ``widx``/``wside`` shift. Returns flops; the caller decrements p."""
    if j >= p - 1:
        return 0
    fl = 0
    t = p - 1 - j
    if qi[Q_M] + 1 > (qi.shape[0] - QH) // 3 or qi[Q_F] + 2 * t > qv.shape[0]:
        fl += flush(Wt, qv, qi, sv, sv2)
    m = qi[Q_M]
    f = qi[Q_F]
    fl += retriangulate(j, R, p, widx, wside, qv[f:f + 2 * t], Wt, False)
    for k in range(t):
        c = qv[f + 2 * k]
        s = qv[f + 2 * k + 1]
        for jm in range(nM):
            mr = M[jm]
            a1 = mr[j + k]
            a2 = mr[j + k + 1]
            mr[j + k] = c * a1 + s * a2
            mr[j + k + 1] = -s * a1 + c * a2
    fl += 4 * nM * t
    b = QH + 3 * m
    qi[b] = j
    qi[b + 1] = -t
    qi[b + 2] = f
    qi[Q_M] = m + 1
    qi[Q_F] = f + 2 * t
    qi[Q_COST] += 4 * t
    return fl


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def multipliers(R, p, g, nu, Wt, qv, qi, sv, sv2):
    """Multipliers of the working constraints (eq. 39):
    ``C^T nu = -g`` solved as ``R nu = -W[:, :p]^T g``; g (n,) is the gradient
    ``J_k^T w_k`` of the level's objective (overwritten: scratch of the solve).
    Returns flops."""
    fl = basis_t(Wt, qv, qi, g, 0, p, sv, sv2)
    for c in range(p):
        g[c] = -g[c]
    solve_upper(R, p, g, nu)
    return fl + p * p // 2
