"""The basis ``W`` of the inequality kernel and the updates of the constraint
decomposition (ICRA 2010, sec. VI and IX), in one of two representations
chosen by the kernel at the start of each solve:

- *explicit* (:mod:`._explicit`: cold solves, and every solve of fewer than
  ``LAZY_MIN_N`` variables): every orthogonal factor is applied to ``W`` at
  once (``2 n L`` multiply-adds per reflector of length L); the products read
  only the columns they need (``Z`` for the projections of eq. 19, held in
  ``Mf[:, p:]``). ``W`` starts as the identity, flagged a permutation of
  its columns (``qi[Q_ID]``, as the factored form flags its ``W0 = I``), and
  bound rows (a box) entering it keep it one (swaps, no multiply-add:
  :func:`._explicit.insert_row`): the products are gathers and scatters
  (of the first level with objective rows, when nothing above is active,
  the projections of eq. 19 are copies), and a level's reflectors are
  pushed on order ``n - p`` instead of n, until the first general update;
- *factored* (:mod:`._factored`: warm re-solves from a recorded active set,
  sec. XI, from ``LAZY_MIN_N`` variables on, until a level iterates more than
  ``LAZY_MAX_ITER`` times: then the queue is flushed and ``W`` stays explicit
  to the end of the solve): ``W = W0 E_1 ... E_m`` with the
  factors queued and applied to the vectors that need them (``2 L`` per
  reflector and vector), flushed into ``W0`` when that is cheaper; the
  projected objective rows are whole rows ``Mf[j] = W^T a_j``.

The functions below take the representation (``lazy``) first and forward to
the one chosen; they are inlined into the kernel, so the choice is one
predictable branch per call. ``R`` (n, n) holds, column j, the coordinates of
working row j in ``W``: ``C^T = W[:, :p] R[:p, :p]``, ``R[:p, :p]`` upper
triangular. Every function returns its multiply-adds.

Workspaces: ``Wt`` (n, n) W (or W0) stored by columns; ``qv``, ``qi`` the
queue (:func:`._factored.queue_sizes`; in the explicit representation ``qv``
is scratch and ``qi`` holds the permutation flag ``qi[Q_ID]``, cleared by
each general update of ``W`` in :mod:`._explicit`, and the permutation); sv,
sv2 (n,) scratch.
"""

from __future__ import annotations

from numba import njit

from hikbench.solvers.hcod import (
    _cache,  # noqa: F401  (before any @njit: cache stamps over every hcod file)
    _explicit,
    _factored,
)
from hikbench.solvers.hcod._factored import Q_ID
from hikbench.solvers.hcod._linalg import FASTMATH

__all__ = [
    "LAZY_MAX_ITER",
    "LAZY_MIN_N",
    "basis_explicit",
    "basis_head",
    "basis_n",
    "basis_permuted",
    "basis_reset",
    "basis_rows",
    "basis_t",
    "delete_row",
    "insert_row",
    "insert_rows",
    "multipliers",
    "push_reflectors",
]

