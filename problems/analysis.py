"""Structure of a hierarchy: row kinds, rank and conditioning of each level,
alone and projected in the null space of the levels above.

For level k with constraint rows ``A_k`` (free rows left out: they never
constrain x) this computes the singular values of

* ``A_k`` itself: its rank ``r_k`` and condition number;
* ``A_k Z_{k-1}``, its projection in the null space of every constraint row of
  the levels above (ICRA 2010 eq. (2) with ``Z_{-1} = I``, ``Z_k`` an
  orthonormal basis of the null space of ``[A_0; ...; A_k]``, shape
  (n, n - rank of the stack)): the rank ``p_k`` it still has there and the
  conditioning it has there.

``r_k - p_k`` is the rank level k shares with the levels above (its
*conflicts*). Every row of a higher level counts as if it were active, so for
inequality levels ``p_k`` is a lower bound of the rank left at the optimum.
A singular value counts in a rank when it exceeds ``rtol * ||A_k||_2`` (the
threshold of :mod:`hikbench.solvers.yardstick`, relative to the unprojected level, so
that a level fully decided by the levels above gets projected rank 0).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hikbench.problems.hierarchy import Hierarchy, check_fits_in_memory

__all__ = ["RANK_RTOL", "LevelStructure", "level_structure"]

RANK_RTOL = 1e-10  #: singular values <= RANK_RTOL * ||A_k||_2 count as zero


@dataclass(frozen=True)
class LevelStructure:
    """Row kinds and spectra of one level (see the module docstring).

    ``sv_*`` are the largest and the smallest singular values counted in the
    rank (NaN when the rank is 0); ``cond = sv_max / sv_min`` (NaN when the
    rank is 0). ``projected_*`` are the same for ``A_k Z_{k-1}``."""

    level: int
    name: str
    rows: int
    equalities: int
    one_sided: int
    two_sided: int
    free: int
    rank: int
    sv_max: float
    sv_min: float
    projected_rank: int
    projected_sv_max: float
    projected_sv_min: float

    @property
    def cond(self) -> float:
        return self.sv_max / self.sv_min if self.rank else float("nan")

    @property
    def projected_cond(self) -> float:
        return self.projected_sv_max / self.projected_sv_min if self.projected_rank else float("nan")

    @property
    def conflicts(self) -> int:
        """Rank shared with the levels above, ``rank - projected_rank``."""
        return self.rank - self.projected_rank


def _extremes(s: np.ndarray, r: int) -> tuple[float, float]:
    return (float(s[0]), float(s[r - 1])) if r else (float("nan"), float("nan"))


def level_structure(h: Hierarchy, rtol: float = RANK_RTOL) -> list[LevelStructure]:
    """One :class:`LevelStructure` per level of h, level 0 first."""
    lo_inf, up_inf = np.isneginf(h.lower), np.isposinf(h.upper)
    out = []
    check_fits_in_memory(h.n, "rank analysis", matrices=3)  # Z, the full SVD's V^T, Z @ V^T
    Z = np.eye(h.n)  # orthonormal basis of the null space of the levels above, (n, n - rank)
    for k in range(h.depth):
        s = h.level_rows(k)
        eq, free = h.is_equality[s], h.is_free[s]
        one = (lo_inf[s] ^ up_inf[s])
        A = h.A[s][~free]
        if A.shape[0] and h.n:
            sv = np.linalg.svd(A, compute_uv=False)
            thr = rtol * sv[0]
            r = int(np.sum(sv > thr))
        else:
            sv, thr, r = np.zeros(0), 0.0, 0
        if A.shape[0] and Z.shape[1]:
            _, sp, Vt = np.linalg.svd(A @ Z, full_matrices=True)
            p = int(np.sum(sp > thr)) if thr > 0 else 0
            Z = Z @ Vt[p:].T
        else:
            sp, p = np.zeros(0), 0
        out.append(LevelStructure(
            level=k, name=h.names[k], rows=s.stop - s.start, equalities=int(eq.sum()),
            one_sided=int(one.sum()), two_sided=int((~eq & ~one & ~free).sum()), free=int(free.sum()),
            rank=r, sv_max=_extremes(sv, r)[0], sv_min=_extremes(sv, r)[1],
            projected_rank=p, projected_sv_max=_extremes(sp, p)[0], projected_sv_min=_extremes(sp, p)[1]))
    return out
