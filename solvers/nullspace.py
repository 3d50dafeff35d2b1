"""The classical null-space recursions of sec. IV of Escande, Mansard, Wieber (ICRA 2010).

Equality hierarchies only (``A_k x = b_k``, in the paper's names ``J_k u = e_k``);
given an inequality row they return status ``unsupported``. With ``u_0 = 0``,
``P_0 = I`` (n, n), for each level k (J_k shape (r_k, n)):

    u_k = u_{k-1} + (J_k P_{k-1})^+ (e_k - J_k u_{k-1})                        (2)

* ``nullspace-svd``: the pseudo-inverse from the SVD
  ``J_k P_{k-1} = U_k S_k Y_k^T`` (10)-(11), ``(J_k P_{k-1})^+ = Y_k S_k^-1 U_k^T``,
  and the projector updated incrementally by (14),
  ``P_k = P_{k-1} - (J_k P_{k-1})^+ J_k P_{k-1}`` — computed literally as the
  product of the pseudo-inverse with the projected matrix. Kept faithful: the
  round-off of that product grows with the conditioning of ``J_k P_{k-1}``
  (about eps * cond), and the projector drifts away from a projector over the
  levels; that drift is part of what the benchmark measures.
* ``nullspace-cod``: the complete orthogonal decomposition (12)-(13)
  ``J_k P_{k-1} = V_k L_k Y_k^T`` (Y_k orthonormal (n, rank), L_k triangular
  (rank, rank), V_k orthonormal (r_k, rank)), from a column-pivoted QR of
  ``(J_k P_{k-1})^T`` then a QR of the (r_k, rank) trapezoidal factor when the
  level is rank-deficient; ``(J_k P_{k-1})^+ = Y_k L_k^-1 V_k^T`` and the
  update (15) ``P_k = P_{k-1} - Y_k Y_k^T``. (Our L_k is upper triangular:
  the transpose convention of the paper's lower L_k; the cost is the same.)
* ``pinv-all``: every level stacked, ``u = Jbar^+ ebar`` by SVD — no
  hierarchy (not strict).

Rank decision: singular values (SVD) or |diagonal of the pivoted R| (COD)
above ``rank_rtol * ||J_k||_2`` (the unprojected level, default 1e-10), so a
level fully decided by the levels above has rank 0 instead of a rank made of
round-off.

Flop estimates (``SolveResult.flops``) follow the cost model of sec. VI: the
products of the recursion counted in multiply-adds as the paper does (its
"approximately 2nm^2 per task" = ``n^2 r`` for ``J_k P_{k-1}`` plus
``n^2 r`` for the projector update; ``r^2/2`` for applying ``L^-1``), the
decompositions with the standard counts of Golub & Van Loan (Matrix
Computations, 3rd ed., sec. 5.4.5 / 8.6.3): R-SVD of a (p, q) matrix, p >= q,
for S, thin U and V: ``6 p q^2 + 20 q^3``; for S, full U and V:
``4 p^2 q + 22 q^3``; Householder QR of (p, q) with thin Q: ``4 q^2 (p - q/3)``
(without forming Q: ``2 q^2 (p - q/3)``). For n = 36 and 6 levels of 6 rows
these give 168.7 Kflops (SVD recursion; paper 168), 125.6 Kflops (COD
recursion; paper 124), 1216 Kflops (SVD all at once; paper 1213) and 64.2
Kflops (COD all at once; paper 69.5).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.linalg

from hikbench.problems.hierarchy import Hierarchy
from hikbench.solvers.base import NUMERICAL_FAILURE, OPTIMAL, Solver, SolveResult
from hikbench.solvers.info import SolverInfo
from hikbench.solvers.options import check_number

__all__ = ["RANK_RTOL", "NullspaceCOD", "NullspaceSVD", "PinvAll", "flops_cod_all_at_once",
           "flops_cod_recursion", "flops_svd_all_at_once", "flops_svd_recursion"]

RANK_RTOL = 1e-10  #: default rank threshold, relative to ||J_k||_2


# ---------------------------------------------------------------- flop counts

def _rsvd_thin(p: int, q: int) -> float:
    """R-SVD of a (p, q) matrix for S, thin U, V (G&VL): ``6 p q^2 + 20 q^3`` (p >= q)."""
    p, q = max(p, q), min(p, q)
    return 6.0 * p * q * q + 20.0 * q ** 3


def _rsvd_full(p: int, q: int) -> float:
    """R-SVD of a (p, q) matrix for S, full U and V (G&VL): ``4 p^2 q + 22 q^3`` (p >= q)."""
    p, q = max(p, q), min(p, q)
    return 4.0 * p * p * q + 22.0 * q ** 3


def _qr(p: int, q: int, form_q: bool) -> float:
    """Householder QR of (p, q), p >= q: ``2 q^2 (p - q/3)``, doubled when the thin Q is formed."""
    p, q = max(p, q), min(p, q)
    return (4.0 if form_q else 2.0) * q * q * (p - q / 3.0)


def flops_svd_recursion(n: int, rows_per_level: Sequence[int]) -> int:
    """Flops of the SVD recursion (2) + (14) on n variables, levels of the given rows.

    Per level of r rows: ``n^2 r`` (J_k P_{k-1}) + R-SVD thin ``6 n r^2 + 20 r^3``
    + ``n^2 r`` (update (14)) + ``2 n r + r^2 + r`` (residual, U^T, S^-1, Y)."""
    total = 0.0
    for r in rows_per_level:
        r = min(int(r), n)
        if r == 0:
            continue
        total += n * n * r + _rsvd_thin(n, r) + n * n * r + 2 * n * r + r * r + r
    return round(total)


def flops_cod_recursion(n: int, rows_per_level: Sequence[int]) -> int:
    """Flops of the COD recursion (2) + (12)-(13) + (15).

    Per level of r rows: ``n^2 r`` (J_k P_{k-1}) + QR with thin Q ``4 r^2 (n - r/3)``
    + ``n^2 r`` (update (15)) + ``2 n r + r^2 + r^2 / 2`` (residual, V^T, L^-1, Y)."""
    total = 0.0
    for r in rows_per_level:
        r = min(int(r), n)
        if r == 0:
            continue
        total += n * n * r + _qr(n, r, True) + n * n * r + 2 * n * r + r * r + r * r / 2
    return round(total)


def flops_svd_all_at_once(n: int, rows: int) -> int:
    """Flops of ``u = Jbar^+ ebar`` by SVD of the stacked (rows, n) matrix:
    R-SVD with full U and V ``4 p^2 q + 22 q^3`` + ``2 rows n + q^2`` (apply U^T, S^-1, V)."""
    q = min(rows, n)
    return round(_rsvd_full(rows, n) + rows * q + q + n * q)


def flops_cod_all_at_once(n: int, rows: int) -> int:
    """Flops of the stacked solve by COD of the (rows, n) matrix (full rank:
    the COD is a QR): Householder QR, Q kept factored, ``2 q^2 (p - q/3)``,
    + applying Q^T to ebar ``p q`` + the triangular solve ``q^2 / 2``
    (multiply-adds), p = max(rows, n), q = min(rows, n). 64.2 Kflops for
    36 x 36 where the paper prints 69.5: the paper's count is not given."""
    p, q = max(rows, n), min(rows, n)
    return round(_qr(p, q, False) + p * q + q * q / 2)