#: variables from which a warm re-solve keeps W factored. Below, the products of an explicit W
#: are cheap (short vectors) and the queue's per-entry overheads dominate: IK-like warm n=20
#: ~11 us explicit, ~13 us factored; n=80 ~95 us explicit, ~60 us factored (in-process, this
#: VM). A cold solve iterates more: a long queue, or a dense W0 after a flush, costs more per
#: product than Z's columns of an explicit W (cold n=80 seed 2: ~1.3 ms factored, ~0.75 explicit)
LAZY_MIN_N = 48
#: iterations of one level after which a factored W goes explicit for the rest of the solve: a
#: warm re-solve iterates once per level, a step of a drifting trajectory like a cold solve
#: (40-step trajectories, drift 0.01, in-process: random n=60 12.3 -> 8.3 ms, IK-like n=48
#: 4.2 -> 3.4 ms, n=64 5.2 -> 4.5 ms; IK-like n=120 8.4 -> 9.1 ms; 2 and 5 measured alike)
LAZY_MAX_ITER = 3
_FM = set(FASTMATH)


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def basis_reset(lazy, Wt, qi):
    """``W = I`` (a solve's start): a flag when factored; explicit, the
    identity written and flagged a permutation (the flag is cleared by the
    first general update)."""
    if lazy:
        _factored.basis_reset(qi)
    else:
        _explicit.reset(Wt, qi)


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def basis_permuted(lazy, qi):
    """``W`` explicit and a permutation of the identity's columns (the
    identity included): bound rows then enter by swaps of its columns, with
    no multiply-add (:func:`._explicit.insert_row`)."""
    return not lazy and qi[Q_ID] != 0


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM)
def basis_explicit(Wt, qv, qi, sv, sv2):
    """The factored ``W`` made explicit (the queue flushed into ``W0``, which
    then is ``W``: the storage of both representations is the same).
    Returns flops."""
    return _factored.flush(Wt, qv, qi, sv, sv2)


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def basis_t(lazy, Wt, qv, qi, x, c0, c1, sv, sv2):
    """``x[c0:c1] <- (W^T x)[c0:c1]`` (x (n,); its other entries are left
    undefined)."""
    if lazy:
        return _factored.basis_t(Wt, qv, qi, x, c0, c1, sv, sv2)
    return _explicit.basis_t(Wt, qi, x, c0, c1, sv)


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def basis_n(lazy, Wt, qv, qi, x, c0, c1, sv, sv2):
    """``x <- W x`` for x (n,) zero outside ``c0:c1`` (e.g. ``Z z``, eq. 31)."""
    if lazy:
        return _factored.basis_n(Wt, qv, qi, x, c0, c1, sv, sv2)
    return _explicit.basis_n(Wt, qi, x, c0, c1, sv)


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def basis_head(lazy, A, i, bcol, bval, Wt, qi, p, out):
    """``out[:p] = W[:, :p]^T a`` for the row ``a = A[i]`` when explicit (the
    coordinates of a frozen row on the working rows' columns: a column of
    ``R``); when factored, out holds the whole projection ``W^T a`` already
    (``Mf``) and is left as it is. Returns flops."""
    if lazy:
        return 0
    return _explicit.head(A, i, bcol, bval, Wt, qi, p, out)


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def basis_rows(lazy, A, rows, j0, j1, bcol, bval, Wt, qv, qi, M, p, sv, sv2):
    """The rows ``A[rows[j]]``, j0 <= j < j1, projected (eq. 19): whole rows
    ``M[j] = W^T a`` when factored, ``M[j, p:] = Z^T a`` when explicit."""
    if lazy:
        return _factored.basis_rows(A, rows, j0, j1, bcol, bval, Wt, qv, qi, M, sv, sv2)
    return _explicit.project_into(A, rows, j0, j1, bcol, bval, Wt, qi, p, M)


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def push_reflectors(lazy, Wt, qv, qi, p, Mr, beta, r, qbf, sv, sv2):
    """``W[:, p:] <- W[:, p:] H_0 ... H_{r-1}`` (eq. 23), reflector t =
    ``I - beta[t] v v^T`` with ``v = Mr[t, t:n-p]`` on the columns ``p + t:``.
    qbf (>= (n - p)^2) flat scratch."""
    if not lazy:
        return _explicit.push_reflectors(Wt, qi, p, Mr, beta, r, qbf, sv, sv2)
    nf = Wt.shape[0] - p
    fl = 0
    for t in range(r):
        fl += _factored.push_reflector(Wt, qv, qi, p + t, Mr[t, t:nf], beta[t], sv, sv2)
    return fl


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def insert_row(lazy, A, i, bcol, bval, R, p, thr, q, Wt, qv, qi, sv, sv2):
    """Row ``A[i]`` enters the working set (one Householder update, sec. IX),
    or is refused as dependent (``||Z^T a|| <= thr``). Returns (ok, flops,
    beta); the reflector stays in ``q[p:]``."""
    if lazy:
        return _factored.insert_row(A, i, bcol, bval, R, p, thr, q, Wt, qv, qi, sv, sv2)
    return _explicit.insert_row(A, i, bcol, bval, Wt, qi, R, p, thr, q, sv)


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def insert_rows(lazy, A, cand, m, bcol, bval, R, p, rank_rtol, rnorm, Qb, bq, cok, Wt, qv, qi, sv, sv2):
    """The rows ``A[cand[:m]]`` enter in order, blocked (``cok[j]`` = 1 when
    row j entered). Qb (>= m, n), bq (>= m) scratch. Returns (t, flops)."""
    if lazy:
        return _factored.insert_rows(A, cand, m, bcol, bval, R, p, rank_rtol, rnorm, Qb, bq, cok,
                                     Wt, qv, qi, sv, sv2)
    return _explicit.insert_rows(A, cand, m, bcol, bval, Wt, qi, R, p, rank_rtol, rnorm, Qb, bq, cok, sv,
                                 sv2)


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def delete_row(lazy, j, R, p, widx, wside, M, nM, Wt, qv, qi, sv, sv2):
    """Working row j leaves (Givens rotations, sec. IX); when factored, the
    rotations are applied to the whole projected rows ``M[:nM]`` too.
    Returns flops; the caller decrements p."""
    if lazy:
        return _factored.delete_row(j, R, p, widx, wside, M, nM, Wt, qv, qi, sv, sv2)
    return _explicit.delete_row(j, Wt, qi, R, p, widx, wside, qv)


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FM, inline="always")
def multipliers(lazy, R, p, g, nu, h, Wt, qv, qi, sv, sv2):
    """Multipliers of the working rows (eq. 39), ``R nu = -W[:, :p]^T g``; g
    (n,) may be overwritten, h (n,) scratch."""
    if lazy:
        return _factored.multipliers(R, p, g, nu, Wt, qv, qi, sv, sv2)
    return _explicit.multipliers(Wt, qi, R, p, g, h, nu)
