"""Hard cases of the test set on exactly representable data (docs/testset.md, "Hard cases").

Every entry of A and every bound is a small integer or a dyadic rational (an integer times a
power of two), so the rank that a case is about is the rank in exact arithmetic: a row that is
the sum of two others is exactly that sum in the stored float64 numbers, a near-parallel row
differs from its neighbour by exactly ``2**-p``, a badly scaled row is an integer row times
exactly ``2**e``. The certified optimum of the stored problem is then the optimum the case is
about (unlike :func:`hikbench.problems.generators.degenerate`'s ``rank_deficient``, whose
combinations are exact only to rounding).

Each case is ``case(n, seed) -> Hierarchy``, deterministic for its arguments
(``numpy.random.default_rng(seed)``).
"""

from __future__ import annotations

import numpy as np

from hikbench.problems.errors import HikbenchError
from hikbench.problems.hierarchy import Hierarchy, Level

__all__ = ["CASES", "hard_case"]


def _ints(rng, shape, low=-3, high=3) -> np.ndarray:
    """Integer entries in [low, high] as float64, no zero row."""
    A = rng.integers(low, high + 1, size=shape).astype(float)
    for i in np.flatnonzero(~A.any(axis=1)) if A.ndim == 2 else ():
        A[i, rng.integers(A.shape[1])] = 1.0
    return A


def _box(n: int, bound: float) -> Level:
    return Level(np.eye(n), np.full(n, -bound), np.full(n, bound), "box")


def _posture(rng, n: int) -> Level:
    """x = t with t in quarters: the last level, which fixes what is left."""
    return Level.equality(np.eye(n), rng.integers(-4, 5, n) / 4.0, "posture")


