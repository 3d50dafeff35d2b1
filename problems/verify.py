"""Solver-independent verification: per-level violations and their
lexicographic comparison.

The optimal slack of every level of the sequence of LSIs (ICRA 2010, eqs.
(33)-(36)) is unique even when x is not, so a solution is judged from x alone:

    v_k(x) = max(lower_k - A_k x, 0) + max(A_k x - upper_k, 0)      (per row)

and the vector of norms ``(||v_0||, ..., ||v_{N-1}||)``. Two such vectors are
compared level by level, each with the tolerance (:func:`level_tolerances`)

    tol_k = rtol * t_k + ROUNDOFF * s_k + atol

where ``t_k`` is the size of level k's own terms at the reference, row by row
(:func:`level_terms`: ``|| |A_k| |x| + |b_k| ||_2``, b_k each row's bound nearer
``A_k x``) and ``s_k = ||A_k||_F ||x|| + ||bounds||`` (:func:`level_scales`)
carries the round-off floor of a backward-stable solve. :func:`verify` is
lexicographic (the first level that differs decides); :func:`judge` is the
verdict of a row against a certified optimum at an accuracy profile of
:data:`PROFILES` (no level above it beyond its tolerance), and
:func:`level_gaps` the gaps that verdict reads, relative to ``t_k``
(docs/verification.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hikbench.problems.errors import HikbenchError
from hikbench.problems.hierarchy import Hierarchy


@dataclass(frozen=True)
class Profile:
    """An accuracy profile: a row is verified at it when no level of x is above the certified
    optimum's by more than ``rtol`` times the level's terms (plus the round-off floor):
    ``level_gaps(h, x, x_ref)[k] <= rtol`` up to :data:`ROUNDOFF` (:func:`judge`)."""

    name: str
    rtol: float
    accepts: str  #: what it accepts, in words (docs/verification.md, report.md)


#: the accuracy profiles, tightest first: a row verified at one is verified at every later one
PROFILES: dict[str, Profile] = {p.name: p for p in (
    Profile("high", 1e-9, "each level within 1e-9 of its terms of the certified optimum: what double precision "
                          "and a backward-stable method reach (docs/verification.md: what hcod, the null-space "
                          "recursions and the cascades reach on the quick suite)"),
    Profile("default", 1e-8, "within 1e-8: QP cascades at their tight tolerances; the optimum perturbed by 1e-6 "
                             "relative (its largest level gap 1.5e-7 to 5e-7 of the terms on equality, IK-like "
                             "and random problems) is refused"),
    Profile("low", 1e-6, "within 1e-6: the optimum perturbed by 1e-6 relative passes, one perturbed by 1e-4 "
                         "does not"),
)}
#: the round-off floor of a level's tolerance, relative to ``||A_k||_F ||x_ref|| + ||bounds_k||``
#: (:func:`level_scales`), at every profile: what a backward-stable solve may leave in a level
#: whose own terms vanish at the reference (hcod's level norms are within 5e-13 of it of the
#: exact optimum's on the certified families)
ROUNDOFF = 1e-12

__all__ = ["PROFILES", "ROUNDOFF", "Profile", "Verdict", "compare_lexicographic", "judge", "level_gaps",
           "level_norms", "level_scales", "level_terms", "level_tolerances", "verify", "violation"]


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
    normwise size of the terms whose difference is the residual: ``ROUNDOFF * scale_k`` is the
    round-off floor of every tolerance (:func:`level_tolerances`; the tolerance's relative
    part follows the level's own terms, :func:`level_terms`). Not
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


def level_terms(h: Hierarchy, x=None) -> np.ndarray:
    """Size of each level's own terms at x, row by row, shape (depth,):

        t_k = || ( sum_j |a_ij| |x_j| + |b_i| )_{i in level k} ||_2

    with ``b_i`` the finite bound of row i nearer ``a_i x`` (0 for a free row; x = 0 where
    None): the products and the bound whose difference is the row's residual, so that ``rtol *
    t_k`` is what an answer accurate to rtol in each of them may leave. Unlike
    ``||A_k||_F ||x||`` (:func:`level_scales`), a component of x that the level's rows do not
    weigh, or a bound of a row far from where the row is, adds nothing: with ``||x*||`` of
    1e9-1e10 from one level, that product made every level's tolerance 1e3-1e4 and hid a gap
    of 65. Homogeneous: bounds and x times c give c t_k."""
    x = np.zeros(h.n) if x is None else _check_x(h, x)
    A = np.abs(h.A)
    m = A.max(axis=1, initial=0.0)
    e = np.where((m > 0) & np.isfinite(m), np.frexp(m)[1], 0)
    with np.errstate(over="ignore", invalid="ignore"):  # (beyond the doubles: inf, as the row's terms are)
        t = np.ldexp(np.ldexp(A, -e[:, None]) @ np.abs(x), e)
        r = h.A @ x
    lo, up = h.lower, h.upper
    near_lo = np.isfinite(lo) & (~np.isfinite(up) | (np.abs(r - lo) <= np.abs(r - up)))
    b = np.where(near_lo, lo, np.where(np.isfinite(up), up, 0.0))
    return _group_norms(t + np.abs(b), h.level, h.depth)


def level_tolerances(h: Hierarchy, x_ref, rtol: float, atol: float = 0.0) -> np.ndarray:
    """``rtol * level_terms(h, x_ref) + ROUNDOFF * level_scales(h, x_ref) + atol``, shape (depth,):
    each level's tolerance for a comparison with the reference ``x_ref``."""
    return rtol * level_terms(h, x_ref) + ROUNDOFF * level_scales(h, x_ref) + atol


