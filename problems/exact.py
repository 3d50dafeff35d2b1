"""An exact certificate of a lexicographic solution, in multiple-precision arithmetic.

Where two solvers disagree near a level's conditioning, double precision cannot say which one
is right. :func:`certify` reads an active set off a point x (each row inside its bounds, or
held at a bound, or violated), solves the sequence of LSIs (ICRA 2010, eqs. (33)-(36)) on that
set in ``digits``-digit arithmetic (mpmath), and checks that the result is the lexicographic
optimum: feasible for every row read as inside, and at each stage (every level, then the
minimum-norm stage) a KKT point with multipliers of the right sign. A certified x* is the
exact optimum of the problem as stored (the float64 numbers of A and the bounds, taken
exactly); its level norms judge any solver's, whatever their agreement with each other.

On that active set, stage k (levels j < k done) is

    min_x 1/2 ||w_k||^2,  w_k = A_T x - t_T
    s.t.  A_E x = e_E

with T the rows of level k read at a bound or violated (their targets t the bound they are
at or beyond; an equality row its value), E the rows of the levels above that are held: a row
with a nonzero optimal slack at its achieved value (eq. 35, w_j* fixed), one with a zero
slack at its bound. Each stage is solved by the SVD null-space method (eq. 2) in ``digits``
digits. The last stage is min 1/2 ||x||^2 on every held row.

At x*, stage k is optimal iff ``A_T^T w_k + A_E^T lam = 0`` with lam free on the rows held
at a value and ``lam >= 0`` (row held at its upper bound) or ``<= 0`` (lower) on the others
(a target row of level k at its bound has the multiplier w_i = 0: it is no constraint).
lam is solved for in ``digits`` digits on the supports float64 bounded least squares gives,
and where none of them serves, by an exact NNLS (Lawson and Hanson), so that a refusal at a
stage means that no multipliers of the right sign exist; the residual must vanish to
``10**-(digits // 2)`` of the size of g's terms. The held rows' equations and the multipliers'
least squares are solved with each row divided by its norm: the same solutions, and a rank
cut at each row's own scale (rows of norm 1e200 and 1 side by side).

Only a certificate that passes every check is returned certified; the reason names the first
check that failed otherwise. The active set is read at each tolerance of :data:`READINGS` in
turn until one certifies. A row read at a bound whose exact slack on its stage points inside
its bounds (a row of a rank-deficient level that the others place there) is let go for that
stage, and held at its bound below if the stage's point leaves it there.

What it certifies is the stored problem. A level whose rows are rank-deficient only to float64
rounding (combinations of others, the ``rank_deficient`` family) has full rank in exact
arithmetic, with singular values ~1e-17 of the largest: its exact optimum is another point
than the one a solver's rank threshold gives, and the certificate is refused there. The cost
is that of dense SVDs in software arithmetic: ~0.1 s at n = 5, ~3 s at n = 20.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hikbench.problems.errors import HikbenchError
from hikbench.problems.hierarchy import Hierarchy

__all__ = ["COST_S", "Certificate", "certify", "estimated_seconds"]

#: row states read off x
INSIDE, AT_LOWER, AT_UPPER, EQUALITY = "inside", "lower", "upper", "equality"


@dataclass
class Certificate:
    """The outcome of :func:`certify`.

    Attributes
    ----------
    certified : bool
        x* passed every check: it is the exact lexicographic optimum.
    reason : str
        Empty when certified, else the first check that failed.
    level_norms : ndarray, shape (levels,)
        The level norms ``||v_k(x*)||`` of the exact x*, rounded to float64 (NaN where the
        stages did not reach x*).
    x : ndarray, shape (n,)
        x* rounded to float64 (NaN where not reached).
    states : list of str
        The state read off the given point for each row (``inside``, ``lower``, ``upper``,
        ``equality``).
    """

    certified: bool
    reason: str
    level_norms: np.ndarray
    x: np.ndarray
    states: list = field(default_factory=list)


def _row_scales(h: Hierarchy, x: np.ndarray, E: "_Exact") -> list:
    """Each row's scale at x, ``|a_i| X + |bound_i|`` (the larger finite bound), in E's numbers
    (no overflow at rows of norm 1e308), a list of (rows,). ``X = ||x||``, or where x = 0 the
    largest ``|bound_j| / |a_j|`` (the distance of a bound's hyperplane from the origin, 1 where
    every bound is 0). No absolute part: the scale of a row multiplied by c (bounds alike) is c
    times its own, and A times c with x divided by c (the same problem in other units of x)
    leaves it unchanged, so that what reads as held and what counts as zero are the same in
    any units (an absolute ``|a_i| (1 + ||x||)`` read every row of A x 1e100 as held and
    certified a point above the optimum)."""
    ctx = E.ctx
    norms = [E.norm(row) if any(row) else ctx.mpf(0) for row in E.A]
    bound = [max(abs(v) if v is not None else ctx.mpf(0) for v in (lo, up)) for lo, up in zip(E.lo, E.up)]
    size = ctx.sqrt(ctx.fsum(ctx.mpf(float(v)) ** 2 for v in x))
    if size == 0:
        size = max((b / a for a, b in zip(norms, bound) if a > 0), default=ctx.mpf(0)) or ctx.mpf(1)
    return [a * size + b for a, b in zip(norms, bound)]


def _row_norms(A: np.ndarray) -> np.ndarray:
    """Each row's 2-norm without overflow (entries up to the largest double), shape (rows,)."""
    m = np.max(np.abs(A), axis=1, initial=0.0)
    safe = np.where(m > 0, m, 1.0)
    return m * np.linalg.norm(A / safe[:, None], axis=1)


