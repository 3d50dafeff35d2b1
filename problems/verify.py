"""Solver-independent verification: per-level violations and their
lexicographic comparison.

The optimal slack of every level of the sequence of LSIs (ICRA 2010, eqs.
(33)-(36)) is unique even when x is not, so a solution is judged from x alone:

    v_k(x) = max(lower_k - A_k x, 0) + max(A_k x - upper_k, 0)      (per row)

and the vector of norms ``(||v_0||, ..., ||v_{N-1}||)``. Two such vectors are
compared lexicographically, level 0 first, each level with the tolerance
``rtol * scale_k + atol`` where ``scale_k`` is the size of level k's terms
(:func:`level_scales`). The first level whose norms differ by more than that
is the verdict.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hikbench.problems.errors import HikbenchError
from hikbench.problems.hierarchy import Hierarchy

__all__ = ["Verdict", "compare_lexicographic", "level_norms", "level_scales", "verify", "violation"]


def _check_x(h: Hierarchy, x) -> np.ndarray:
    x = np.asarray(x, dtype=np.float64)
    if x.shape != (h.n,):
        raise HikbenchError(f"x has shape {x.shape}: expected ({h.n},)")
    return x


def violation(h: Hierarchy, x) -> np.ndarray:
    """Per-row violation ``v(x) = max(lower - A x, 0) + max(A x - upper, 0)``.

    Returns ndarray, shape (m,), nonnegative. NaN in x gives NaN rows (a wrong
    result must look wrong), never a silent zero.
    """
    x = _check_x(h, x)
    with np.errstate(invalid="ignore", over="ignore"):  # (x holding inf: 0 * inf is NaN, said by the row, not a warning)
        r = h.A @ x
        v = np.maximum(h.lower - r, 0.0) + np.maximum(r - h.upper, 0.0)  # (inf - inf: NaN, as it should)
    v[np.isnan(r)] = np.nan
    return v


def _group_norms(values: np.ndarray, groups: np.ndarray, count: int) -> np.ndarray:
    """2-norm of ``values[groups == g]`` for g < count, each scaled by its
    largest entry before squaring (``m ||v / m||``): no overflow above 1e154
    nor underflow below 1e-154, where the plain sum of squares gave inf or
    0 (a problem at bounds x 1e-300 then had every answer's norms 0, a wrong
    one passing as the reference). NaN stays NaN, inf stays inf, an empty
    group is 0."""
    a = np.abs(values)
    m = np.zeros(count)
    with np.errstate(invalid="ignore"):
        np.maximum.at(m, groups, a)  # (np.maximum propagates NaN)
    mg = m[groups]
    with np.errstate(invalid="ignore", divide="ignore"):
        q = np.where(mg > 0, a / mg, 0.0)
        out = m * np.sqrt(np.bincount(groups, weights=q * q, minlength=count))
    out[np.isposinf(m)] = np.inf
    return out


def _norm(v) -> float:
    """2-norm of the entries of v (any shape), scaled as :func:`_group_norms`."""
    v = np.asarray(v, dtype=float).ravel()
    return float(_group_norms(v, np.zeros(v.size, dtype=np.intp), 1)[0])


def level_norms(h: Hierarchy, x) -> np.ndarray:
    """``(||v_0(x)||_2, ..., ||v_{N-1}(x)||_2)``, shape (depth,); 0 for an
    empty level. Each level's violations are scaled by their largest before
    squaring (:func:`_group_norms`), so a problem at any scale the doubles
    hold is judged in its own units."""
    v = violation(h, x)
    return _group_norms(v, h.level, h.depth)


def level_scales(h: Hierarchy, x=None) -> np.ndarray:
    """Scale of each level's residual, shape (depth,).

    ``scale_k = ||A_k||_F * ||x|| + ||finite bounds of level k||_2``: the
    size of the terms whose difference is the residual, so that ``rtol *
    scale_k`` is the round-off a backward-stable solver may make. Not
    floored: a level of small coefficients (a task in other units, scaled by
    1e-7) is judged relative to its own size; a floor at 1 let rtol 1e-6 pass
    an answer that left such a level wholly undone (and then, free of it, was
    lower at the next level). Nor is ``||x||`` given a ``1 +``: with every bound and x at 1e-9, ``||A_k||_F``
    alone was 1e9 times the level's size, and any answer passed. Scaling
    the bounds and both x by one factor scales the tolerance alike.
    ``atol`` of :func:`verify` is the one absolute part of a tolerance.
    """
    xn = 0.0 if x is None else _norm(x)
    out = np.zeros(h.depth)
    for k in range(h.depth):
        s = h.level_rows(k)
        b = np.concatenate([h.lower[s], h.upper[s]])
        b = b[np.isfinite(b)]
        out[k] = _scaled_product(h.A[s], xn) + _norm(b)
    return out


def _scaled_product(A: np.ndarray, xn: float) -> float:
    """``||A||_F * xn`` without overflow where the product is a double (rows of norm 1e308
    with x of 1e-3: ``||A||_F`` alone overflowed, and an infinite tolerance passed any answer)."""
    m = float(np.max(np.abs(A), initial=0.0))
    if m == 0 or not np.isfinite(m) or xn == 0:
        return _norm(A) * xn
    e = int(np.frexp(m)[1])
    with np.errstate(over="ignore"):  # (beyond the doubles: inf, as the level's terms are)
        return float(np.ldexp(_norm(np.ldexp(A, -e)) * xn, e))


@dataclass(frozen=True)
class Verdict:
    """Result of a lexicographic comparison of two level-norm vectors.

    Attributes
    ----------
    level : int or None
        First level whose norms differ beyond tolerance; None when equal.
    lower : {"a", "b"} or None
        Which vector is lower there (lexicographically better).
    difference : float
        ``norms_a[level] - norms_b[level]`` (0.0 when equal).
    tolerance : float
        The tolerance used at that level.
    """

    level: int | None
    lower: str | None
    difference: float = 0.0
    tolerance: float = 0.0

    @property
    def equal(self) -> bool:
        return self.level is None


def compare_lexicographic(norms_a, norms_b, scales=None, rtol: float = 1e-9, atol: float = 0.0) -> Verdict:
    """Compare two level-norm vectors lexicographically, level 0 first.

    Level k differs when ``|a_k - b_k| > rtol * scales[k] + atol``. NaN in
    either vector counts as a difference with the NaN side worse.
    """
    a = np.asarray(norms_a, dtype=float)
    b = np.asarray(norms_b, dtype=float)
    if a.shape != b.shape or a.ndim != 1:
        raise HikbenchError(f"norm vectors must have the same 1-D shape; got {a.shape} and {b.shape}")
    s = np.ones_like(a) if scales is None else np.asarray(scales, dtype=float)
    if s.shape != a.shape:
        raise HikbenchError(f"scales has shape {s.shape}: expected {a.shape}")
    for k in range(a.size):
        tol = rtol * s[k] + atol
        if np.isnan(a[k]) or np.isnan(b[k]):
            if np.isnan(a[k]) and np.isnan(b[k]):
                return Verdict(k, None, float("nan"), tol)
            return Verdict(k, "b" if np.isnan(a[k]) else "a", float("nan"), tol)
        d = a[k] - b[k]
        if abs(d) > tol:
            return Verdict(k, "a" if d < 0 else "b", float(d), tol)
    return Verdict(None, None, 0.0, 0.0)


def verify(h: Hierarchy, x, x_ref, rtol: float = 1e-9, atol: float = 0.0) -> Verdict:
    """Compare a solution x with a reference x_ref on hierarchy h
    (``"a"`` is x, ``"b"`` the reference). Scales use the reference's norm
    only: with x's own (the larger of the two, before the audit of
    2026-11-23) an x with a huge component along a direction no level
    constrains bought itself a tolerance without limit -- ``x0 = 1``
    violated by 1000 passed beside ``x2 = 1e12``, and QP cascades returning
    ``||x|| = 5e10`` where 0.5 does were verified though level 0 was worse by
    7.8e-6 (tolerance 8.7e-9 at the reference's scale). Such an x, whose own
    rounding exceeds the tolerance, is not verified."""
    x = _check_x(h, x)
    x_ref = _check_x(h, x_ref)
    return compare_lexicographic(level_norms(h, x), level_norms(h, x_ref), level_scales(h, x_ref), rtol, atol)