def level_gaps(h: Hierarchy, x, x_ref) -> np.ndarray:
    """``(||v_k(x)|| - ||v_k(x_ref)||) / t_k`` (:func:`level_terms` of x_ref), shape (depth,):
    how far each level of x is above the reference's (< 0: below), relative to the level's own
    terms; 0 where both norms are equal, +-inf where the terms vanish and the norms differ,
    NaN where a norm is NaN."""
    a, b = level_norms(h, _check_x(h, x)), level_norms(h, _check_x(h, x_ref))
    t = level_terms(h, x_ref)
    with np.errstate(divide="ignore", invalid="ignore"):
        g = (a - b) / t
    g[a == b] = 0.0
    return g


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

    Level k differs when ``|a_k - b_k| > rtol * scales[k] + atol[k]`` (atol a number, or one
    per level). NaN in either vector counts as a difference with the NaN side worse.
    """
    a = np.asarray(norms_a, dtype=float)
    b = np.asarray(norms_b, dtype=float)
    if a.shape != b.shape or a.ndim != 1:
        raise HikbenchError(f"norm vectors must have the same 1-D shape; got {a.shape} and {b.shape}")
    s = np.ones_like(a) if scales is None else np.asarray(scales, dtype=float)
    if s.shape != a.shape:
        raise HikbenchError(f"scales has shape {s.shape}: expected {a.shape}")
    at = np.broadcast_to(np.asarray(atol, dtype=float), a.shape) if np.ndim(atol) == 0 else np.asarray(atol, float)
    if at.shape != a.shape:
        raise HikbenchError(f"atol has shape {at.shape}: expected a number or {a.shape}")
    for k in range(a.size):
        tol = rtol * s[k] + at[k]
        if np.isnan(a[k]) or np.isnan(b[k]):
            if np.isnan(a[k]) and np.isnan(b[k]):
                return Verdict(k, None, float("nan"), tol)
            return Verdict(k, "b" if np.isnan(a[k]) else "a", float("nan"), tol)
        d = a[k] - b[k]
        if abs(d) > tol:
            return Verdict(k, "a" if d < 0 else "b", float(d), tol)
    return Verdict(None, None, 0.0, 0.0)


def verify(h: Hierarchy, x, x_ref, rtol: float = 1e-9, atol: float = 0.0) -> Verdict:
    """Compare a solution x with a reference x_ref on hierarchy h lexicographically
    (``"a"`` is x, ``"b"`` the reference), level k with the tolerance of
    :func:`level_tolerances`: ``rtol`` times the level's own terms at the reference, plus the
    round-off floor, plus ``atol``. Both come from the reference only: with x's own, an x
    with a huge component along a direction no level constrains bought itself a tolerance
    without limit (``x0 = 1`` violated by 1000 passed beside ``x2 = 1e12``). Such an x, whose
    own rounding exceeds the tolerance, is not verified."""
    x = _check_x(h, x)
    x_ref = _check_x(h, x_ref)
    return compare_lexicographic(level_norms(h, x), level_norms(h, x_ref), level_terms(h, x_ref), rtol,
                                 ROUNDOFF * level_scales(h, x_ref) + atol)


def judge(h: Hierarchy, x, x_ref, rtol: float) -> Verdict:
    """The verdict of x against a certified optimum x_ref at ``rtol`` (a profile's, :data:`PROFILES`):
    the first level where x is above x_ref beyond its tolerance (:func:`level_tolerances`;
    ``lower`` "b": not verified), else the first where it is below beyond it (``lower`` "a":
    verified; x can be below the exact optimum only by trading within a tolerance above), else
    equal. Every level counts, not only the first that differs: x is verified at rtol iff no
    level is above the optimum beyond its tolerance, so a row verified at a tolerance is
    verified at every larger one (at "high", then "default", then "low")."""
    x = _check_x(h, x)
    x_ref = _check_x(h, x_ref)
    a, b = level_norms(h, x), level_norms(h, x_ref)
    tol = level_tolerances(h, x_ref, rtol)
    below = None
    for k in range(a.size):
        if np.isnan(a[k]) or np.isnan(b[k]):
            if np.isnan(a[k]):
                return Verdict(k, "b", float("nan"), float(tol[k]))
            below = below or Verdict(k, "a", float("nan"), float(tol[k]))
            continue
        d = a[k] - b[k]
        if d > tol[k]:
            return Verdict(k, "b", float(d), float(tol[k]))
        if -d > tol[k] and below is None:
            below = Verdict(k, "a", float(d), float(tol[k]))
    return below or Verdict(None, None, 0.0, 0.0)