def rank_deficient(n: int, seed: int) -> Hierarchy:
    """A level of 2r rows of rank r: its last r rows are exact integer combinations (sums and
    differences) of its first r, with targets that agree (a consistent level) or not (seed odd)."""
    rng = np.random.default_rng(seed)
    r = max(1, n // 3)
    B = _ints(rng, (r, n))
    C = np.array([B[i] + B[(i + 1) % r] if r > 1 else 2 * B[i] for i in range(r)])
    tB = rng.integers(-3, 4, r).astype(float)
    tC = np.array([tB[i] + tB[(i + 1) % r] if r > 1 else 2 * tB[i] for i in range(r)])
    if seed % 2:
        tC = tC + rng.integers(1, 3, r)  # inconsistent: a nonzero optimal slack
    D = _ints(rng, (r, n))
    E = np.vstack([D, D[:1] - D[-1:]])  # another rank-deficient level below, inequalities
    return Hierarchy.from_levels([
        _box(n, 2.0),
        Level.equality(np.vstack([B, C]), np.concatenate([tB, tC]), "rank-deficient task"),
        Level(E, np.full(len(E), -1.0), np.full(len(E), 1.0), "rank-deficient inequalities"),
        _posture(rng, n)], n=n)


def duplicate_rows(n: int, seed: int) -> Hierarchy:
    """A row repeated in its level with a conflicting target, and a row of the level above
    copied into the level below with another target (decided above: a nonzero slack)."""
    rng = np.random.default_rng(seed)
    A1 = _ints(rng, (max(2, n // 2), n))
    t1 = rng.integers(-2, 3, len(A1)).astype(float)
    A1 = np.vstack([A1, A1[:1]])
    t1 = np.append(t1, t1[0] + 2.0)
    A2 = np.vstack([A1[1:2], _ints(rng, (2, n)), A1[1:2]])
    u2 = np.array([t1[1] - 1.0, 1.0, 1.0, t1[1] - 1.0])
    return Hierarchy.from_levels([
        _box(n, 3.0), Level.equality(A1, t1, "duplicated row, conflicting targets"),
        Level(A2, np.full(4, -np.inf), u2, "rows copied from above"), _posture(rng, n)], n=n)


def near_parallel(n: int, seed: int) -> Hierarchy:
    """Rows a and a + 2**-p e_j (p = 10 .. 40) side by side in a level, with targets that an
    integer point x^ meets exactly (``t = A x^``, exact in float64), and ``|c x - c x^| <= 1`` with
    c = a - 2**-p e_k under it: full rank in exact arithmetic, conditioned like 2**p. A solver
    whose rank cut drops one row of the pair leaves the direction e_j to the levels below; the
    exact optimum does not."""
    rng = np.random.default_rng(seed)
    p = int(rng.integers(10, 41))
    a = _ints(rng, (1, n))[0]
    j = int(rng.integers(n))
    b = a.copy()
    b[j] += 2.0 ** -p
    A1 = np.vstack([a, b, _ints(rng, (max(0, n // 2 - 2), n))]) if n > 2 else np.vstack([a, b])
    x_hat = rng.integers(-1, 2, n).astype(float)
    t1 = A1 @ x_hat  # (integers plus a multiple of 2^-p: exact)
    c = a.copy()
    c[(j + 1) % n] -= 2.0 ** -p
    return Hierarchy.from_levels([
        _box(n, 4.0), Level.equality(A1, t1, f"near-parallel rows (2^-{p})"),
        Level(np.vstack([c, -c]), np.array([-np.inf, -np.inf]), np.array([c @ x_hat + 1.0, 1.0 - c @ x_hat]),
              "near-parallel below (|c x - c x^| <= 1)"), _posture(rng, n)], n=n)


def conflicting_levels(n: int, seed: int) -> Hierarchy:
    """The same rows asked other values at successive levels, and an inequality level that the
    box above cannot satisfy: each lower level keeps only what the one above leaves."""
    rng = np.random.default_rng(seed)
    m = max(1, n // 2)
    C = _ints(rng, (m, n))
    t = rng.integers(-2, 3, m).astype(float)
    return Hierarchy.from_levels([
        _box(n, 1.0),
        Level(np.eye(n)[: max(1, n // 3)], np.full(max(1, n // 3), 2.0), np.full(max(1, n // 3), np.inf),
              "x_i >= 2 (box: <= 1)"),
        Level.equality(C, t, "task"), Level.equality(C, t + 1.0, "same rows, other targets"),
        Level.equality(C[::-1], t[::-1] - 0.5, "same rows reversed, other targets"), _posture(rng, n)], n=n)


def infeasible_top(n: int, seed: int) -> Hierarchy:
    """Level 0 infeasible in itself: ``x_0 >= 1`` and ``x_0 <= -1`` (and ``sum x >= n`` inside
    a box of 1/2 in one level): a nonzero optimal slack at the top."""
    rng = np.random.default_rng(seed)
    A0 = np.vstack([np.eye(n)[:1], np.eye(n)[:1], np.ones((1, n)), np.eye(n)])
    lo0 = np.concatenate([[1.0, -np.inf, float(n)], np.full(n, -0.5)])
    up0 = np.concatenate([[np.inf, -1.0, np.inf], np.full(n, 0.5)])
    A1 = _ints(rng, (max(1, n // 2), n))
    return Hierarchy.from_levels([
        Level(A0, lo0, up0, "infeasible: x0 >= 1, x0 <= -1, sum x >= n, |x| <= 1/2"),
        Level.equality(A1, rng.integers(-2, 3, len(A1)).astype(float), "task"), _posture(rng, n)], n=n)


def deep_one_row(n: int, seed: int) -> Hierarchy:
    """``2n`` levels of one row each (integer rows, entries in [-2, 2]), equalities and one- and
    two-sided inequalities in turn: the stack is saturated after about n levels."""
    rng = np.random.default_rng(seed)
    levels = []
    for k in range(2 * n):
        a = _ints(rng, (1, n), -2, 2)
        v = float(rng.integers(-3, 4))
        kind = k % 3
        lo, up = (v, v) if kind == 0 else ((v, np.inf) if kind == 1 else (v - 1.0, v + 1.0))
        levels.append(Level(a, np.array([lo]), np.array([up]), f"row {k}"))
    return Hierarchy.from_levels(levels, n=n)


def degenerate_vertex(n: int, seed: int) -> Hierarchy:
    """An integer vertex v held by 2n inequality rows ``a_i x <= a_i v`` (n of them would do: a
    degenerate vertex), and a task below that pulls x beyond v inside the cone of the rows:
    the optimum sits at v with more rows at their bound than n."""
    rng = np.random.default_rng(seed)
    v = rng.integers(-2, 3, n).astype(float)
    A = np.vstack([np.eye(n), _ints(rng, (n, n), 0, 2)])  # nonnegative rows: v + c 1 is beyond all
    u = A @ v
    return Hierarchy.from_levels([
        _box(n, 4.0), Level(A, np.full(2 * n, -np.inf), u, "2n rows through the vertex v"),
        Level.equality(np.eye(n), v + 2.0, "target beyond v"), _posture(rng, n)], n=n)


def badly_scaled(n: int, seed: int) -> Hierarchy:
    """Integer rows times exactly ``2**e`` (e in [-30, 30]), bounds alike: the same geometry as
    the unscaled rows, row norms spread over 18 orders of magnitude."""
    rng = np.random.default_rng(seed)
    m = max(2, n // 2)
    A1, A2 = _ints(rng, (m, n)), _ints(rng, (n, n))
    s1 = 2.0 ** rng.integers(-30, 31, m)
    s2 = 2.0 ** rng.integers(-30, 31, n)
    t1 = rng.integers(-2, 3, m).astype(float)
    return Hierarchy.from_levels([
        Level(np.eye(n) * s2[:, None], -2.0 * s2, 2.0 * s2, "box, rows scaled by 2^e"),
        Level.equality(A1 * s1[:, None], t1 * s1, "task, rows scaled by 2^e"),
        Level(A2 * s2[:, None], np.full(n, -np.inf), s2, "inequalities, rows scaled by 2^e"),
        _posture(rng, n)], n=n)


#: the hard cases by name
CASES = {"rank_deficient": rank_deficient, "duplicate_rows": duplicate_rows, "near_parallel": near_parallel,
         "conflicting_levels": conflicting_levels, "infeasible_top": infeasible_top,
         "deep_one_row": deep_one_row, "degenerate_vertex": degenerate_vertex, "badly_scaled": badly_scaled}


def hard_case(case: str, n: int = 6, seed: int = 0) -> Hierarchy:
    """The hard case ``case`` (one of :data:`CASES`) at n variables."""
    if case not in CASES:
        raise HikbenchError(f"unknown hard case {case!r}; expected one of {', '.join(CASES)}")
    if not isinstance(n, (int, np.integer)) or n < 2:
        raise HikbenchError(f"hard case {case}: n must be an integer >= 2; got {n!r}")
    return CASES[case](int(n), int(seed))