# ---------------------------------------------------------------- solvers

class _EqualityOnly(Solver):
    supports_inequalities = False
    supports_warm_start = False

    def __init__(self, rank_rtol: float = RANK_RTOL):
        self.rank_rtol = check_number(self.name, "rank_rtol", rank_rtol, low=0, high=1, high_open=True)

    def _check(self, h: Hierarchy) -> SolveResult | None:
        self.check_hierarchy(h)
        if h.has_inequalities:
            ineq = np.flatnonzero(~h.is_equality)
            k = int(h.level[ineq[0]])
            at_k = ineq[h.level[ineq] == k]
            free = int(h.is_free[at_k].sum())
            what = ", ".join(f"{c} {kind} row(s)" for c, kind in ((at_k.size - free, "inequality"), (free, "free"))
                             if c)
            return self.unsupported(h, f"equality hierarchies only; level {k} has {what}")
        return None

    def _result(self, h: Hierarchy, x, ranks, flops) -> SolveResult:
        info = {"ranks": tuple(int(r) for r in ranks)}
        if not np.all(np.isfinite(x)):
            return SolveResult(x=x, status=NUMERICAL_FAILURE, reason=f"{self.name}: NaN/inf in the solution",
                               flops=flops, info=info)
        return SolveResult(x=x, status=OPTIMAL, flops=flops, info=info)


