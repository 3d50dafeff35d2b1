"""Set-up of the inequality kernel: the scaled problem, the workspace layout
and the per-row / per-level data computed once per hierarchy."""

from __future__ import annotations

import math
from functools import lru_cache
from itertools import accumulate

import numpy as np
from numba import njit

from hikbench.solvers.hcod import _cache  # noqa: F401  (before any @njit: cache stamps over every hcod file)
from hikbench.solvers.hcod._factored import queue_sizes
from hikbench.solvers.hcod._linalg import FASTMATH, level_scale

from ._layout import (
    F_A,
    F_BETA,
    F_BLOCKS,
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
    FEND0,
    I_BCOL,
    I_BLOCKS,
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
    IOFF0,
    IP_D,
    IP_HAS_INEQ,
    IP_MAX_ITER,
    IP_MMAX,
    IP_MT,
    IP_N,
    IP_WARM,
    N_HEAD,
    N_IP,
    N_OUT,
    N_PRM,
)

_FM = set(FASTMATH)

#: a problem whose finite bounds, each level scaled by 1 / ||A_k||_F, are all below this in
#: magnitude is solved with its bounds multiplied by a power of 2 that brings the largest into [1, 2)
#: (:func:`load`). The kernel's absolute tolerance parts showed no error down to bounds x 1e-6 of
#: problems whose largest scaled bound is 0.1-1 (IK-like); this threshold leaves such problems as
#: they are (bit for bit) with a margin of 1e3
BOUND_SCALE_MIN = 2.0**-10
ALIGN = 8  #: float blocks start on multiples of 8 doubles (64 bytes)
# the blocks of the workspaces, their offsets in the header of the int one, the parameter slots:
# named in ._layout (F_BLOCKS, I_BLOCKS, FEND0, IOFF0, N_HEAD, N_IP, N_PRM, N_OUT are read from here too)


