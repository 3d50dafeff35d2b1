"""Numba kernels of the HCOD: projections, the rank-revealing COD of a
projected level, and the updates of the constraint decomposition.

Notation (ICRA 2010, sec. V-VI). ``W`` (n, n) is orthonormal; its first ``p``
columns span the rows of the working (active) constraints of the levels above,
its last ``nf = n - p`` columns are ``Z`` (the null-space basis, eq. 16). It is
stored by columns, as ``Wt = W^T`` (row c of ``Wt`` is column c of ``W``):
the updates (reflectors from the right, Givens on two columns) and the products
``W^T a`` then run on contiguous vectors of length n.
``R`` (n, n) holds, column j, the coordinates of working row j in ``W``:
``C^T = W[:, :p] R[:p, :p]`` with ``R[:p, :p]`` upper triangular (rows enter in
order). Every routine returns the number of multiply-adds it did (the flop
counter of :class:`~solvers.base.SolveResult`).

Rows are read from ``A`` (m, n); a *bound row* (one nonzero, e.g. a box row
``e_i``) has ``bcol[i] >= 0`` and coefficient ``bval[i]``: its products cost
O(1) instead of O(n).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, types
from numba.extending import intrinsic
from numba.np.arrayobj import make_array, populate_array

#: the projection of the objective rows on Z (:func:`project_into`) calls BLAS from these
#: sizes up; below, the vectorised loops beat a BLAS call (its overhead ~1 us). The basis
#: updates never call it: the loops two reflectors at a time beat the compact WY form with
#: BLAS at every size measured (IK-like warm n=80 137 -> 105 us, n=480 17.9 -> 15.8 ms)
BLAS_MIN_ROWS = 8
BLAS_MIN_N = 64
BLAS_MIN_WORK = 20_000
#: fast-math flags of every kernel: reassociation (vectorised reductions) and FMA
#: contraction; no "nnan"/"ninf" (the kernels test finiteness)
FASTMATH = frozenset({"reassoc", "contract", "nsz", "arcp"})
_FM = set(FASTMATH)


# -- vector primitives on 1-D views. Loops run over range(len) from 0: numba then knows the
# index is nonnegative (no wraparound test) and LLVM vectorises them (a loop over
# range(p, n) on a 2-D array stays scalar: ~10x slower on these sizes).
@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def vdot(x, y):
    """``x @ y`` for 1-D views of equal length."""
    s = 0.0
    for c in range(x.shape[0]):
        s += x[c] * y[c]
    return s


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def vaxpy(a, x, y):
    """``y += a x`` for 1-D views of equal length."""
    for c in range(x.shape[0]):
        y[c] += a * x[c]


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def vreflect(bt, v, y):
    """``y <- (I - bt v v^T) y`` for 1-D views of equal length (2 len flops)."""
    s = 0.0
    for c in range(v.shape[0]):
        s += v[c] * y[c]
    s *= bt
    for c in range(v.shape[0]):
        y[c] -= s * v[c]


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def vreflect4(bt, v, y0, y1, y2, y3):
    """:func:`vreflect` on four views at once (each load of v shared by four
    rows: ~1.25 loads per multiply-add instead of 2)."""
    s0 = 0.0
    s1 = 0.0
    s2 = 0.0
    s3 = 0.0
    for c in range(v.shape[0]):
        e = v[c]
        s0 += e * y0[c]
        s1 += e * y1[c]
        s2 += e * y2[c]
        s3 += e * y3[c]
    s0 *= bt
    s1 *= bt
    s2 *= bt
    s3 *= bt
    for c in range(v.shape[0]):
        e = v[c]
        y0[c] -= s0 * e
        y1[c] -= s1 * e
        y2[c] -= s2 * e
        y3[c] -= s3 * e


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def reflect_rows(bt, v, M, j0, j1, c0):
    """``M[j, c0:c0 + len(v)] <- (I - bt v v^T) M[j, c0:...]`` for the rows
    j0 <= j < j1 of M, four at a time."""
    c1 = c0 + v.shape[0]
    j = j0
    while j + 4 <= j1:
        vreflect4(bt, v, M[j, c0:c1], M[j + 1, c0:c1], M[j + 2, c0:c1], M[j + 3, c0:c1])
        j += 4
    while j < j1:
        vreflect(bt, v, M[j, c0:c1])
        j += 1


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def householder(v, nrm):
    """Turn ``v`` (norm ``nrm`` > 0) into the vector of the reflector
    ``I - bt v v^T`` that maps it to ``alpha e_1`` (sign chosen against
    cancellation): ``v[0] -= alpha``. Returns (alpha, bt)."""
    x0 = v[0]
    alpha = -nrm if x0 >= 0.0 else nrm
    v[0] = x0 - alpha
    return alpha, 1.0 / (nrm * (nrm + abs(x0)))


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def wt_times_row(A, i, bcol, bval, Wt, out):
    """``out = W^T a`` for the row ``a = A[i]`` (``out[c] = Wt[c] @ a``; a
    gather of column ``bcol[i]`` of ``Wt`` for a bound row). Returns flops."""
    n = Wt.shape[0]
    b = bcol[i]
    if b >= 0:
        v = bval[i]
        for c in range(n):
            out[c] = v * Wt[c, b]
        return n
    ra = A[i]
    for c in range(n):
        out[c] = vdot(Wt[c], ra)
    return n * n


@intrinsic
def unowned(typingctx, arr):
    """The array ``arr`` (same data, shape, strides and type) with no owner
    (null meminfo and parent). numba then skips the reference counting of
    every view taken of it and of every call it is passed to: on an owned
    array each costs two atomic operations, ~0.7 us per solve at the entry
    of the kernel alone (its ~45 block views). Valid while the caller holds
    ``arr`` (the kernels' workspaces, held by the solver object); the result
    and its views must not outlive the call (the kernels return none)."""

    def codegen(context, builder, sig, args):
        src = make_array(sig.args[0])(context, builder, args[0])
        dst = make_array(sig.return_type)(context, builder)
        populate_array(dst, data=src.data, shape=src.shape, strides=src.strides,
                       itemsize=src.itemsize, meminfo=None, parent=None)
        return dst._getvalue()

    return arr(arr), codegen


@intrinsic
def matrix_view(typingctx, vec, rows, cols):
    """``vec.reshape((rows, cols))`` for a C-contiguous 1-D view of an
    :func:`unowned` array, without reshape's checks (~20 ns each; the kernel
    takes ten such views per call): the caller guarantees ``rows * cols <=
    vec.size``. The result is unowned, like ``vec``."""
    if not (isinstance(vec, types.Array) and vec.ndim == 1 and vec.layout == "C"):
        return None
    mat = types.Array(vec.dtype, 2, "C")

    def codegen(context, builder, sig, args):
        src = make_array(sig.args[0])(context, builder, args[0])
        dst = make_array(mat)(context, builder)
        nr = context.cast(builder, args[1], sig.args[1], types.intp)
        nc = context.cast(builder, args[2], sig.args[2], types.intp)
        row_bytes = builder.mul(nc, src.itemsize)
        populate_array(dst, data=src.data, shape=[nr, nc], strides=[row_bytes, src.itemsize],
                       itemsize=src.itemsize, meminfo=None, parent=None)
        return dst._getvalue()

    return mat(vec, rows, cols), codegen

__all__ = [
    "apply_reflectors",
    "apply_reflectors_to_basis",
    "cod",
    "delete_row",
    "householder",
    "insert_row",
    "insert_rows",
    "level_scale",
    "matrix_view",
    "mf_reflect",
    "multipliers",
    "project_into",
    "reflect_rows",
    "row_dot",
    "solve_lower",
    "step_from_z",
    "unowned",
    "wt_times_row",
]


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def level_scale(A, s0, s1, n):
    """``1 / ||A[s0:s1, :n]||_F`` without overflow or underflow of the squares
    (the per-level scaling of the HCOD kernels); 1.0 for a zero block."""
    s = 0.0
    for i in range(s0, s1):
        ra = A[i, :n]
        s += vdot(ra, ra)
    if s > 1e-280 and s < 1e280:
        return 1.0 / math.sqrt(s)
    amax = 0.0  # rescale first
    for i in range(s0, s1):
        for c in range(n):
            amax = max(amax, abs(A[i, c]))
    if amax == 0.0:
        return 1.0
    s = 0.0
    for i in range(s0, s1):
        for c in range(n):
            a = A[i, c] / amax
            s += a * a
    sc = 1.0 / (amax * math.sqrt(s))
    if not (sc > 0.0 and sc < np.inf):
        sc = 1.0 / amax
    return sc


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def row_dot(a, b, bv, x):
    """``a @ x`` for the row ``a = A[i]`` with ``b = bcol[i]``, ``bv = bval[i]``
    (O(1) for a bound row). Takes the row view and scalars: on owned arrays,
    passing the whole arrays into a helper costs ~35 ns of reference counting
    per call (the kernels' own arrays are :func:`unowned`)."""
    if b >= 0:
        return bv * x[b]
    return vdot(a, x)


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def cod(Mr, nO, nf, thr, rows, bvec, diag, beta):
    """Rank-revealing Householder QR with column pivoting of ``M^T`` (nf, nO),
    whose columns are the rows of ``Mr``: ``M^T Pi = H [R1 R2; 0 0]``, the
    first half of the COD (19) (``L_k = [R1 R2]^T``, ``Y_k = H[:, :r]``,
    ``Z_k = H[:, r:]``).

    Pivoting permutes ``Mr``, ``rows`` and ``bvec`` together. The rank r is
    the number of pivots whose remaining norm exceeds ``thr`` (the relative
    threshold times ``||A_k||``, see the package docstring). Remaining norms
    are downdated, and recomputed when cancellation makes the downdate
    unreliable. On return, reflector i is ``I - beta[i] v v^T`` with
    ``v = Mr[i, i:nf]``, ``diag[i]`` is ``R1[i, i]`` and ``Mr[j, i]`` (j > i)
    is ``R[i, j]``. ``beta[i:]`` holds the squared norms while running.

    Returns (r, flops)."""
    fl = nO * nf
    for j in range(nO):
        mj = Mr[j, :nf]
        beta[j] = vdot(mj, mj)
    kmax = min(nO, nf)
    r = 0
    for i in range(kmax):
        best = -1.0
        jb = i
        for j in range(i, nO):
            if beta[j] > best:
                best = beta[j]
                jb = j
        mb = Mr[jb, i:nf]
        fl += nf - i
        nrm = math.sqrt(vdot(mb, mb))
        if not nrm > thr:
            break
        if jb != i:
            for c in range(nf):
                t = Mr[i, c]
                Mr[i, c] = Mr[jb, c]
                Mr[jb, c] = t
            ti = rows[i]
            rows[i] = rows[jb]
            rows[jb] = ti
            tb = bvec[i]
            bvec[i] = bvec[jb]
            bvec[jb] = tb
            beta[jb] = beta[i]
        alpha, bt = householder(Mr[i, i:nf], nrm)
        beta[i] = bt
        diag[i] = alpha
        vi = Mr[i, i:nf]
        reflect_rows(bt, vi, Mr, i + 1, nO, i)
        for j in range(i + 1, nO):
            v = beta[j] - Mr[j, i] * Mr[j, i]
            if v > 1e-3 * beta[j]:
                beta[j] = v
            else:
                mj = Mr[j, i + 1:nf]
                beta[j] = vdot(mj, mj)
        fl += 2 * (nO - i - 1) * (nf - i)
        r = i + 1
    return r, fl


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def solve_lower(Mr, diag, nO, r, bvec, Lb, y):
    """Least-squares solve of the second half of the COD (19):
    ``y = argmin ||L y - c||`` with ``L`` (nO, r) of full column rank,
    ``L[j, l] = R[l, j]`` (from :func:`cod`) and ``c = bvec[:nO]`` (the
    permuted residual ``e_k - J_k u``). When r == nO, L is lower triangular
    and this is a forward substitution; otherwise L is reduced by Householder
    (``L = V_k [L_k; 0]``, eq. 19) in the scratch ``Lb`` (r, nO), and bvec is
    overwritten. Returns flops."""
    fl = 0
    if r == nO:
        for i in range(r):
            s = bvec[i]
            for l in range(i):
                s -= Mr[i, l] * y[l]
            y[i] = s / diag[i]
        return r * r // 2 + r
    for l in range(r):
        for j in range(nO):
            if j > l:
                Lb[l, j] = Mr[j, l]
            elif j == l:
                Lb[l, j] = diag[l]
            else:
                Lb[l, j] = 0.0
    for l in range(r):
        vl = Lb[l, l:nO]
        nrm = math.sqrt(vdot(vl, vl))
        alpha, bt = householder(vl, nrm)
        for l2 in range(l + 1, r):
            vreflect(bt, vl, Lb[l2, l:nO])
        vreflect(bt, vl, bvec[l:nO])
        Lb[l, l] = alpha
        fl += 2 * (r - l) * (nO - l) + 2 * (nO - l)
    for l in range(r - 1, -1, -1):
        s = bvec[l]
        for l2 in range(l + 1, r):
            s -= Lb[l2, l] * y[l2]
        y[l] = s / Lb[l, l]
    return fl + r * r // 2


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def apply_reflectors(Mr, beta, r, nf, z):
    """``z <- H z`` with ``H = H_0 ... H_{r-1}`` from :func:`cod`; z (nf,).
    Used for ``Z_{k-1} Y_k y`` in eq. (31). Returns flops."""
    fl = 0
    for i in range(r - 1, -1, -1):
        vreflect(beta[i], Mr[i, i:nf], z[i:nf])
        fl += 2 * (nf - i)
    return fl


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def step_from_z(Wt, p, z, out):
    """``out = Z z`` with ``Z = W[:, p:]`` (n, nf), i.e. the rows ``Wt[p:]``
    combined. Returns flops."""
    n = Wt.shape[0]
    out[:] = 0.0
    for c in range(n - p):
        vaxpy(z[c], Wt[p + c], out)
    return n * (n - p)


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def apply_reflectors_to_basis(Wt, p, Mr, beta, r, sv, sv2):
    """``W[:, p:] <- W[:, p:] H`` (eq. 23: ``[Y_bar_k, Z_k] = Z_{k-1} H``) with
    ``H = H_0 ... H_{r-1}``, reflector i = ``I - beta[i] v v^T`` on the
    columns ``p + i:`` (``v = Mr[i, i:nf]``). On ``Wt = W^T``: ``s = sum_c v_c
    Wt[p + i + c]``, then ``Wt[p + i + c] -= beta_i v_c s`` (vectors of length n).
    Two reflectors at a time: one pass over the rows of ``Wt`` for both sums,
    ``s2 -= beta_i (v_{i+1} . v_i) s1`` (reflector i acts first), one pass for
    the update. After it, ``W[:, p:p+r]`` spans the projected level and
    ``W[:, p+r:]`` is ``Z_k``. sv, sv2 (n,) are scratch. Returns flops."""
    n = Wt.shape[0]
    nf = n - p
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
        for c in range(i + 1, nf):
            a = v1[c]
            b = v2[c]
            d12 += a * b
            w = Wt[p + c]
            for e in range(n):
                x = w[e]
                sv[e] += a * x
                sv2[e] += b * x
        g = b1 * d12
        for e in range(n):
            sv2[e] -= g * sv[e]
        vaxpy(-b1 * v1[i], sv, Wt[p + i])
        for c in range(i + 1, nf):
            a = b1 * v1[c]
            b = b2 * v2[c]
            w = Wt[p + c]
            for e in range(n):
                w[e] -= a * sv[e] + b * sv2[e]
        i += 2
    if i < r:
        sv[:] = 0.0
        for c in range(i, nf):
            vaxpy(Mr[i, c], Wt[p + c], sv)
        bt = -beta[i]
        for c in range(i, nf):
            vaxpy(bt * Mr[i, c], sv, Wt[p + c])
    return 2 * n * nf * r


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def insert_row(A, i, bcol, bval, Wt, R, p, thr, q, sv):
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
    fl = wt_times_row(A, i, bcol, bval, Wt, q)
    qz = q[p:]
    nrm = math.sqrt(vdot(qz, qz))
    if not nrm > thr:
        return False, fl, 0.0
    alpha, bt = householder(qz, nrm)
    sv[:] = 0.0
    for c in range(n - p):
        vaxpy(qz[c], Wt[p + c], sv)
    for c in range(n - p):
        vaxpy(-bt * qz[c], sv, Wt[p + c])
    fl += 2 * n * (n - p)
    for c in range(p):
        R[c, p] = q[c]
    R[p, p] = alpha
    return True, fl, bt


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def insert_rows(A, cand, m, bcol, bval, Wt, R, p, rank_rtol, lnorm, rowlev, Qb, bq, cok, sv, sv2):
    """Add the rows ``A[cand[:m]]`` to the working constraints, in order, as m
    calls of :func:`insert_row` would (same rank test, same ``W`` and ``R``),
    but blocked: ``Q = A_cand W`` at once, the Householder QR of ``Q[:, p:]``
    row by row (row j meets the reflectors of the accepted rows before it),
    then the t accepted reflectors applied to ``W[:, p:]`` together
    (:func:`apply_reflectors_to_basis`). ``cok[j]`` = 1 when row j entered.
    Shapes: Qb (>= m, n), bq (>= m), sv, sv2 (n,) scratch. Returns (t, flops)."""
    n = Wt.shape[0]
    fl = 0
    for j in range(m):
        fl += wt_times_row(A, cand[j], bcol, bval, Wt, Qb[j])
    t = 0
    for j in range(m):
        i = cand[j]
        c0 = p + t
        v = Qb[j, c0:]
        nrm = math.sqrt(vdot(v, v))
        if not nrm > rank_rtol * lnorm[rowlev[i]]:
            cok[j] = 0
            continue
        cok[j] = 1
        alpha, bt = householder(v, nrm)
        for l in range(c0):
            R[l, c0] = Qb[j, l]
        R[c0, c0] = alpha
        reflect_rows(bt, v, Qb, j + 1, m, c0)
        fl += 2 * (m - j - 1) * (n - c0)
        if t < j:  # keep the reflectors packed: reflector t in Qb[t, p + t:]
            Qb[t, c0:] = v
        bq[t] = bt
        t += 1
    if t > 0:
        fl += apply_reflectors_to_basis(Wt, p, Qb[:, p:], bq, t, sv, sv2)
    return t, fl


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def delete_row(j, Wt, R, p, widx, wside):
    """Remove working row j (0 <= j < p): drop column j of R (it becomes upper
    Hessenberg) and restore the triangle by Givens rotations applied to R's
    rows and W's columns (``W R`` is unchanged; the columns of W are the rows
    of ``Wt``). ``widx``/``wside`` shift. Returns flops; the caller decrements p.

    The rotation of ``(a, b) = (R[i, i], R[i + 1, i])`` takes ``sqrt(a^2 +
    b^2)``, not hypot: R's columns are rows of a level scaled to norm 1
    (entries <= 1 in magnitude) and ``b`` is a former diagonal entry, above
    the rank threshold (1e-10 by default): far from under- and overflow."""
    n = Wt.shape[0]
    fl = 0
    if j >= p - 1:
        return 0
    for col in range(j, p - 1):
        for rr in range(col + 2):
            R[rr, col] = R[rr, col + 1]
        widx[col] = widx[col + 1]
        wside[col] = wside[col + 1]
    # Givens rotations down the subdiagonal. The next pivot a = R[i + 1, i + 1] after
    # rotation i is carried in a register (computed from the entries loaded before the row
    # update): the chain from one rotation to the next is sqrt, division, one fma
    a = R[j, j]
    for i in range(j, p - 1):
        b = R[i + 1, i]
        h = math.sqrt(a * a + b * b)
        if h == 0.0:
            a = R[i + 1, i + 1]
            continue
        c = a / h
        s = b / h
        if i + 1 < p - 1:
            a = -s * R[i, i + 1] + c * R[i + 1, i + 1]
        R[i, i] = h
        R[i + 1, i] = 0.0
        r1 = R[i, i + 1:p - 1]
        r2 = R[i + 1, i + 1:p - 1]
        for col in range(r1.shape[0]):
            x1 = r1[col]
            x2 = r2[col]
            r1[col] = c * x1 + s * x2
            r2[col] = -s * x1 + c * x2
        w1 = Wt[i]
        w2 = Wt[i + 1]
        for rr in range(n):
            a1 = w1[rr]
            a2 = w2[rr]
            w1[rr] = c * a1 + s * a2
            w2[rr] = -s * a1 + c * a2
        fl += 4 * (p - 1 - i) + 4 * n
    return fl


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def multipliers(Wt, R, p, g, h, nu):
    """Multipliers of the working constraints (eq. 39):
    ``C^T nu = -g`` solved as ``R nu = -W[:, :p]^T g``; g (n,) is the gradient
    ``J_k^T w_k`` of the level's objective. Returns flops."""
    n = Wt.shape[0]
    for c in range(p):
        h[c] = vdot(Wt[c], g)
    for c in range(p - 1, -1, -1):
        nu[c] = (-h[c] - vdot(R[c, c + 1:p], nu[c + 1:p])) / R[c, c]
    return n * p + p * p // 2


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def project_into(A, Olist, j0, j1, bcol, bval, Wt, p, Mf):
    """``Mf[j, p:] = A[Olist[j]] @ W[:, p:]`` for j0 <= j < j1: the objective rows
    projected on Z (eq. 19), kept up to date across iterations. Returns flops."""
    n = Wt.shape[0]
    fl = 0
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


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def mf_reflect(Mf, nO, p, q, bt):
    """After a row entered ``W`` (reflector ``I - bt q[p:] q[p:]^T`` applied to
    ``W[:, p:]``), update the projected objective rows the same way. Returns flops."""
    n = Mf.shape[1]
    qz = q[p:]
    for j in range(nO):
        vreflect(bt, qz, Mf[j, p:])
    return 2 * nO * (n - p)
