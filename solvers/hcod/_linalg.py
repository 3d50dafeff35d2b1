"""Numba kernels of the HCOD: vector primitives (products, reflectors one,
two or four rows at a time), the rank-revealing COD of a projected level and
its least-squares solve, and the array helpers of the kernels (unowned
workspaces, cheap 2-D views). The basis ``W`` and the updates of the
constraint decomposition are in :mod:`._basis`; the orthogonal factors
applied to the columns of a basis stored by columns are at the end.

Every routine that computes returns the number of multiply-adds it did (the
flop counter of :class:`~hikbench.solvers.base.SolveResult`). Rows are read from
``A`` (m, n); a *bound row* (one nonzero, e.g. a box row ``e_i``) has
``bcol[i] >= 0`` and coefficient ``bval[i]``: its products cost O(1).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, types
from numba.extending import intrinsic
from numba.np.arrayobj import make_array, populate_array

from hikbench.solvers.hcod import _cache  # noqa: F401  (before any @njit: cache stamps over every hcod file)

#: fast-math flags of every kernel: reassociation (vectorised reductions) and FMA
#: contraction; no "nnan"/"ninf" (the kernels test finiteness)
FASTMATH = frozenset({"reassoc", "contract", "nsz", "arcp"})
#: a pivot of a level's COD (19) within NEAR_RANK times the rank threshold may be rounding: a
#: level in the span of the rows above, projected on Z just above the threshold. An LSE step
#: through such a pivot that moves u by more than ``NEAR_RANK_STEP (1 + ||u||)`` leaves out the
#: pivots from that one on (``info["near_rank_steps_cut"]``; ._kernel, ._equality): its rounding,
#: eps times the step along the rows above, would violate them. A level whose huge optimum is
#: real (rows of norm 1e-11, full rank at their own scale) has pivots of order its own norm, far
#: from the threshold.
NEAR_RANK = 10.0
NEAR_RANK_STEP = 1e6
#: a wide level's COD (:func:`cod`, ``rrt``) takes a pivot past the level's rank threshold when the
#: row's remaining norm exceeds this fraction of its own norm (or ``rank_rtol``, if larger). A
#: row's projection on Z carries rounding of about eps x cond(rows above) x (their spread of
#: norms): up to 1e-6 of its norm at cond 1e6 and rows over 1e4 (the conditioning sweep's trial
#: 2272: pivots of 1e-6 .. 3e-6 of their rows, taken, left level 1 6.8e-4 above where the level's
#: threshold leaves it). The cuts this mends were 1.6e-4 .. 6.1e-3 of their rows (badly_scaled
#: n = 12 seeds 128, 1143, 1402, 1696, 2785, 2876, 3144)
ROW_RANK_RTOL = 1e-5
_FM = set(FASTMATH)
#: the products of many general rows with an explicit basis (``_explicit.project_into``,
#: ``_factored.basis_rows``) call BLAS from these sizes up; below, the vectorised loops beat a
#: BLAS call (its overhead ~1 us). The basis updates never call it: the loops two reflectors
#: at a time beat the compact WY form with BLAS at every size measured
BLAS_MIN_ROWS = 8
BLAS_MIN_N = 64
BLAS_MIN_WORK = 20_000


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
def reflect_pair(b1, v1, b2, v2, d12, x):
    """Apply two consecutive reflectors (of a level, or of the pending queue of
    :mod:`._factored`), ``H1 = I - b1 v1 v1^T``
    then ``H2 = I - b2 v2 v2^T`` acting on ``x[1:]`` (v2 starts one column
    later), to the row view x in one pass for the dots and one for the
    update: ``s1 = b1 v1.x``, ``s2 = b2 (v2.x[1:] - s1 d12)`` with ``d12 =
    v2.v1[1:]``, ``x -= s1 v1 + s2 [0, v2]``. Shapes: v1, x (L,), v2 (L-1,)."""
    a = v1[0] * x[0]
    b = 0.0
    v1s = v1[1:]
    xs = x[1:]
    for c in range(v2.shape[0]):
        a += v1s[c] * xs[c]
        b += v2[c] * xs[c]
    s1 = b1 * a
    s2 = b2 * (b - s1 * d12)
    x[0] -= s1 * v1[0]
    for c in range(v2.shape[0]):
        xs[c] -= s1 * v1s[c] + s2 * v2[c]


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def reflect_pair4(b1, v1, b2, v2, d12, x, y, z, w):
    """:func:`reflect_pair` on four row views together (shared loads of v1
    and v2)."""
    ax = v1[0] * x[0]
    ay = v1[0] * y[0]
    az = v1[0] * z[0]
    aw = v1[0] * w[0]
    bx = 0.0
    by = 0.0
    bz = 0.0
    bw = 0.0
    v1s = v1[1:]
    xs = x[1:]
    ys = y[1:]
    zs = z[1:]
    ws = w[1:]
    for c in range(v2.shape[0]):
        e1 = v1s[c]
        e2 = v2[c]
        ax += e1 * xs[c]
        bx += e2 * xs[c]
        ay += e1 * ys[c]
        by += e2 * ys[c]
        az += e1 * zs[c]
        bz += e2 * zs[c]
        aw += e1 * ws[c]
        bw += e2 * ws[c]
    s1x = b1 * ax
    s2x = b2 * (bx - s1x * d12)
    s1y = b1 * ay
    s2y = b2 * (by - s1y * d12)
    s1z = b1 * az
    s2z = b2 * (bz - s1z * d12)
    s1w = b1 * aw
    s2w = b2 * (bw - s1w * d12)
    x[0] -= s1x * v1[0]
    y[0] -= s1y * v1[0]
    z[0] -= s1z * v1[0]
    w[0] -= s1w * v1[0]
    for c in range(v2.shape[0]):
        e1 = v1s[c]
        e2 = v2[c]
        xs[c] -= s1x * e1 + s2x * e2
        ys[c] -= s1y * e1 + s2y * e2
        zs[c] -= s1z * e1 + s2z * e2
        ws[c] -= s1w * e1 + s2w * e2


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def quad_gram(v1, v2, v3, v4):
    """The products ``g_ij = v_i . v_j`` (i > j, over v_i's columns) of four
    consecutive reflectors of a level, ``v_i`` starting ``i - 1`` columns after
    ``v1`` (shapes (L,), (L-1,), (L-2,), (L-3,)): the coupling terms of
    :func:`reflect_quad`. Returns (g21, g31, g32, g41, g42, g43)."""
    g21 = v2[0] * v1[1]
    g31 = v3[0] * v1[2]
    g32 = v3[0] * v2[1]
    g21 += v2[1] * v1[2]
    v1s = v1[3:]
    v2s = v2[2:]
    v3s = v3[1:]
    g41 = 0.0
    g42 = 0.0
    g43 = 0.0
    for c in range(v4.shape[0]):
        e4 = v4[c]
        e3 = v3s[c]
        e2 = v2s[c]
        e1 = v1s[c]
        g21 += e2 * e1
        g31 += e3 * e1
        g32 += e3 * e2
        g41 += e4 * e1
        g42 += e4 * e2
        g43 += e4 * e3
    return g21, g31, g32, g41, g42, g43


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def _quad_head(v1, v2, v3, x):
    """The dots of :func:`reflect_quad` over the three columns where not all
    four reflectors are nonzero."""
    a1 = v1[0] * x[0] + v1[1] * x[1] + v1[2] * x[2]
    a2 = v2[0] * x[1] + v2[1] * x[2]
    a3 = v3[0] * x[2]
    return a1, a2, a3


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def _quad_coef(b, g, a1, a2, a3, a4):
    """``s_i = b_i (v_i . x_{i-1})`` where ``x_{i-1}`` is x after the first
    i - 1 reflectors: ``v_i . x_{i-1} = a_i - sum_{j<i} s_j g_ij``."""
    g21, g31, g32, g41, g42, g43 = g
    b1, b2, b3, b4 = b
    s1 = b1 * a1
    s2 = b2 * (a2 - s1 * g21)
    s3 = b3 * (a3 - s1 * g31 - s2 * g32)
    s4 = b4 * (a4 - s1 * g41 - s2 * g42 - s3 * g43)
    return s1, s2, s3, s4


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def _quad_tail(v1, v2, v3, x, s1, s2, s3):
    x[0] -= s1 * v1[0]
    x[1] -= s1 * v1[1] + s2 * v2[0]
    x[2] -= s1 * v1[2] + s2 * v2[1] + s3 * v3[0]


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def reflect_quad(b, g, v1, v2, v3, v4, x):
    """Apply four consecutive reflectors ``H_i = I - b_i v_i v_i^T`` (H1 first;
    ``v_i`` starts ``i - 1`` columns after v1, shapes (L,), (L-1,), (L-2,),
    (L-3,)) to the row view x (L,) in one pass for the dots and one for the
    update: ``x -= sum_i s_i v_i`` with the ``s_i`` of :func:`_quad_coef`
    (b = (b1..b4), g from :func:`quad_gram`)."""
    a1, a2, a3 = _quad_head(v1, v2, v3, x)
    a4 = 0.0
    v1s = v1[3:]
    v2s = v2[2:]
    v3s = v3[1:]
    xs = x[3:]
    for c in range(v4.shape[0]):
        xc = xs[c]
        a1 += v1s[c] * xc
        a2 += v2s[c] * xc
        a3 += v3s[c] * xc
        a4 += v4[c] * xc
    s1, s2, s3, s4 = _quad_coef(b, g, a1, a2, a3, a4)
    _quad_tail(v1, v2, v3, x, s1, s2, s3)
    for c in range(v4.shape[0]):
        xs[c] -= s1 * v1s[c] + s2 * v2s[c] + s3 * v3s[c] + s4 * v4[c]


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def reflect_quad2(b, g, v1, v2, v3, v4, x, y):
    """:func:`reflect_quad` on two row views together: 8 products per four
    loads of the reflectors and two of the rows, and in the update 8
    multiply-adds per two stores. (Two rows, not four: four rows' 16 sums,
    or 16 coefficients, do not fit AVX2's 16 vector registers; LLVM kept 6
    of them on the stack, a load and a store each per iteration: equality
    n = 120 8 x 12 took 13 % longer, paired.)"""
    ax1, ax2, ax3 = _quad_head(v1, v2, v3, x)
    ay1, ay2, ay3 = _quad_head(v1, v2, v3, y)
    ax4 = 0.0
    ay4 = 0.0
    v1s = v1[3:]
    v2s = v2[2:]
    v3s = v3[1:]
    xs = x[3:]
    ys = y[3:]
    for c in range(v4.shape[0]):
        e1 = v1s[c]
        e2 = v2s[c]
        e3 = v3s[c]
        e4 = v4[c]
        xc = xs[c]
        yc = ys[c]
        ax1 += e1 * xc
        ax2 += e2 * xc
        ax3 += e3 * xc
        ax4 += e4 * xc
        ay1 += e1 * yc
        ay2 += e2 * yc
        ay3 += e3 * yc
        ay4 += e4 * yc
    sx1, sx2, sx3, sx4 = _quad_coef(b, g, ax1, ax2, ax3, ax4)
    sy1, sy2, sy3, sy4 = _quad_coef(b, g, ay1, ay2, ay3, ay4)
    _quad_tail(v1, v2, v3, x, sx1, sx2, sx3)
    _quad_tail(v1, v2, v3, y, sy1, sy2, sy3)
    for c in range(v4.shape[0]):
        e1 = v1s[c]
        e2 = v2s[c]
        e3 = v3s[c]
        e4 = v4[c]
        xs[c] -= sx1 * e1 + sx2 * e2 + sx3 * e3 + sx4 * e4
        ys[c] -= sy1 * e1 + sy2 * e2 + sy3 * e3 + sy4 * e4


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def householder(v, nrm):
    """Turn ``v`` (norm ``nrm`` > 0) into the vector of the reflector
    ``I - bt v v^T`` that maps it to ``alpha e_1`` (sign chosen against
    cancellation): ``v[0] -= alpha``. Returns (alpha, bt).

    Outside 1e-150 < nrm < 1e150, ``bt ~ 1 / nrm^2`` overflows (or underflows)
    and ``nrm`` itself may have lost its last bits to subnormal squares: v is
    first scaled by a power of 2 to a norm in [0.5, 1) (the same reflector,
    with bt for the scaled v; LAPACK's dlarfg rescales likewise), and alpha
    scaled back. A level's rows 1e-155 the size of its largest meet this."""
    back = 1.0
    if not (1e-150 < nrm < 1e150):
        back, nrm = _scale_to_unit(v, nrm)
    x0 = v[0]
    alpha = -nrm if x0 >= 0.0 else nrm
    v[0] = x0 - alpha
    return alpha * back, 1.0 / (nrm * (nrm + abs(x0)))


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def _scale_to_unit(v, nrm):
    """v times 2^e, its norm brought to [0.5, 1) (two factors: 2^e alone overflows for a
    subnormal nrm). Returns (2^-e, the norm computed again); 2^-e is exact, subnormal or not."""
    e = -math.frexp(nrm)[1]
    s1 = math.ldexp(1.0, e // 2)
    s2 = math.ldexp(1.0, e - e // 2)
    for c in range(v.shape[0]):
        v[c] = (v[c] * s1) * s2
    return math.ldexp(1.0, -e), math.sqrt(vdot(v, v))


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
    "cod",
    "householder",
    "level_scale",
    "matrix_view",
    "mf_reflect",
    "near_rank_cut",
    "quad_gram",
    "reflect_pair",
    "reflect_pair4",
    "reflect_quad",
    "reflect_quad2",
    "reflect_rows",
    "row_dot",
    "solve_lower",
    "unowned",
]


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def near_rank_cut(y, d, r, thr, ycap):
    """Where a level's LSE solution ``y`` (r,) of the COD (19), pivots ``d``
    (r,), is cut (NEAR_RANK): the first pivot t within ``NEAR_RANK thr`` of
    zero at which ``||y[:t+1]||`` passes ``ycap``, or -1."""
    acc = 0.0
    for t in range(r):
        acc += y[t] * y[t]
        if acc > ycap * ycap and abs(d[t]) <= NEAR_RANK * thr:
            return t
    return -1


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
        # amax near the largest double, or subnormal: 1 / amax overflows below ~5.6e-309, where
        # the largest power of 2 brings the level to a norm of 2^1023 amax (0.28 at 3e-309)
        sc = min(1.0 / amax, math.ldexp(1.0, 1023))
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


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def row_axpy(w, a, b, bv, y):
    """``y += w a`` for the row ``a = A[i]`` (see :func:`row_dot`; O(1) for a
    bound row)."""
    if b >= 0:
        y[b] += bv * w
    else:
        vaxpy(w, a, y)


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def cod(Mr, nO, nf, thr, rows, diag, beta, rrt, Olist, rnorm):
    """Rank-revealing Householder QR with column pivoting of ``M^T`` (nf, nO),
    whose columns are the rows of ``Mr``: ``M^T Pi = H [R1 R2; 0 0]``, the
    first half of the COD (19) (``L_k = [R1 R2]^T``, ``Y_k = H[:, :r]``,
    ``Z_k = H[:, r:]``).

    Pivoting permutes ``Mr`` and ``rows`` together. The rank r is
    the number of pivots whose remaining norm exceeds ``thr`` (the relative
    threshold times ``||A_k||``, see the package docstring). With ``rrt > 0``
    (a wide level: row norms spread beyond ``MET_SPREAD``), once no remaining
    norm exceeds ``thr``, pivoting goes on row by row: the row whose remaining
    norm is the largest fraction of its own norm ``rnorm[Olist[rows[j]]]``
    (unprojected) is a pivot while that fraction exceeds ``rrt`` (the kernel
    passes ``max(ROW_RANK_RTOL, rank_rtol)``). A row 1e-8 the size of its
    level's largest sees directions under the level's threshold that the
    large rows do not: cut, they were never descended. Remaining norms
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
            if rrt == 0.0:
                break
            # row by row: the largest remaining fraction of a row's own norm
            best = -1.0
            for j in range(i, nO):
                rn = rnorm[Olist[rows[j]]]
                if rn > 0.0 and beta[j] > best * rn * rn:
                    best = beta[j] / (rn * rn)
                    jb = j
            mb = Mr[jb, i:nf]
            fl += nf - i
            nrm = math.sqrt(vdot(mb, mb))
            if not nrm > rrt * rnorm[Olist[rows[jb]]]:
                break
        if jb != i:
            for c in range(nf):
                t = Mr[i, c]
                Mr[i, c] = Mr[jb, c]
                Mr[jb, c] = t
            ti = rows[i]
            rows[i] = rows[jb]
            rows[jb] = ti
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


#: a row appended to a level's COD as a pivot with a diagonal below this fraction of its
#: norm (above the rank threshold) has the COD refactored with pivoting before the freeze
WEAK_PIVOT = 1e-3


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def cod_append(Mr, j, nf, thr, r, rows, diag, beta, rrt, Olist, rnorm):
    """Update the COD of :func:`cod` (rank r, rows ``Mr[:j]``) for one more
    row, loaded in ``Mr[j, :nf]`` with its index in ``rows[j]`` (sec. IX: a
    row enters by updating the decomposition, not by refactoring it): the r
    reflectors are applied to the row; when what is left of it on the columns
    ``r:`` has norm above ``thr``, or ``rrt`` times its own unprojected norm
    (the rank tests of :func:`cod`), it becomes
    pivot r -- swapped with the first dependent row, reduced by one more
    reflector, which the dependent rows meet too.

    Without pivoting, a nearly dependent row that comes first becomes a pivot
    with a small diagonal where :func:`cod` would have taken a later row: the
    least-squares step is the same, but the pivots become working rows at the
    freeze. ``weak`` flags a new pivot whose diagonal is below ``WEAK_PIVOT``
    times the row's norm, so that the caller refactors with pivoting before
    the freeze. Returns (rank, flops, weak)."""
    mj = Mr[j, :nf]
    rn = math.sqrt(vdot(mj, mj))
    fl = nf
    for i in range(r):
        vreflect(beta[i], Mr[i, i:nf], mj[i:])
        fl += 2 * (nf - i)
    if r == nf:
        return r, fl, False
    v = mj[r:]
    nrm = math.sqrt(vdot(v, v))
    fl += nf - r
    if not (nrm > thr or (rrt > 0.0 and nrm > rrt * rnorm[Olist[rows[j]]])):
        return r, fl, False
    if j != r:
        for c in range(nf):
            t = Mr[r, c]
            Mr[r, c] = mj[c]
            mj[c] = t
        t = rows[r]
        rows[r] = rows[j]
        rows[j] = t
    alpha, bt = householder(Mr[r, r:nf], nrm)
    beta[r] = bt
    diag[r] = alpha
    reflect_rows(bt, Mr[r, r:nf], Mr, r + 1, j + 1, r)
    fl += 2 * (j - r) * (nf - r)
    return r + 1, fl, nrm < WEAK_PIVOT * rn


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def solve_upper(R, p, h, x):
    """``x = R[:p, :p]^-1 h[:p]`` for the upper triangular ``R`` (p*p/2
    multiply-adds), by columns: once ``x[c]`` is known its term leaves the rows
    above at once. The chain from one unknown to the next is then one fma and
    one division; by rows (dot products) it would be a whole reduction, and
    these solves are short (p <= n). h (>= p,) is overwritten."""
    for c in range(p - 1, -1, -1):
        v = h[c] / R[c, c]
        x[c] = v
        for l in range(c):
            h[l] -= v * R[l, c]


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def solve_lower(Mr, diag, nO, r, bvec, Lb, y):
    """Least-squares solve of the second half of the COD (19):
    ``y = argmin ||L y - c||`` with ``L`` (nO, r) of full column rank,
    ``L[j, l] = R[l, j]`` (from :func:`cod`) and ``c = bvec[:nO]`` (the
    permuted residual ``e_k - J_k u``). When r == nO, L is lower triangular
    and this is a forward substitution; otherwise L is reduced by Householder
    (``L = V_k [L_k; 0]``, eq. 19) in the scratch ``Lb`` (r, nO). Both
    substitutions go by columns (:func:`solve_upper`); bvec is overwritten.
    Returns flops."""
    fl = 0
    if r == nO:
        # forward substitution by columns
        for l in range(r):
            v = bvec[l] / diag[l]
            y[l] = v
            for i in range(l + 1, r):
                bvec[i] -= Mr[i, l] * v
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
    # L_k y = (V_k^T c)[:r] (L_k upper triangular here, from the QR of L) by columns (see
    # solve_upper): Lb[l, :l] is column l of L_k above its diagonal
    for l in range(r - 1, -1, -1):
        v = bvec[l] / Lb[l, l]
        y[l] = v
        vaxpy(-v, Lb[l, :l], bvec[:l])
    return fl + r * r // 2


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def qr_rows(Qb, cand, m, p, rank_rtol, rnorm, R, bq, cok):
    """The Householder QR, row by row, of ``Qb[:m, p:]`` (the candidate rows
    ``A[cand[:m]]`` projected on the basis, ``Qb[j] = W^T a_j``): row j meets
    the reflectors of the accepted rows before it, and enters (``cok[j]`` = 1)
    when what is left of it on the free columns has norm above
    ``rank_rtol * rnorm[cand[j]]`` (the rank test of a single insertion, at
    the row's own norm). The accepted row t gets ``R[:, p + t] = (Qb[j, :p + t],
    alpha)``; its reflector ``I - bq[t] v v^T`` on the columns ``p + t:`` is
    left packed in ``Qb[t, p + t:]``. Returns (t, flops)."""
    n = Qb.shape[1]
    fl = 0
    t = 0
    for j in range(m):
        c0 = p + t
        v = Qb[j, c0:]
        nrm = math.sqrt(vdot(v, v))
        if not nrm > rank_rtol * rnorm[cand[j]]:
            cok[j] = 0
            continue
        cok[j] = 1
        alpha, bt = householder(v, nrm)
        for l in range(c0):
            R[l, c0] = Qb[j, l]
        R[c0, c0] = alpha
        reflect_rows(bt, v, Qb, j + 1, m, c0)
        fl += 2 * (m - j - 1) * (n - c0)
        if t < j:
            Qb[t, c0:] = v
        bq[t] = bt
        t += 1
    return t, fl


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
def mf_reflect(Mf, nO, p, q, bt):
    """After a row entered ``W`` (reflector ``I - bt q[p:] q[p:]^T`` applied to
    ``W[:, p:]``), update the projected objective rows the same way. Returns flops."""
    n = Mf.shape[1]
    qz = q[p:]
    for j in range(nO):
        vreflect(bt, qz, Mf[j, p:])
    return 2 * nO * (n - p)


# -- orthogonal factors applied to the columns of a basis stored by columns (Wt = W^T: column c
# of W is the row Wt[c], a contiguous vector of length n)
@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def reflect_cols(Wt, o, bt, v, sv):
    """``W[:, o:o+L] <- W[:, o:o+L] (I - bt v v^T)`` (v (L,)): ``s = sum_c
    v_c Wt[o + c]``, then ``Wt[o + c] -= bt v_c s``. sv (n,) scratch. Returns
    flops."""
    sv[:] = 0.0
    for c in range(v.shape[0]):
        vaxpy(v[c], Wt[o + c], sv)
    for c in range(v.shape[0]):
        vaxpy(-bt * v[c], sv, Wt[o + c])
    return 2 * Wt.shape[0] * v.shape[0]


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def reflect_cols_pair(Wt, o, b1, v1, b2, v2, d, sv, sv2):
    """Two reflectors, ``W[:, o:] <- W[:, o:] H1 H2`` with v1 (L,) on the
    columns ``o:o+L`` and v2 (L-1,) one column to the right, ``d = v1[1:] .
    v2``: one pass over the rows of Wt for both sums, ``s2 -= b1 d s1`` (H1
    acts first), one pass for the update. sv, sv2 (n,) scratch. Returns flops."""
    n = Wt.shape[0]
    a = v1[0]
    w = Wt[o]
    for e in range(n):
        sv[e] = a * w[e]
    sv2[:] = 0.0
    for c in range(v2.shape[0]):
        a = v1[c + 1]
        bb = v2[c]
        w = Wt[o + 1 + c]
        for e in range(n):
            x = w[e]
            sv[e] += a * x
            sv2[e] += bb * x
    g = b1 * d
    for e in range(n):
        sv2[e] -= g * sv[e]
    vaxpy(-b1 * v1[0], sv, Wt[o])
    for c in range(v2.shape[0]):
        a = b1 * v1[c + 1]
        bb = b2 * v2[c]
        w = Wt[o + 1 + c]
        for e in range(n):
            w[e] -= a * sv[e] + bb * sv2[e]
    return 4 * n * v1.shape[0]


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def rotate_cols(c, s, w1, w2):
    """``(w1, w2) <- (c w1 + s w2, -s w1 + c w2)``: a Givens rotation of two
    columns of W (two rows of Wt, (n,) each)."""
    for e in range(w1.shape[0]):
        a1 = w1[e]
        a2 = w2[e]
        w1[e] = c * a1 + s * a2
        w2[e] = -s * a1 + c * a2


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def retriangulate(j, R, p, widx, wside, cs, Wt, rotate_w):
    """Remove working row j (0 <= j < p - 1) from ``R``: drop its column (R
    becomes upper Hessenberg) and restore the triangle by the Givens rotations
    ``G_i`` of the rows ``(i, i + 1)``, i = j .. p - 2, stored as ``cs[2 (i -
    j)] = c``, ``cs[2 (i - j) + 1] = s`` (cs (>= 2 (p - 1 - j),); c = 1, s = 0
    when the pair is already zero). ``W R`` stays unchanged when the same
    rotations are applied to the columns ``(i, i + 1)`` of W: here, one
    rotation after the other, when ``rotate_w`` (a constant of the caller: W
    explicit, ``Wt = W^T``), else by the caller. ``widx``/``wside`` shift.
    Returns flops; the caller decrements p.

    The rotation of ``(a, b) = (R[i, i], R[i + 1, i])`` takes ``sqrt(a^2 +
    b^2)``, not hypot: R's columns are rows of a level scaled to norm 1
    (entries <= 1 in magnitude) and ``b`` is a former diagonal entry, above
    the rank threshold (1e-10 by default): far from under- and overflow."""
    fl = 0
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
            cs[2 * (i - j)] = 1.0
            cs[2 * (i - j) + 1] = 0.0
            a = R[i + 1, i + 1]
            continue
        c = a / h
        s = b / h
        cs[2 * (i - j)] = c
        cs[2 * (i - j) + 1] = s
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
        fl += 4 * (p - 1 - i)
        if rotate_w:
            rotate_cols(c, s, Wt[i], Wt[i + 1])
            fl += 4 * Wt.shape[0]
    return fl