def layout(n: int, mt: int, D: int, mmax: int):
    """Offsets of the float and int workspaces (blocks in the order of
    F_BLOCKS / I_BLOCKS, ._layout). Returns (foff, fend, ioff), int64 arrays:
    float block b is ``fw[foff[b]:fend[b]]``, its start a multiple of ALIGN;
    int block b is ``iw[ioff[b]:ioff[b + 1]]``, after the header of N_HEAD
    entries that stores all three."""
    mm = max(mmax, 1)
    fsz = {F_W: n * n, F_R: n * n, F_U: n, F_PS: n, F_Z: n, F_G: n, F_HV: n, F_NU: n, F_Q: n, F_UPREV: n,
           F_Y: n, F_MR: mm * n, F_BVEC: mm, F_DIAG: mm, F_BETA: mm, F_LB: mm * max(min(n, mm), 1),
           F_TARGET: mt, F_RNORM: mt, F_BVAL: mt, F_LNORM: D, F_HIST_DU: D * n, F_MF: mm * n, F_QB: n * n,
           F_BQ: n, F_SV: 2 * n, F_A: mt * n, F_LO: mt, F_UP: mt, F_PRM: N_PRM, F_QV: queue_sizes(n)[0]}
    isz = {I_STATE: mt, I_SIDE: mt, I_KIND: mt, I_BCOL: mt, I_WIDX: n, I_WSIDE: n, I_OLIST: mm,
           I_HIST_STATE: D * mt, I_HIST_SIDE: D * mt, I_HIST_VALID: D, I_OUT: N_OUT + D, I_LEVID: D,
           I_PIV: mm, I_CAND: n, I_COK: n, I_STARTS: D + 1, I_IP: N_IP, I_QI: queue_sizes(n)[1]}
    fsz = [fsz[b] for b in range(len(F_BLOCKS))]
    isz = [isz[b] for b in range(len(I_BLOCKS))]
    foff = np.array((0, *accumulate(-(-size // ALIGN) * ALIGN for size in fsz)), dtype=np.int64)
    fend = foff[:-1] + np.array(fsz, dtype=np.int64)
    return foff, fend, np.array((N_HEAD, *(N_HEAD + c for c in accumulate(isz))), dtype=np.int64)


@lru_cache(maxsize=64)
def _template(ip):
    """For ``ip`` (see :func:`workspaces`): the size of the float workspace,
    the int workspace as it starts (the offsets of :func:`layout` as its
    header, then ``ip`` in its block, zeros elsewhere; read-only), the start
    of the "prm" block and the slices of the blocks :func:`workspaces`
    returns (u, out). Computed once per shape and options (a cold solve on a
    fresh solver allocates its workspaces)."""
    foff, fend, ioff = layout(ip[IP_N], ip[IP_MT], ip[IP_D], ip[IP_MMAX])
    iw0 = np.zeros(ioff[-1], dtype=np.int64)
    iw0[:N_HEAD] = np.concatenate((foff, fend, ioff))
    iw0[ioff[I_IP]:ioff[I_IP + 1]] = ip
    iw0.setflags(write=False)
    fo, fe, io = foff.tolist(), fend.tolist(), ioff.tolist()
    return fo[-1], iw0, fo[F_PRM], slice(fo[F_U], fe[F_U]), slice(io[I_OUT], io[I_OUT + 1])


@njit(cache=True, nogil=True)
def _allocate(size, iw0, prm, at):
    """A zeroed float workspace of ``size`` starting on a 64-byte boundary (a
    cache line, an AVX-512 vector: the rows of W and R then are aligned
    whenever 8 divides n; measured: IK-like warm n=40 35 us aligned, 39 us
    not; numpy and numba only guarantee 16 and 32 bytes), ``prm`` written at
    ``at``, and a copy of ``iw0``. One compiled call: ~2 us less than the
    same in numpy calls, per cold solve on a fresh solver."""
    buf = np.zeros(size + ALIGN)
    start = (-buf.ctypes.data % (8 * ALIGN)) // 8
    fw = buf[start:start + size]
    fw[at:at + prm.size] = prm
    return fw, iw0.copy()


def int_params(n: int, mt: int, D: int, mmax: int, max_iter: int, warm: int, has_ineq: bool) -> tuple:
    """The "ip" block, a tuple with each value in its slot IP_* (._layout):
    n variables, mt rows (the min-norm stage's included), D levels, mmax rows
    of the largest level, the cap on the iterations, the warm start (one of
    WARM_*), whether the problem has inequalities."""
    # (a tuple in the slots' order, checked below: a cold solve on a fresh solver builds it, and
    # filling a list by slot cost 0.25 us more)
    return n, mt, D, mmax, max_iter, warm, 1 if has_ineq else 0


if (IP_N, IP_MT, IP_D, IP_MMAX, IP_MAX_ITER, IP_WARM, IP_HAS_INEQ) != tuple(range(N_IP)):
    raise AssertionError("_setup.int_params: the IP_* slots of ._layout are no longer in its order")


def workspaces(ip, prm):
    """The float and int workspaces of the kernel for ``ip`` (the "ip" block,
    a tuple: :func:`int_params`) and ``prm``
    (the "prm" block), the int one headed by the offsets (see
    :func:`layout`). Returns (fw, iw, u, out): the workspaces and views of
    the blocks the caller reads."""
    size, iw0, at, s_u, s_out = _template(ip)
    fw, iw = _allocate(size, iw0, prm, at)
    return fw, iw, fw[s_u], iw[s_out]


def fblock(fw, iw, name: str):
    """The float block ``name`` (one of F_BLOCKS) of fw, a view (the offsets
    are read from iw's header)."""
    b = F_BLOCKS.index(name)
    return fw[iw[b]:iw[FEND0 + b]]


def iblock(iw, name: str):
    """The int block ``name`` (one of I_BLOCKS) of iw, a view (the offsets
    are read from iw's header)."""
    b = I_BLOCKS.index(name)
    return iw[iw[IOFF0 + b]:iw[IOFF0 + b + 1]]


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def prepare(A, lo, up, starts, kind, bcol, bval, rnorm, lnorm, levid, seen, k0, k1):
    """For levels k0 .. k1-1: row kinds (0 equality, 1 inequality, 2 free),
    bound rows (one nonzero), row norms, the Frobenius norm of each level
    ``||A_k||_F`` (the scale of the rank threshold) and identity-like levels
    (``levid``: n bound rows on distinct variables with equal |coefficient|,
    e.g. a posture task or the min-norm stage, whose projection ``J_k Z``
    has orthogonal columns)."""
    _m, n = A.shape
    for k in range(k0, k1):
        s = 0.0
        for i in range(starts[k], starts[k + 1]):
            ra = A[i]
            # one vectorised pass: the squared norm, the nonzeros and the sum of their column
            # indices (a bound row's column; a search loop for it cost 5 us of 9 at n=80)
            ss = 0.0
            nz = 0
            cs = 0
            for c in range(n):
                v = ra[c]
                ss += v * v
                t = v != 0.0
                nz += t
                cs += c * t
            rnorm[i] = math.sqrt(ss)
            s += ss
            if nz == 1:
                bcol[i] = cs
                bval[i] = ra[cs]
            else:
                bcol[i] = -1
                bval[i] = 0.0
            if lo[i] == up[i]:
                kind[i] = 0
            elif lo[i] == -np.inf and up[i] == np.inf:
                kind[i] = 2
            else:
                kind[i] = 1
        lnorm[k] = math.sqrt(s)
        levid[k] = 0
        if starts[k + 1] - starts[k] == n and n > 0:
            for c in range(n):
                seen[c] = 0
            ok = True
            d0 = abs(bval[starts[k]])
            for i in range(starts[k], starts[k + 1]):
                if bcol[i] < 0 or seen[bcol[i]] != 0 or abs(bval[i]) != d0:
                    ok = False
                    break
                seen[bcol[i]] = 1
            if ok:
                levid[k] = 1
                for i in range(starts[k], starts[k + 1]):
                    if kind[i] != 0:
                        ok = False
                if ok:
                    levid[k] = 2  # identity-like equality level: strictly convex, x unique after it


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def load(fw, iw, A, lo, up, starts, min_norm, fresh):
    """Write a hierarchy (A (m, n), lo, up (m,), starts (D+1,)) into the
    workspaces of :func:`workspaces` as the kernel reads it: each level scaled
    by ``1 / ||A_k||_F`` (computed without overflow; same minimisers, O(1)
    numbers in the reflectors), then the per-row data of :func:`prepare`.
    When ``min_norm``, the level ``I x = 0`` follows; it is the same for
    every problem of the shape, and the kernel writes none of these blocks,
    so it is written and prepared only into ``fresh`` workspaces (a third of
    the rows at n = 80 less to write per problem). The workspaces must have
    been made for (n, m + n min_norm, D + min_norm, ...).

    Returns f, the factor of the bounds: 1, or when every finite scaled bound
    is below BOUND_SCALE_MIN (2^-10) in magnitude (and one is not 0), the power of 2
    that brings the largest into [1, 2). The kernel then solves for ``u = f x``:
    the same minimisers scaled (the problem is homogeneous in (x, bounds)),
    seen by its tolerances at the order of magnitude they are made for."""
    foff = iw[:FEND0]
    fend = iw[FEND0:IOFF0]
    ioff = iw[IOFF0:N_HEAD]
    m, n = A.shape
    D = starts.shape[0] - 1
    mt = m + (n if min_norm else 0)
    A2 = fw[foff[F_A]:foff[F_A] + mt * n].reshape((mt, n))
    lo2 = fw[foff[F_LO]:fend[F_LO]]
    up2 = fw[foff[F_UP]:fend[F_UP]]
    st2 = iw[ioff[I_STARTS]:ioff[I_STARTS + 1]]
    for k in range(D + 1):
        st2[k] = starts[k]
    bmax = 0.0  # the largest finite scaled bound
    for k in range(D):
        sc = level_scale(A, starts[k], starts[k + 1], n)
        for i in range(starts[k], starts[k + 1]):
            a2 = A2[i]
            a = A[i]
            for c in range(n):
                a2[c] = a[c] * sc
            lo2[i] = lo[i] * sc
            up2[i] = up[i] * sc
            if lo2[i] > -np.inf:
                bmax = max(bmax, abs(lo2[i]))
            if up2[i] < np.inf:
                bmax = max(bmax, abs(up2[i]))
    f = 1.0
    if 0.0 < bmax < BOUND_SCALE_MIN:
        # the kernel's tolerances have absolute parts (1 + ||u||, + 1) that assume bounds not far
        # below 1: a problem wholly smaller is solved as u = f x, f a power of 2 (exact)
        f = math.ldexp(1.0, min(1 - math.frexp(bmax)[1], 1021))
        for i in range(m):
            lo2[i] *= f
            up2[i] *= f
    k1 = D
    if min_norm and fresh:
        st2[D + 1] = mt
        for i in range(m, mt):
            A2[i, :] = 0.0
            A2[i, i - m] = 1.0
            lo2[i] = 0.0
            up2[i] = 0.0
        k1 = D + 1
    prepare(A2, lo2, up2, st2, iw[ioff[I_KIND]:ioff[I_KIND + 1]], iw[ioff[I_BCOL]:ioff[I_BCOL + 1]],
            fw[foff[F_BVAL]:fend[F_BVAL]], fw[foff[F_RNORM]:fend[F_RNORM]],
            fw[foff[F_LNORM]:fend[F_LNORM]],
            iw[ioff[I_LEVID]:ioff[I_LEVID + 1]], iw[ioff[I_WIDX]:ioff[I_WIDX + 1]], 0, k1)
    return f