class _Recursion(_EqualityOnly):
    def _step(self, M: np.ndarray, thr: float):
        """Returns (pinv_apply(v), update_term, rank) for M = J_k P_{k-1}."""
        raise NotImplementedError

    def solve(self, hierarchy: Hierarchy) -> SolveResult:
        h = hierarchy
        bad = self._check(h)
        if bad is not None:
            return bad
        n = h.n
        u = np.zeros(n)
        P = np.eye(n)
        ranks = []
        with np.errstate(all="ignore"):
            for k in range(h.depth):
                s = h.level_rows(k)
                J, e = h.A[s], h.lower[s]
                if J.shape[0] == 0:
                    ranks.append(0)
                    continue
                thr = self.rank_rtol * np.linalg.norm(J, 2)
                M = J @ P  # (r_k, n)
                try:
                    apply_pinv, P_minus, rank = self._step(M, thr)
                except (np.linalg.LinAlgError, ValueError) as err:
                    return SolveResult(x=u, status=NUMERICAL_FAILURE,
                                       reason=f"{self.name}: level {k}: decomposition failed: {err}")
                ranks.append(rank)
                if rank:
                    u = u + apply_pinv(e - J @ u)  # eq. (2)
                    P = P - P_minus
        return self._result(h, u, ranks, self._flops(n, [h.level_rows(k).stop - h.level_rows(k).start
                                                          for k in range(h.depth)]))


class NullspaceSVD(_Recursion):
    """Eq. (2) with the SVD pseudo-inverse (10)-(11) and the projector update (14)."""

    name = "nullspace-svd"
    description = "classical recursion eq. (2): SVD pseudo-inverse, incremental projector update (14)"

    def _step(self, M, thr):
        U, S, Yt = np.linalg.svd(M, full_matrices=False)
        rank = int(np.sum(S > thr))
        Ur, Sr, Yr = U[:, :rank], S[:rank], Yt[:rank].T
        pinv = (Yr / Sr) @ Ur.T  # (n, r_k): Y_k S_k^-1 U_k^T, eq. (11)
        return (lambda v: pinv @ v), pinv @ M, rank  # (J P)^+ (J P), eq. (14)

    @staticmethod
    def _flops(n, rows):
        return flops_svd_recursion(n, rows)


class NullspaceCOD(_Recursion):
    """Eq. (2) with the COD pseudo-inverse (12)-(13) and the projector update (15)."""

    name = "nullspace-cod"
    description = "classical recursion eq. (2): complete orthogonal decomposition (12)-(13), update (15)"

    def _step(self, M, thr):
        # (J P)^T Pi = Q R  ->  J P = Pi R^T Q^T
        Q, R, piv = scipy.linalg.qr(M.T, mode="economic", pivoting=True)
        d = np.abs(np.diag(R))
        rank = int(np.sum(d > thr))
        if rank == 0:
            return (lambda v: np.zeros(M.shape[1])), None, 0
        Y = Q[:, :rank]  # (n, rank), orthonormal
        T = R[:rank, :].T  # (r_k, rank), lower trapezoidal
        Pi = np.eye(M.shape[0])[:, piv]  # J P = Pi T Y^T
        if rank < M.shape[0]:
            Vb, L = np.linalg.qr(T)  # T = Vb L, L (rank, rank) upper triangular
        else:
            Vb, L = np.eye(rank), T  # already square lower triangular
        V = Pi @ Vb  # (r_k, rank): J P = V L Y^T, eq. (12)
        lower = rank == M.shape[0]

        def apply_pinv(v):  # Y L^-1 V^T v, eq. (13)
            return Y @ scipy.linalg.solve_triangular(L, V.T @ v, lower=lower)

        return apply_pinv, Y @ Y.T, rank  # eq. (15)

    @staticmethod
    def _flops(n, rows):
        return flops_cod_recursion(n, rows)


class PinvAll(_EqualityOnly):
    """All levels stacked, ``u = Jbar^+ ebar`` (no hierarchy)."""

    name = "pinv-all"
    strict = False
    description = "all levels stacked and solved at once by SVD pseudo-inverse (no hierarchy)"

    def solve(self, hierarchy: Hierarchy) -> SolveResult:
        h = hierarchy
        bad = self._check(h)
        if bad is not None:
            return bad
        if h.rows == 0:
            return self._result(h, np.zeros(h.n), [0], 0)
        U, S, Vt = np.linalg.svd(h.A, full_matrices=False)
        rank = int(np.sum(S > self.rank_rtol * (S[0] if S.size else 0.0)))
        x = Vt[:rank].T @ ((U[:, :rank].T @ h.lower) / S[:rank])
        return self._result(h, x, [rank], flops_svd_all_at_once(h.n, h.rows))


SOLVERS = [SolverInfo.of(cls) for cls in (NullspaceSVD, NullspaceCOD, PinvAll)]
