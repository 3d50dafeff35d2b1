"""Set-up of the inequality kernel: the scaled problem, the workspace layout
and the per-row / per-level data computed once per hierarchy."""

from __future__ import annotations

import math
from itertools import accumulate

import numpy as np
from numba import njit

from solvers.hcod._factored import queue_sizes
from solvers.hcod._linalg import level_scale

N_OUT = 9  #: counters at the head of the "out" block; the iterations per level follow them
N_IP = 7  #: integer parameters (n, mt, D, mmax, max_iter, warm_mode, has_ineq)
N_PRM = 4  #: float parameters (rank_rtol, feas_rtol, dual_rtol, freeze_rtol)
ALIGN = 8  #: float blocks start on multiples of 8 doubles (64 bytes)
# float workspace blocks (names, size in units of: n*n, n, mmax*n, mmax, mmax*min(n,mmax), mt, D, D*n);
# then the (scaled) problem and the parameters, so the kernel takes two arrays, and the queue of
# the basis when factored (._factored)
F_BLOCKS = ("W", "R", "u", "ps", "z", "g", "hv", "nu", "q", "uprev", "y", "Mr", "bvec", "diag", "beta",
            "Lb", "target", "rnorm", "bval", "lnorm", "hist_du", "Mf", "Qb", "bq", "sv", "A", "lo", "up",
            "prm", "Qv")
# int blocks; "out" holds the N_OUT counters, then the iterations per level
I_BLOCKS = ("state", "side", "kind", "bcol", "rowlev", "widx", "wside", "Olist", "hist_state",
            "hist_side", "hist_valid", "out", "levid", "piv", "cand", "cok", "starts", "ip", "qi")
#: the int workspace starts with the offsets themselves: foff (starts of the float blocks and
#: the total, iw[:FEND0]), fend (ends of the float blocks, iw[FEND0:IOFF0]), ioff (iw[IOFF0:N_HEAD])
FEND0 = len(F_BLOCKS) + 1
IOFF0 = FEND0 + len(F_BLOCKS)
N_HEAD = IOFF0 + len(I_BLOCKS) + 1


def layout(n: int, mt: int, D: int, mmax: int):
    """Offsets of the float and int workspaces (blocks in the order of
    F_BLOCKS / I_BLOCKS). Returns (foff, fend, ioff), int64 arrays: float
    block b is ``fw[foff[b]:fend[b]]``, its start a multiple of ALIGN;
    int block b is ``iw[ioff[b]:ioff[b + 1]]``, after the header of N_HEAD
    entries that stores all three."""
    mm = max(mmax, 1)
    fsz = (n * n, n * n, n, n, n, n, n, n, n, n, n, mm * n, mm, mm, mm, mm * max(min(n, mm), 1), mt, mt, mt, D,
           D * n, mm * n, n * n, n, 2 * n, mt * n, mt, mt, N_PRM, queue_sizes(n)[0])
    isz = (mt, mt, mt, mt, mt, n, n, mm, D * mt, D * mt, D, N_OUT + D, D, mm, n, n, D + 1, N_IP, queue_sizes(n)[1])
    foff = np.array((0, *accumulate(-(-size // ALIGN) * ALIGN for size in fsz)), dtype=np.int64)
    fend = foff[:-1] + np.array(fsz, dtype=np.int64)
    return foff, fend, np.array((N_HEAD, *(N_HEAD + c for c in accumulate(isz))), dtype=np.int64)


def workspaces(n: int, mt: int, D: int, mmax: int):
    """The float and int workspaces of the kernel, the int one headed by the
    offsets (see :func:`layout`). Returns (fw, iw, foff, fend, ioff)."""
    foff, fend, ioff = layout(n, mt, D, mmax)
    # the float workspace starts on a 64-byte boundary (a cache line, an AVX-512 vector): the
    # rows of W and R then are aligned whenever 8 divides n (measured: IK-like warm n=40
    # 35 us aligned, 39 us not; numpy only guarantees 16 bytes)
    size = int(foff[-1])
    buf = np.zeros(size + ALIGN)
    start = (-buf.ctypes.data % (8 * ALIGN)) // 8
    fw = buf[start:start + size]
    iw = np.zeros(int(ioff[-1]), dtype=np.int64)
    iw[:FEND0] = foff
    iw[FEND0:IOFF0] = fend
    iw[IOFF0:N_HEAD] = ioff
    return fw, iw, foff, fend, ioff


def fblock(fw, foff, fend, name: str):
    """The float block ``name`` (one of F_BLOCKS) of fw, a view."""
    b = F_BLOCKS.index(name)
    return fw[foff[b]:fend[b]]


def iblock(iw, ioff, name: str):
    """The int block ``name`` (one of I_BLOCKS) of iw, a view."""
    b = I_BLOCKS.index(name)
    return iw[ioff[b]:ioff[b + 1]]


@njit(cache=True, nogil=True, error_model="numpy")
def prepare(A, lo, up, starts, kind, bcol, bval, rnorm, rowlev, lnorm, levid, seen):
    """Row kinds (0 equality, 1 inequality, 2 free), bound rows (one nonzero),
    row norms, the Frobenius norm of each level ``||A_k||_F`` (the scale of
    the rank threshold) and identity-like levels (``levid``: n bound rows on
    distinct variables with equal |coefficient|, e.g. a posture task or the
    min-norm stage, whose projection ``J_k Z`` has orthogonal columns)."""
    _m, n = A.shape
    D = starts.shape[0] - 1
    for k in range(D):
        s = 0.0
        for i in range(starts[k], starts[k + 1]):
            rowlev[i] = k
            nz = 0
            col = -1
            ss = 0.0
            for c in range(n):
                a = A[i, c]
                if a != 0.0:
                    nz += 1
                    col = c
                    ss += a * a
            rnorm[i] = math.sqrt(ss)
            s += ss
            if nz == 1:
                bcol[i] = col
                bval[i] = A[i, col]
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


@njit(cache=True, nogil=True, error_model="numpy")
def scaled_problem(A, lo, up, starts, min_norm):
    """The arrays the kernel solves: each level scaled by ``1 / ||A_k||_F``
    (computed without overflow; same minimisers, O(1) numbers in the
    reflectors) and, when ``min_norm``, the level ``I x = 0`` appended.
    Returns (A (m', n), lo, up, starts (D'+1,))."""
    m, n = A.shape
    D = starts.shape[0] - 1
    extra = n if min_norm else 0
    A2 = np.zeros((m + extra, n))
    lo2 = np.zeros(m + extra)
    up2 = np.zeros(m + extra)
    st2 = np.empty(D + 1 + (1 if min_norm else 0), np.int64)
    for k in range(D + 1):
        st2[k] = starts[k]
    if min_norm:
        st2[D + 1] = m + n
        for c in range(n):
            A2[m + c, c] = 1.0
    for k in range(D):
        sc = level_scale(A, starts[k], starts[k + 1], n)
        for i in range(starts[k], starts[k + 1]):
            for c in range(n):
                A2[i, c] = A[i, c] * sc
            lo2[i] = lo[i] * sc
            up2[i] = up[i] * sc
    return A2, lo2, up2, st2
