"""The inequality kernel's view of its two workspaces (:mod:`._layout`):
one accessor per kind of block and the groups of blocks the phases take.

Float block ``b`` is ``fw[iw[b]:iw[FEND0 + b]]``, int block ``b`` is
``iw[iw[IOFF0 + b]:iw[IOFF0 + b + 1]]`` (the header of iw, written by
:func:`._setup.layout`); ``b`` is one of the ``F_*`` / ``I_*`` constants,
frozen into the compiled code. Every function here is inlined into its
caller: a block costs the two loads of its offsets.
"""

from __future__ import annotations

from numba import njit

from hikbench.solvers.hcod import _cache  # noqa: F401  (before any @njit: cache stamps over every hcod file)
from hikbench.solvers.hcod._layout import (
    F_A,
    F_BETA,
    F_BVAL,
    F_BVEC,
    F_DIAG,
    F_G,
    F_HIST_DU,
    F_HV,
    F_LB,
    F_LO,
    F_MF,
    F_MR,
    F_NU,
    F_PRM,
    F_PS,
    F_Q,
    F_QV,
    F_RNORM,
    F_SV,
    F_TARGET,
    F_U,
    F_UP,
    F_W,
    F_Y,
    F_Z,
    FEND0,
    I_BCOL,
    I_HIST_SIDE,
    I_HIST_STATE,
    I_HIST_VALID,
    I_KIND,
    I_OLIST,
    I_PIV,
    I_QI,
    I_SIDE,
    I_STATE,
    I_WIDX,
    I_WSIDE,
    IOFF0,
    PRM_DUAL_RTOL,
    PRM_FEAS_RTOL,
    PRM_FREEZE_RTOL,
    PRM_RANK_RTOL,
)
from hikbench.solvers.hcod._linalg import FASTMATH, matrix_view

_FM = set(FASTMATH)


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def fblock(fw, iw, b):
    """Float block b (an ``F_*`` constant) of fw, a 1-D view."""
    return fw[iw[b]:iw[FEND0 + b]]


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def iblock(iw, b):
    """Int block b (an ``I_*`` constant) of iw, a 1-D view."""
    return iw[iw[IOFF0 + b]:iw[IOFF0 + b + 1]]


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def tolerances(fw, iw):
    """The "prm" block's tolerances: (rank_rtol, feas_rtol, dual_rtol, freeze_rtol)."""
    prm = fblock(fw, iw, F_PRM)
    return prm[PRM_RANK_RTOL], prm[PRM_FEAS_RTOL], prm[PRM_DUAL_RTOL], prm[PRM_FREEZE_RTOL]


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def problem_blocks(fw, iw, mt, n):
    """The scaled problem (._setup.load): (A (mt, n), lo, up, bcol, bval, kind,
    rnorm), the last five per row (mt,)."""
    return (matrix_view(fblock(fw, iw, F_A), mt, n), fblock(fw, iw, F_LO), fblock(fw, iw, F_UP),
            iblock(iw, I_BCOL), fblock(fw, iw, F_BVAL), iblock(iw, I_KIND), fblock(fw, iw, F_RNORM))


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def basis_blocks(fw, iw, n):
    """The basis W (._basis): (Wt (n, n): W or W0 by columns, qv, qi: the queue
    of the factored form, sv, sv2: two scratch vectors (n,))."""
    sv = fblock(fw, iw, F_SV)
    return (matrix_view(fblock(fw, iw, F_W), n, n), fblock(fw, iw, F_QV), iblock(iw, I_QI), sv[:n],
            sv[n:])


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def active_set_blocks(fw, iw):
    """The active set: (state, side, target (mt,) per row; Olist: the level's
    objective rows; widx, wside (n,): the working rows and their sides)."""
    return (iblock(iw, I_STATE), iblock(iw, I_SIDE), fblock(fw, iw, F_TARGET), iblock(iw, I_OLIST),
            iblock(iw, I_WIDX), iblock(iw, I_WSIDE))


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def record_blocks(fw, iw, D, mt, n):
    """The warm-start record of the last call (sec. XI): (hist_state,
    hist_side (D, mt), hist_valid (D,), hist_du (D, n))."""
    return (matrix_view(iblock(iw, I_HIST_STATE), D, mt), matrix_view(iblock(iw, I_HIST_SIDE), D, mt),
            iblock(iw, I_HIST_VALID), matrix_view(fblock(fw, iw, F_HIST_DU), D, n))


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def vector_blocks(fw, iw):
    """The vectors (n,): (u, ps, z, g, hv, nu, q), named in ._layout."""
    return (fblock(fw, iw, F_U), fblock(fw, iw, F_PS), fblock(fw, iw, F_Z), fblock(fw, iw, F_G),
            fblock(fw, iw, F_HV), fblock(fw, iw, F_NU), fblock(fw, iw, F_Q))


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def lse_blocks(fw, iw, mmax, n):
    """The level's COD (19) and LSE (28): (Mr, Mf (mmax, n), piv, diag, beta,
    bvec (mmax,), Lb, y (n,)); mmax >= 1."""
    return (matrix_view(fblock(fw, iw, F_MR), mmax, n), matrix_view(fblock(fw, iw, F_MF), mmax, n),
            iblock(iw, I_PIV), fblock(fw, iw, F_DIAG), fblock(fw, iw, F_BETA), fblock(fw, iw, F_BVEC),
            matrix_view(fblock(fw, iw, F_LB), max(min(n, mmax), 1), mmax), fblock(fw, iw, F_Y))