def _where(h: Hierarchy, i: int) -> str:
    """``level k, row j`` of the stacked row i."""
    k = int(np.searchsorted(h.starts, i, side="right")) - 1
    return f"level {k}, row {i - h.starts[k]}"


def _read_states(h: Hierarchy, E: "_Exact", x, rtol: float, scale: list) -> list[str]:
    """Each row's state at x (E's numbers): at a bound or beyond it within or past ``rtol`` of
    the row's scale (:func:`_row_scales`) reads as held there (or violated, the same target).
    ``A x`` is taken in E's digits (a row of norm 1e308 overflows in float64)."""
    states = []
    for i in range(h.A.shape[0]):
        lo, up = E.lo[i], E.up[i]
        if h.lower[i] == h.upper[i]:
            states.append(EQUALITY)
            continue
        r, tol = E.dot(i, x), rtol * scale[i]
        if up is not None and r >= up - tol and (lo is None or up - r <= r - lo):
            states.append(AT_UPPER)
        elif lo is not None and r <= lo + tol:
            states.append(AT_LOWER)
        else:
            states.append(INSIDE)
    return states


class _Exact:
    """The problem's numbers in ``digits`` digits and the linear algebra on them."""

    def __init__(self, h: Hierarchy, digits: int):
        import mpmath

        self.ctx = mpmath.MPContext()  # (its own precision: mpmath.mp's is left alone)
        self.ctx.dps = digits
        self.digits = digits
        self.A = [[self.ctx.mpf(float(v)) for v in row] for row in h.A]
        self.lo = [self.ctx.mpf(float(v)) if np.isfinite(v) else None for v in h.lower]
        self.up = [self.ctx.mpf(float(v)) if np.isfinite(v) else None for v in h.upper]
        self.n = h.n

    def matrix(self, rows):
        return self.ctx.matrix([self.A[i] for i in rows]) if rows else self.ctx.zeros(0, self.n)

    def solve_held(self, rows, values):
        """The minimum-norm x of ``A_rows x = values`` and the null-space basis of ``A_rows``
        (:meth:`lstsq`), each row divided by its norm: the same solution set, and a rank cut
        at the rows' own scale (relative to the stacked rows' norm it dropped a row 1e-200 the
        size of another)."""
        ctx = self.ctx
        if not rows:
            return self.lstsq(ctx.zeros(0, self.n), ctx.zeros(0, 1))
        norms = [self.norm(self.A[i]) for i in rows]
        M = ctx.matrix([[v / s for v in self.A[i]] for i, s in zip(rows, norms)])
        return self.lstsq(M, ctx.matrix([v / s for v, s in zip(values, norms)]))

    def norm(self, row):
        """||row||_2 of a list of this context's numbers (1 for a zero row: a divisor)."""
        return self.ctx.sqrt(self.ctx.fsum(v * v for v in row)) or self.ctx.mpf(1)

    def dot(self, i, x):
        return self.ctx.fsum(self.A[i][q] * x[q] for q in range(self.n))

    def _svd(self, M, ref):
        """U, s, Vt and the rank of M: singular values above 10**-(digits * 2 // 3) of ``ref``
        (the data's own zeros, not a tolerance), ``ref`` the size of the rows before their
        projection (projected, a row in the span of the rows above is ~1e-50, not 0: measured
        against itself, it made a direction of an x of 1e50)."""
        U, s, Vt = self.ctx.svd_r(M, full_matrices=True)
        cut = self.ctx.mpf(10) ** (-(self.digits * 2 // 3)) * ref
        rank = sum(1 for j in range(len(s)) if s[j] > cut)
        return U, s, Vt, rank

    def lstsq(self, M, b, ref=None):
        """The minimum-norm least-squares solution of M y = b (M m x p), and the null-space
        basis of M (p x (p - rank), columns). ``ref``: the scale of the rank cut (default
        ``||M||_F``)."""
        ctx = self.ctx
        p = M.cols
        if M.rows == 0:
            return ctx.zeros(p, 1), ctx.eye(p)
        if ref is None:
            ref = ctx.mnorm(M, "f")
        U, s, Vt, r = self._svd(M, ref)
        y = ctx.zeros(p, 1)
        for j in range(r):
            c = ctx.fsum(U[i, j] * b[i] for i in range(M.rows)) / s[j]
            for q in range(p):
                y[q] += c * Vt[j, q]
        N = ctx.zeros(p, p - r)
        for j in range(r, p):
            for q in range(p):
                N[q, j - r] = Vt[j, q]
        return y, N


def _multipliers_vanish(E: _Exact, g, gscale, held, rtol_exp: int) -> bool:
    """Whether ``g + C^T lam = 0`` has a solution with lam's signs (``held``: (row, sign) with
    sign +1 at an upper bound (lam >= 0), -1 at a lower one (its row negated, lam >= 0), 0 free),
    to ``10**-rtol_exp`` of ``gscale`` (the size of g's terms). First on the supports that float64
    bounded least squares gives, lam on each in E's digits; where none passes, by
    :func:`_nnls` in E's digits, which settles it."""
    from scipy.optimize import lsq_linear

    ctx = E.ctx
    tol = ctx.mpf(10) ** -rtol_exp * gscale
    if ctx.sqrt(ctx.fsum(v * v for v in g)) <= tol:
        return True
    if not held:
        return False
    C = [[E.A[i][q] * (s if s else 1) for q in range(E.n)] for i, s in held]
    Cf = np.array([[float(v) for v in row] for row in C])
    gmax = max(abs(v) for v in g)
    gf = np.array([float(v / gmax) for v in g])  # (g scaled: its terms may exceed a double)
    lb = np.array([-np.inf if s == 0 else 0.0 for _, s in held])
    # the support from the rows as they are and from the rows and g scaled to norm 1 (on the raw
    # rows, norms 1e-4 .. 1e4 around a gradient of 3e-7, bounded least squares stopped at 20 % of
    # |g|: badly_scaled n=12 seed 101), then every row
    rn = np.maximum(_row_norms(Cf), 1e-300)
    lam_tol = tol / float(rn.max())  # (a multiplier that small moves g by under tol)

    def passes(support, lam) -> bool:
        res = [ctx.fsum(C[j][q] * lam[t] for t, j in enumerate(support)) + g[q] for q in range(E.n)]
        small = ctx.sqrt(ctx.fsum(v * v for v in res)) <= tol
        return small and all(held[j][1] == 0 or lam[t] >= -lam_tol for t, j in enumerate(support))

    supports = []
    cmax = max(float(np.max(np.abs(Cf))), 1e-300)  # (rows of norm 1e308 overflow bounded least squares)
    for M, b in ((Cf / cmax, gf), (Cf / rn[:, None], gf / max(float(np.linalg.norm(gf)), 1e-300))):
        with np.errstate(over="ignore", invalid="ignore"):  # (rows 1e300 apart: a support that fails, not an error)
            lam_f = np.nan_to_num(lsq_linear(M.T, -b, bounds=(lb, np.inf), method="bvls").x)
        big = max(float(np.max(np.abs(lam_f))), 1e-300)
        supports.append([j for j in range(len(held)) if held[j][1] == 0 or abs(lam_f[j]) > 1e-12 * big])
    supports.append(list(range(len(held))))
    for support in supports:
        if support and passes(support, _lstsq_on(E, C, g, support)):
            return True
    lam = _nnls(E, C, g, [s == 0 for _, s in held], gscale)
    return passes(list(range(len(held))), lam)


def _lstsq_on(E: _Exact, C, g, support) -> list:
    """A lam of ``min ||g + C_S^T lam||`` on the rows S = ``support`` of C: the minimum-norm one
    of the rows divided by their norms (the rank cut at the rows' own scale), scaled back."""
    ctx = E.ctx
    norms = [E.norm(C[j]) for j in support]
    M = ctx.matrix([[C[j][q] / s for j, s in zip(support, norms)] for q in range(E.n)])  # (n, |S|)
    lam, _ = E.lstsq(M, ctx.matrix([-v for v in g]))
    return [lam[t] / s for t, s in enumerate(norms)]


def _nnls(E: _Exact, C, g, free, gscale) -> list:
    """lam minimising ``||g + C^T lam||`` with ``lam_j >= 0`` where not ``free[j]``: the active
    set method of Lawson and Hanson (Solving Least Squares Problems, 1974, ch. 23, NNLS), the
    free multipliers always in the passive set P, each least squares on P solved in E's digits.
    A row enters P where the residual's gain along it, ``-c_j . (g + C^T lam)``, exceeds the
    arithmetic's zero (``10**-(2 digits / 3)`` of ``|c_j| gscale``). C: (rows, n) lists of E's
    numbers; returns lam, a list of (rows,)."""
    ctx = E.ctx
    m, n = len(C), E.n
    eps = ctx.mpf(10) ** (-(E.digits * 2 // 3))
    gain_zero = [eps * gscale * E.norm(row) for row in C]
    P = [j for j in range(m) if free[j]]

    def solve(P):
        z = [ctx.mpf(0)] * m
        for t, v in zip(P, _lstsq_on(E, C, g, P) if P else ()):
            z[t] = v
        return z

    lam = solve(P)
    for _ in range(3 * m + 3):  # (finite in exact arithmetic: a cap against the rank cut)
        r = [-(ctx.fsum(C[j][q] * lam[j] for j in range(m)) + g[q]) for q in range(n)]
        gains = [(ctx.fsum(C[j][q] * r[q] for q in range(n)), j) for j in range(m)
                 if j not in P]
        gains = [(w, j) for w, j in gains if w > gain_zero[j]]
        if not gains:
            break
        P.append(max(gains)[1])
        while True:
            z = solve(P)
            out = [j for j in P if not free[j] and z[j] <= 0]
            if not out:
                break
            # back along lam -> z to the first multiplier that reaches 0; it leaves P
            alpha = min(lam[j] / (lam[j] - z[j]) if lam[j] > 0 else ctx.mpf(0) for j in out)
            lam = [lam[j] + alpha * (z[j] - lam[j]) for j in range(m)]
            P = [j for j in P if free[j] or lam[j] > 0]
        lam = z
    return lam


#: seconds of :func:`certify` (one reading, 50 digits) per ``n^2 x rows x levels``, an upper estimate:
#: the quick, ci and paper suites' problems (n = 6 .. 50, 4 .. 65 rows) and a robot stack (n = 38, 117
#: rows) took 0.2 to 1 times it on an AMD EPYC core (1 on a loaded machine)
COST_S = 2.5e-4


def estimated_seconds(h: Hierarchy) -> float:
    """The time :func:`certify` is expected to take on h when its first reading certifies
    (:data:`COST_S` ``n^2 rows depth``; dense SVDs in software arithmetic): 1 s at n = 12 with
    12 rows in 3 levels, 211 s at a robot stack of n = 38 and 117 rows in 5 levels (99 s
    measured)."""
    return COST_S * float(h.n) ** 2 * h.rows * h.depth


#: the reading tolerances :func:`certify` tries in turn (rows within them of a bound read as held)
READINGS = (1e-8, 1e-11, 1e-14, 0.0)


def certify(h: Hierarchy, x, rtol: float | None = None, digits: int = 50) -> Certificate:
    """Certify the lexicographic optimum on the active set read off x (module docstring).

    Parameters
    ----------
    h : Hierarchy
    x : array_like, shape (n,)
        The point the active set is read off (any solver's x).
    rtol : float >= 0, optional
        A row within ``rtol`` of its scale from a bound (or beyond it) is read as held there.
        By default each of :data:`READINGS` in turn, until one certifies: a row a solver left
        2e-9 inside its bound, or a bound of 1e-300 beside x = 0, reads as held at 1e-8 and
        the exact x* on that set is then not the minimum-norm point.
    digits : int
        Decimal digits of the arithmetic (>= 30).

    Returns
    -------
    Certificate
        The first certified reading's, else the first reading's refusal.
    """
    x = np.asarray(x, dtype=np.float64)
    if x.shape != (h.n,) or not np.all(np.isfinite(x)):
        raise HikbenchError(f"certify: x must be finite with shape ({h.n},); got shape {x.shape}")
    if not (isinstance(digits, int) and not isinstance(digits, bool) and digits >= 30):
        raise HikbenchError(f"certify: digits must be an int >= 30; got {digits!r}")
    if rtol is not None and not 0.0 <= rtol < 1.0:
        raise HikbenchError(f"certify: rtol must be in [0, 1); got {rtol!r}")
    first = None
    for reading in (READINGS if rtol is None else (rtol,)):
        cert = _certify_reading(h, x, reading, digits)
        if cert.certified:
            return cert
        first = first or cert
    return first


def _certify_reading(h: Hierarchy, x: np.ndarray, rtol: float, digits: int) -> Certificate:
    """:func:`certify` for one reading tolerance."""
    E = _Exact(h, digits)
    ctx = E.ctx
    x_mp = [ctx.mpf(float(v)) for v in x]
    scale = _row_scales(h, x, E)
    states = _read_states(h, E, x_mp, rtol, scale)
    row_norm = [E.norm(row) for row in E.A]
    # a slack within 10**-(2 digits / 3) of its row's scale is the arithmetic's zero
    zero = [v * ctx.mpf(10) ** (-(digits * 2 // 3)) for v in scale]

    def slack(i, xv, target):
        w = E.dot(i, xv) - target
        return w if abs(w) > zero[i] else ctx.mpf(0)
    nan = np.full(h.depth, np.nan)

    def fail(reason: str) -> Certificate:
        return Certificate(False, reason, nan, np.full(h.n, np.nan), states)

    held: list[tuple[int, int]] = []  # (row, sign): +1 upper, -1 lower, 0 at a value
    values: list = []  # the value each held row is held at
    stages = []  # (target rows, their targets, rows held above) per level, for the KKT checks at x*
    for k in range(h.depth):
        rows = range(h.starts[k], h.starts[k + 1])
        x0, N = E.solve_held([i for i, _ in held], values)
        let_go = {}  # rows read at a bound that are free on this stage: their bound
        while True:
            T = [i for i in rows if states[i] != INSIDE and i not in let_go]
            t = [E.lo[i] if states[i] in (AT_LOWER, EQUALITY) else E.up[i] for i in T]
            if not T:
                break
            AT = E.matrix(T)
            y, _ = E.lstsq(AT * N, ctx.matrix(t) - AT * x0, ref=ctx.mnorm(AT, "f"))
            x_k = x0 + N * y
            w = [slack(i, x_k, ti) for i, ti in zip(T, t)]
            side = [{AT_UPPER: 1, AT_LOWER: -1, EQUALITY: 0}[states[i]] for i in T]
            # a row read at a bound whose exact slack points inside its bounds is free on this
            # stage (a row of a rank-deficient level that the others place there): the one
            # furthest inside is let go, and the stage solved again
            inside = [(-sd * wi / zero[i], i) for i, sd, wi in zip(T, side, w) if sd * wi < 0]
            if not inside:
                break
            j = max(inside)[1]
            let_go[j] = E.lo[j] if states[j] == AT_LOWER else E.up[j]
        stages.append((T, t, len(held)))
        for i, ti, wi, sd in (zip(T, t, w, side) if T else ()):
            if wi != 0 or sd == 0:
                held.append((i, 0))
                values.append(ti + wi)
            else:
                held.append((i, sd))
                values.append(ti)
        # a row let go that the stage's point leaves at its bound is held there below (an
        # inequality of a level above); one inside is free, and x* must keep it inside
        for i, b in let_go.items():
            if T and slack(i, x_k, b) == 0:
                held.append((i, 1 if states[i] == AT_UPPER else -1))
                values.append(b)
            else:
                states[i] = INSIDE
    xs, _ = E.solve_held([i for i, _ in held], values)  # the minimum-norm x*
    # feasibility: the held rows at their values (the SVD's rank cut may have left a row out),
    # every other row inside its bounds
    for i, v in zip((i for i, _ in held), values):
        if abs(E.dot(i, xs) - v) > zero[i]:
            return fail(f"{_where(h, i)}: held at its value by the active set read off x, "
                        f"but the exact x* misses it (rows dependent beyond the arithmetic's digits)")
    for i, s in enumerate(states):
        if s != INSIDE:
            continue
        r = E.dot(i, xs)
        if (E.lo[i] is not None and r < E.lo[i]) or (E.up[i] is not None and r > E.up[i]):
            return fail(f"{_where(h, i)}: read as inside its bounds, but the exact x* "
                        f"leaves them")
    # KKT at x*, stage by stage: the rows held above stage k, the gradient of its objective
    half = digits // 2
    for k, (T, t, n_above) in enumerate(stages):
        if not T:
            continue
        w = [slack(i, xs, ti) for i, ti in zip(T, t)]
        g = [ctx.fsum(E.A[i][q] * wi for i, wi in zip(T, w)) for q in range(h.n)]
        gscale = ctx.fsum(row_norm[i] * abs(wi) for i, wi in zip(T, w))
        if not _multipliers_vanish(E, g, gscale, held[:n_above], half):
            return fail(f"level {k}: the exact x* is not optimal for its stage (no multipliers of the "
                        f"right sign cancel the gradient): the active set read off x is not the optimal one")
    if not _multipliers_vanish(E, list(xs), ctx.sqrt(ctx.fsum(v * v for v in xs)), held, half):
        return fail("the minimum-norm stage: the exact x* is not the minimum-norm point of the optimal set")
    norms = np.zeros(h.depth)
    for k in range(h.depth):
        s2 = ctx.mpf(0)
        for i in range(h.starts[k], h.starts[k + 1]):
            r = E.dot(i, xs)
            v = (E.lo[i] - r if E.lo[i] is not None and r < E.lo[i] else 0) + (
                r - E.up[i] if E.up[i] is not None and r > E.up[i] else 0)
            s2 += v * v if abs(v) > zero[i] else 0  # (a violation within the arithmetic's zero is none)
        norms[k] = float(ctx.sqrt(s2))
    return Certificate(True, "", norms, np.array([float(v) for v in xs]), states)
