"""An exact certificate of a lexicographic solution, in rational arithmetic (python-flint).

Where two solvers disagree near a level's conditioning, double precision cannot say which one
is right. :func:`certify` reads an active set off a point x (each row inside its bounds, held
at a bound, or violated), computes the lexicographic optimum x* on that set exactly (every
float64 of A and the bounds taken as the rational it is), and proves it optimal: every stage
(each level, then the minimum-norm stage) a KKT point with exact multipliers of the right
sign. A certified x* is the exact optimum of the problem as stored; its level norms judge any
solver's, whatever their agreement with each other. Derivation: docs/verification.md.

On the active set, stage k (levels j < k done) is

    min_x 1/2 ||w_k||^2,  w_k = A_T x - t_T,   s.t.  A_H x = h_H

T the rows of level k read at a bound or violated (t their bound; an equality row its value),
H the rows of the levels above held at their stage's value ``t + w`` (ICRA 2010, eq. 35: a
nonzero optimal slack at its value, a zero one at its bound). With B an independent subset of
H and T1 of T that extends it (chosen modulo a 62-bit prime; every consequence is checked
exactly), the rows T2 = T \\ T1 are combinations of R = [B; T1]: where T2 is empty, w_k = 0;
otherwise, on pivot columns P of R (R_P square, nonsingular, and x zero off P: the same
reachable ``A x``), the stage's KKT system

    [A_TP  -I     0   ] [x_P]   [t]
    [B_P    0     0   ] [w  ] = [h]
    [0     A_TP^T B_P^T] [lam]   [0]

is square and nonsingular (one exact solve, ``fmpq_mat.solve``). A row read at a bound whose
exact slack points inside its bounds is let go for that stage, and held at its bound below
where the stage's point leaves it there. x* is the minimum-norm point of every held row,
``x* = B^T (B B^T)^-1 v``.

At x*, stage k is optimal iff ``g + sum_j lam_j a_j = 0``, g = sum of level k's violations
times their rows, lam free on the rows of the levels above with a nonzero slack (or an
equality), ``lam >= 0`` at an upper bound and ``<= 0`` at a lower one. The stage's own lam
(the KKT solve's) is checked first; where a sign is wrong (multipliers not unique: parallel or
duplicated rows at their bounds, rows weakly active), the multipliers are searched over every
row of the levels above that x* holds at a bound or a value, as the feasibility problem it is:
a float64 LP (HiGHS) proposes a support, checked exactly, else an exact NNLS (Lawson and
Hanson) decides. Every check is exact: no tolerance, no digit limit.

Only a certificate that passes every check is certified; the reason names the first check
that failed otherwise. The active set is read at each tolerance of :data:`READINGS` in turn
until one certifies. What it certifies is the stored problem: a level rank-deficient only to
float64 rounding (the ``rank_deficient`` family) has full rank in exact arithmetic and another
optimum, which the active set read off a solver's point does not give: refused. So is an x*
that no double attains (its rounding misses a level's exact norm beyond the high profile's
tolerance at x: rows independent only by ~1e-16, whose conflict the exact x*, of norm 1e12-5e16,
meets): the reason says the level is rank-deficient only to float64 rounding.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from fractions import Fraction

import numpy as np

from hikbench.problems.errors import HikbenchError
from hikbench.problems.hierarchy import Hierarchy

__all__ = ["COST_S", "READINGS", "Certificate", "certify", "estimated_seconds"]

#: row states read off x
INSIDE, AT_LOWER, AT_UPPER, EQUALITY = "inside", "lower", "upper", "equality"
#: the prime of the independence and pivot choices (the largest below 2^62); a choice it gets
#: wrong (probability ~n/2^62) fails an exact check, never passes one
_PRIME = 2**62 - 57


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
        The level norms ``||v_k(x*)||`` of the exact x*, rounded to float64 (NaN where not
        certified).
    x : ndarray, shape (n,)
        x* rounded to float64 (NaN where not certified).
    states : list of str
        The state read off the given point for each row (``inside``, ``lower``, ``upper``,
        ``equality``).
    level_norms_sq : tuple of Fraction, shape (levels,)
        The exact squared level norms ``||v_k(x*)||^2`` (empty where not certified).
    x_exact : tuple of Fraction, shape (n,)
        The exact x* (empty where not certified).
    reading : float
        The reading tolerance of :data:`READINGS` whose active set this is.
    without_rounding_entries : bool or None
        Where refused and A has entries of rounding size (at most :data:`ROUNDING_ENTRY` of their
        level's largest, e.g. a Jacobian column of rounding noise): whether, with those entries
        set to 0, x's active set is certified and x attains that optimum (the ``reason`` says
        so). It does not certify x: the stored numbers' exact optimum is another. None otherwise.
    wrong_sign_rows : tuple of int
        Where refused at a level's stage: the rows of the levels above held at a bound whose exact
        multiplier there has the wrong sign (pushed inside; :func:`certify` reads the active set
        again with them inside).
    """

    certified: bool
    reason: str
    level_norms: np.ndarray
    x: np.ndarray
    states: list = field(default_factory=list)
    level_norms_sq: tuple = ()
    x_exact: tuple = ()
    reading: float = float("nan")
    without_rounding_entries: bool | None = None
    wrong_sign_rows: tuple = ()


def _q(v: float):
    from flint import fmpq

    return fmpq(*v.as_integer_ratio())


def _to_float(q) -> float:
    """The float64 nearest the rational q (Python's int division rounds correctly; 0 or inf
    beyond the double range)."""
    p, d = int(q.p), int(q.q)
    try:
        return p / d
    except OverflowError:
        return math.copysign(math.inf, p)


def _sqrt_float(q) -> float:
    """sqrt(q) for a rational q >= 0, to float64 (~2^-100 relative before rounding)."""
    p, d = int(q.p), int(q.q)
    if p == 0:
        return 0.0
    e = (220 - p.bit_length() + d.bit_length()) // 2  # p 4^e / d has ~220 bits: its root ~110
    r = math.isqrt((p << (2 * e)) // d if e >= 0 else p // (d << (-2 * e)))
    return math.ldexp(float(r), -e) if r.bit_length() < 1000 else math.ldexp(float(r >> 200), 200 - e)


def _norm_q(v: np.ndarray):
    """||v||_2 of a float64 vector as a rational (its largest entry times the float norm of v
    divided by it: no overflow at entries of 1e308), about 1e-16 relative."""
    m = float(np.max(np.abs(v), initial=0.0))
    return _q(0.0) if m == 0 else _q(m) * _q(float(np.linalg.norm(v / m)))


class _Data:
    """The problem's numbers as rationals (fmpq) and modulo :data:`_PRIME`, and the exact
    linear algebra on them. Rows are indexed by the hierarchy's stacked row."""

    def __init__(self, h: Hierarchy):
        from flint import fmpq, fmpq_mat

        self.n, self.m = h.n, h.A.shape[0]
        self.rows, self.mod = [], []
        for row in h.A.tolist():
            pq = [v.as_integer_ratio() for v in row]
            self.rows.append([fmpq(p, q) for p, q in pq])
            self.mod.append([p * pow(q, -1, _PRIME) % _PRIME for p, q in pq])
        self.lo = [_q(v) if math.isfinite(v) else None for v in h.lower.tolist()]
        self.up = [_q(v) if math.isfinite(v) else None for v in h.upper.tolist()]
        self.A = fmpq_mat(self.m, self.n, [v for row in self.rows for v in row])

    def mat(self, rows, cols=None):
        """The fmpq_mat of the given rows (and columns), shape (len(rows), len(cols))."""
        from flint import fmpq_mat

        if cols is None:
            return fmpq_mat(len(rows), self.n, [v for i in rows for v in self.rows[i]])
        return fmpq_mat(len(rows), len(cols), [self.rows[i][q] for i in rows for q in cols])

    def dots(self, x) -> list:
        """``A x`` for an exact x (a list of n fmpq), a list of (rows,)."""
        from flint import fmpq_mat

        return (self.A * fmpq_mat(self.n, 1, list(x))).entries()

    def _rref_pivots(self, entries, r: int, c: int) -> list[int]:
        """The pivot columns of the r x c matrix ``entries`` (row-major, mod the prime)."""
        from flint import nmod_mat

        if r == 0 or c == 0:
            return []
        R, rank = nmod_mat(r, c, entries, _PRIME).rref()
        rows = R.tolist()
        pivots, j = [], 0
        for i in range(rank):
            while int(rows[i][j]) == 0:
                j += 1
            pivots.append(j)
            j += 1
        return pivots

    def independent(self, rows) -> list:
        """The greedy independent subset of ``rows``, in their order (mod the prime)."""
        rows = list(rows)
        ent = [self.mod[i][q] for q in range(self.n) for i in rows]  # (the rows as columns)
        return [rows[j] for j in self._rref_pivots(ent, self.n, len(rows))]

    def pivot_columns(self, rows) -> list[int]:
        """Columns P where the independent ``rows`` restricted to P are nonsingular."""
        return self._rref_pivots([v for i in rows for v in self.mod[i]], len(rows), self.n)


def _solve(K, b):
    """K y = b for a square fmpq_mat K, or None where K is singular."""
    try:
        return K.solve(b).entries()
    except ZeroDivisionError:
        return None


def _stage(D: _Data, B, hB, T, t, cache=None):
    """Stage k's exact slacks w on T and multipliers lam on the held rows B (values hB):
    (w, lam) with ``g + B^T lam = 0`` on every column (checked). lam is None where every
    target is met (w = 0, g = 0) and where T lies in the span of B (w from any point of the
    held set, ``cache``: B -> that point; g in the span of B, its multipliers solved only where
    a sign is asked). None where a system is singular (an independence the prime got wrong)."""
    from flint import fmpq, fmpq_mat

    zero = fmpq(0)
    R = D.independent([*B, *T])
    T1 = [i for i in R if i not in set(B)]
    if len(T1) == len(T):
        return [zero] * len(T), None
    if not T1:  # (saturated: A_T x is the same at every point of the held set)
        xh = cache.get(tuple(B)) if cache is not None else None
        if xh is None:
            xh = _stage_point(D, B, hB)
            if xh is None:
                return None
            if cache is not None:
                cache[tuple(B)] = xh
        r = (D.mat(T) * fmpq_mat(D.n, 1, xh)).entries()
        return [ri - ti for ri, ti in zip(r, t)], None
    P = D.pivot_columns([*B, *T1])
    r, nt, nb = len(P), len(T), len(B)
    N = r + nt + nb
    K = [zero] * (N * N)
    for a, i in enumerate(T):  # A_TP x_P - w = t
        for c, q in enumerate(P):
            K[a * N + c] = D.rows[i][q]
            K[(nt + nb + c) * N + r + a] = D.rows[i][q]  # A_TP^T w + ...
        K[a * N + r + a] = fmpq(-1)
    for b, i in enumerate(B):  # B_P x_P = h
        for c, q in enumerate(P):
            K[(nt + b) * N + c] = D.rows[i][q]
            K[(nt + nb + c) * N + r + nt + b] = D.rows[i][q]  # ... + B_P^T lam = 0
    y = _solve(fmpq_mat(N, N, K), fmpq_mat(N, 1, [*t, *hB, *([zero] * r)]))
    if y is None:
        return None
    w, lam = y[r:r + nt], y[r + nt:]
    # g + B^T lam = 0 on every column (on P by the solve; elsewhere as T2 lies in span R)
    res = (D.mat(T).transpose() * fmpq_mat(nt, 1, w) + (D.mat(B).transpose() * fmpq_mat(nb, 1, lam)
                                                         if nb else fmpq_mat(D.n, 1)))
    if any(v != 0 for v in res.entries()):
        return None
    return w, lam


def _stage_point(D: _Data, held_rows, values):
    """An exact x with ``A_i x = v_i`` on the independent ``held_rows`` (zero off their pivot
    columns), a list of (n,); None where singular."""
    from flint import fmpq, fmpq_mat

    x = [fmpq(0)] * D.n
    if not held_rows:
        return x
    P = D.pivot_columns(held_rows)
    y = _solve(D.mat(held_rows, P), fmpq_mat(len(values), 1, list(values)))
    if y is None:
        return None
    for q, v in zip(P, y):
        x[q] = v
    return x


def _min_norm(D: _Data, rows, values, need_z: bool = True):
    """The minimum-norm x of ``A_rows x = values`` (rows independent): ``x = B^T z``,
    ``B B^T z = v``; returns (x, z) or None where singular. Where the rows fix every direction
    (B square) x solves ``B x = v`` and z ``B^T z = x`` (entries of the data's size, not the Gram
    matrix's: ~5x faster), z only where ``need_z``."""
    from flint import fmpq, fmpq_mat

    if not rows:
        return [fmpq(0)] * D.n, []
    Bm = D.mat(rows)
    v = fmpq_mat(len(values), 1, list(values))
    if len(rows) == D.n:
        x = _solve(Bm, v)
        if x is None:
            return None
        z = _solve(Bm.transpose(), fmpq_mat(D.n, 1, x)) if need_z else None
        return (None if need_z and z is None else (x, z))
    z = _solve(Bm * Bm.transpose(), v)
    if z is None:
        return None
    return (Bm.transpose() * fmpq_mat(len(z), 1, z)).entries(), z


def _signs_ok(signs, lam) -> bool:
    """lam_j >= 0 at an upper bound (+1), <= 0 at a lower one (-1), free (0)."""
    return all(s * v >= 0 for s, v in zip(signs, lam))


def _scaled_floats(values) -> np.ndarray:
    """Rationals as float64 after one power-of-2 scaling that brings the largest near 1."""
    e = max((int(v.p).bit_length() - int(v.q).bit_length() for v in values if v != 0), default=0)
    out = []
    for v in values:
        p, d = int(v.p), int(v.q)
        out.append(p / (d << e) if e >= 0 else (p << -e) / d)
    return np.array(out, dtype=float)


def _multipliers_exist(D: _Data, g, cands) -> bool:
    """Whether ``g + sum_j lam_j a_j = 0`` has a solution with lam's signs (``cands``: (row,
    sign), sign +1 an upper bound (lam >= 0), -1 a lower one (lam <= 0), 0 free), decided
    exactly: a support proposed by a float64 LP, solved and checked exactly; else the exact
    NNLS (:func:`_nnls`)."""
    if all(v == 0 for v in g):
        return True
    if not cands:
        return False
    from scipy.optimize import linprog

    C = np.array([[_to_float(v) for v in D.rows[i]] for i, _ in cands])
    C *= np.array([s or 1 for _, s in cands], dtype=float)[:, None]
    with np.errstate(over="ignore", invalid="ignore"):
        m = np.max(np.abs(C), axis=1, keepdims=True)
        C = np.nan_to_num(C / np.where(m > 0, m, 1.0))
        gf = _scaled_floats(g)
    free = [s == 0 for _, s in cands]
    res = linprog(np.zeros(len(cands)), A_eq=C.T, b_eq=-gf, method="highs",
                  bounds=[(None, None) if f else (0, None) for f in free])
    if res.status == 0:
        lam = np.asarray(res.x)
        big = max(float(np.max(np.abs(lam))), 1e-300)
        support = [j for j in range(len(cands)) if abs(lam[j]) > 1e-9 * big]
        if _exact_on_support(D, g, [cands[j] for j in support]):
            return True
    return _nnls(D, g, cands)


def _exact_on_support(D: _Data, g, cands) -> bool:
    """Whether multipliers of the right signs on the rows of ``cands`` (made independent)
    cancel g exactly: one square solve on pivot coordinates, then every coordinate checked."""
    from flint import fmpq_mat

    rows = D.independent([i for i, _ in cands])
    if not rows:
        return False
    sign = dict(cands)
    Q = D.pivot_columns(rows)
    lam = _solve(D.mat(rows, Q).transpose(), fmpq_mat(len(Q), 1, [-g[q] for q in Q]))
    if lam is None:
        return False
    res = D.mat(rows).transpose() * fmpq_mat(len(rows), 1, lam)
    if any(r + gq != 0 for r, gq in zip(res.entries(), g)):
        return False
    return _signs_ok([sign[i] for i in rows], lam)


def _nnls(D: _Data, g, cands) -> bool:
    """Exact Lawson and Hanson NNLS (Solving Least Squares Problems, 1974, ch. 23) on
    ``min ||g + C^T lam||``, C the candidate rows times their signs, lam >= 0 on the signed
    ones, the free ones always in the passive set P; each least squares on P (independent by
    construction) solved exactly through its Gram matrix. Finite in exact arithmetic; True
    iff the residual vanishes."""
    from flint import fmpq, fmpq_mat

    sign = [s for _, s in cands]
    C = [[v * (s or 1) for v in D.rows[i]] for i, s in cands]
    Cm = fmpq_mat(len(C), D.n, [v for row in C for v in row])
    gm = fmpq_mat(D.n, 1, list(g))
    free_rows = D.independent([i for i, s in cands if s == 0])
    P = [j for j, (i, s) in enumerate(cands) if s == 0 and i in set(free_rows)]
    # (a row duplicated among the candidates: the first copy only)
    P = list(dict.fromkeys(P))

    def ls(P):
        if not P:
            return {}
        CP = fmpq_mat(len(P), D.n, [v for j in P for v in C[j]])
        z = _solve(CP * CP.transpose(), -(CP * gm))
        return None if z is None else dict(zip(P, z))

    def residual(lam):
        r = -gm
        if lam:
            idx = list(lam)
            r = r - fmpq_mat(len(idx), D.n, [v for j in idx for v in C[j]]).transpose() * fmpq_mat(
                len(idx), 1, [lam[j] for j in idx])
        return r

    lam = ls(P)
    if lam is None:
        return False
    for _ in range(10 * len(cands) + 10):
        r = residual(lam)
        if all(v == 0 for v in r.entries()):
            return True
        gains = (Cm * r).entries()
        enter = [(gains[j], j) for j in range(len(cands)) if j not in lam and sign[j] != 0 and gains[j] > 0]
        if not enter:
            return False
        best = max(enter)
        P = [*lam, best[1]]
        lam = {**lam, best[1]: fmpq(0)}
        while True:
            z = ls(P)
            if z is None:
                return False
            out = [j for j in P if sign[j] != 0 and z[j] <= 0]
            if not out:
                lam = z
                break
            alpha = min(lam[j] / (lam[j] - z[j]) for j in out if lam[j] > 0) if any(lam[j] > 0 for j in out) \
                else fmpq(0)
            lam = {j: lam[j] + alpha * (z[j] - lam[j]) for j in P}
            P = [j for j in P if sign[j] == 0 or lam[j] > 0]
            lam = {j: lam[j] for j in P}
    return False


#: seconds of :func:`certify` (one reading) per ``(n + rows)^3``, on an AMD EPYC core: the shipped
#: suites' problems took 0.05 to 1 times it (see :func:`estimated_seconds`)
COST_S = 3e-7


def estimated_seconds(h: Hierarchy) -> float:
    """The time :func:`certify` is expected to take on h when its first reading certifies, to an
    order of magnitude (:data:`COST_S` ``(n + rows)^3``: the stages' exact KKT systems and the
    minimum-norm system): 1.1 s at a robot stack of n = 38 and 117 rows (0.2-0.4 s measured),
    8.5 s at IK-like n = 80 with 225 rows (0.5-1.4 s), 3 s at equality n = 120 with 96 rows
    (0.9-1.7 s), 1 s at equality n = 30 with 20 levels of 6 rows (0.4 s)."""
    return COST_S * float(h.n + h.rows) ** 3


#: the reading tolerances :func:`certify` tries in turn (rows within them of a bound read as held)
READINGS = (1e-8, 1e-11, 1e-14, 0.0)
#: at most this many times per reading, the rows held whose exact multipliers have the wrong sign
#: at the stage that refuses are read as inside and the active set certified again (joints at their
#: limits to 1e-21, bounds of rounding size, that the exact optimum leaves by 1e-21)
RELEASES = 8


def certify(h: Hierarchy, x, rtol: float | None = None) -> Certificate:
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

    Returns
    -------
    Certificate
        The first certified reading's, else the first reading's refusal.
    """
    x = np.asarray(x, dtype=np.float64)
    if x.shape != (h.n,) or not np.all(np.isfinite(x)):
        raise HikbenchError(f"certify: x must be finite with shape ({h.n},); got shape {x.shape}")
    if rtol is not None and not (isinstance(rtol, (int, float)) and 0.0 <= rtol < 1.0):
        raise HikbenchError(f"certify: rtol must be in [0, 1); got {rtol!r}")
    D = _Data(h)
    first, tried = None, set()
    for reading in (READINGS if rtol is None else (float(rtol),)):
        cert = _certify_reading(h, D, x, reading, tried)
        if cert is None:  # (the same active set as a reading before: the same refusal)
            continue
        released: set = set()
        for _ in range(RELEASES):  # (rows held whose multipliers push them inside: read inside, again)
            if cert.certified or not cert.wrong_sign_rows:
                break
            released |= set(cert.wrong_sign_rows)
            again = _certify_reading(h, D, x, reading, tried, frozenset(released))
            if again is None:
                break
            cert = again if again.certified else cert
            if not again.certified:
                cert.wrong_sign_rows = again.wrong_sign_rows
        if cert.certified:
            return cert
        first = first or cert
    return _explain_rounding_entries(h, x, rtol, first)


#: an entry of A at most this fraction of its level's largest |entry| is of rounding size (a
#: Jacobian column of rounding noise: 2.8e-17 to 5.6e-17 beside entries of 0.2-0.6)
ROUNDING_ENTRY = 1e-15


def _explain_rounding_entries(h: Hierarchy, x: np.ndarray, rtol, refused: Certificate) -> Certificate:
    """``refused``, its reason extended where A has entries of rounding size
    (:data:`ROUNDING_ENTRY`): the certificate of x on A with those entries set to 0, and whether
    x attains that optimum (``without_rounding_entries``). x stays refused: the stored numbers'
    exact optimum moves along those entries (a gain of ~1e-17 at one level for O(1) at the
    levels below), which no double-precision solver resolves."""
    A = np.array(h.A)
    small = np.zeros(A.shape, dtype=bool)
    for k in range(h.depth):
        rows = h.level_rows(k)
        block = np.abs(A[rows])
        small[rows] = (block > 0) & (block <= ROUNDING_ENTRY * np.max(block, initial=0.0))
    if not small.any():
        return refused
    A[small] = 0.0
    clean = certify(Hierarchy(A, h.lower, h.upper, h.level, n=h.n, depth=h.depth), x, rtol)
    i, j = (int(v) for v in np.argwhere(small)[0])
    what = (f"; with the {int(small.sum())} entries of A of rounding size (|a_ij| <= "
            f"{float(np.max(np.abs(h.A[small]))):.2g}, at most {ROUNDING_ENTRY:g} of their level's largest; the "
            f"first at {_where(h, i)}, column {j}) set to 0")
    if not clean.certified:
        refused.reason += what + f", it is refused too ({clean.reason})"
        return refused
    from hikbench.problems.verify import PROFILES, judge

    attains = judge(h, x, clean.x, PROFILES["high"].rtol).lower != "b"
    refused.reason += what + (", x is the exact optimum (certified): the exact optimum of the stored numbers "
                              "uses those entries, which double precision does not resolve" if attains else
                              ", the exact optimum is certified and x does not attain it")
    refused.without_rounding_entries = attains
    return refused


def _where(h: Hierarchy, i: int) -> str:
    """``level k, row j`` of the stacked row i."""
    k = int(np.searchsorted(h.starts, i, side="right")) - 1
    return f"level {k}, row {i - h.starts[k]}"


def _row_scales(h: Hierarchy, D: _Data, x: np.ndarray) -> list:
    """Each row's scale at x, ``|a_i| X + |bound_i|`` (the larger finite bound), as rationals
    (no overflow at rows of norm 1e308), a list of (rows,). ``X = ||x||``, or where x = 0 the
    largest ``|bound_j| / |a_j|`` (1 where every bound is 0). No absolute part: the scale of a
    row multiplied by c (bounds alike) is c times its own, and A times c with x divided by c
    leaves it unchanged, so that what reads as held is the same in any units."""
    from flint import fmpq

    norms = [_norm_q(row) for row in h.A]
    bound = [max(abs(v) if v is not None else fmpq(0) for v in (lo, up)) for lo, up in zip(D.lo, D.up)]
    size = _norm_q(x)
    if size == 0:
        size = max((b / a for a, b in zip(norms, bound) if a > 0), default=fmpq(0)) or fmpq(1)
    return [a * size + b for a, b in zip(norms, bound)]


def _read_states(h: Hierarchy, D: _Data, r: list, rtol: float, scale: list) -> list[str]:
    """Each row's state at x (``r = A x``, exact): at a bound or beyond it within or past
    ``rtol`` of the row's scale reads as held there (or violated, the same target)."""
    rq = _q(rtol)
    states = []
    for i in range(D.m):
        lo, up = D.lo[i], D.up[i]
        if h.lower[i] == h.upper[i]:
            states.append(EQUALITY)
            continue
        tol = rq * scale[i]
        if up is not None and r[i] >= up - tol and (lo is None or up - r[i] <= r[i] - lo):
            states.append(AT_UPPER)
        elif lo is not None and r[i] <= lo + tol:
            states.append(AT_LOWER)
        else:
            states.append(INSIDE)
    return states


def _huge_note(x: np.ndarray, xs) -> str:
    """Where the exact x* is over 1e8 times larger than x (rows held that are independent only to
    rounding: x* meets their conflict along a direction of size ~1e-16), a note saying so."""
    size = float(np.linalg.norm(np.array([_to_float(v) for v in xs])))
    if not size > 1e8 * max(float(np.linalg.norm(x)), 1e-300):
        return ""
    return (f" (x* has norm {size:.2g}, x {float(np.linalg.norm(x)):.2g}: the rows held are independent only by "
            f"float64 rounding, a level rank-deficient only to rounding)")


def _violation(D: _Data, i: int, r):
    """The signed violation of row i at ``a_i x = r``: r - up above, r - lo below, else 0."""
    if D.up[i] is not None and r > D.up[i]:
        return r - D.up[i]
    if D.lo[i] is not None and r < D.lo[i]:
        return r - D.lo[i]
    return r * 0


def _certify_reading(h: Hierarchy, D: _Data, x: np.ndarray, rtol: float, tried: set,
                     released: frozenset = frozenset()) -> Certificate | None:
    """:func:`certify` for one reading tolerance, the rows ``released`` read as inside; None where
    its active set is one of ``tried`` (the active sets read before, to which it is added)."""
    x_q = [_q(v) for v in x.tolist()]
    scale = _row_scales(h, D, x)
    states = _read_states(h, D, D.dots(x_q), rtol, scale)
    for i in released:
        if states[i] in (AT_LOWER, AT_UPPER):
            states[i] = INSIDE
    if tuple(states) in tried:
        return None
    tried.add(tuple(states))
    nan = np.full(h.depth, np.nan)

    def fail(reason: str) -> Certificate:
        return Certificate(False, reason, nan, np.full(h.n, np.nan), states, reading=rtol)

    held: list[tuple[int, int]] = []  # (row, sign): +1 upper, -1 lower, 0 at a value
    values: list = []  # the value each held row is held at
    stages = []  # per level: (its targets T, their slacks w, the held rows B it was solved on, lam on B or None)
    basis: list[int] = []  # an independent subset of the held rows
    points: dict = {}  # a point of each independent held set a saturated stage met
    for k in range(h.depth):
        rows = range(h.starts[k], h.starts[k + 1])
        hB = [values[j] for j, (i, _) in enumerate(held) if i in set(basis)]
        B = [i for i, _ in held if i in set(basis)]
        let_go = {}  # rows read at a bound that are free on this stage: their bound
        while True:
            T = [i for i in rows if states[i] != INSIDE and i not in let_go]
            t = [D.lo[i] if states[i] in (AT_LOWER, EQUALITY) else D.up[i] for i in T]
            out = _stage(D, B, hB, T, t, points) if T else ([], None)
            if out is None:
                return fail(f"level {k}: the stage's exact KKT system is singular on the rows chosen "
                            f"independent (a choice modulo the prime that exact arithmetic refutes)")
            w, lam = out
            side = [{AT_UPPER: 1, AT_LOWER: -1, EQUALITY: 0}[states[i]] for i in T]
            # a row read at a bound whose exact slack points inside its bounds is free on this
            # stage (a row of a rank-deficient level that the others place there): the one
            # furthest inside is let go, and the stage solved again
            inside = [(-sd * wi / (scale[i] or 1), i) for i, sd, wi in zip(T, side, w) if sd * wi < 0]
            if not inside:
                break
            j = max(inside)[1]
            let_go[j] = D.lo[j] if states[j] == AT_LOWER else D.up[j]
        stages.append((T, w, B, lam))
        for i, ti, wi, sd in zip(T, t, w, side):
            held.append((i, 0 if wi != 0 or sd == 0 else sd))
            values.append(ti + wi)
        basis = D.independent([*B, *T])
        # a row let go that the stage's point leaves at its bound is held there below (an
        # inequality of a level above); one inside is free, and x* must keep it inside
        if let_go:
            held_vals = dict(zip((i for i, _ in held), values))
            xk = _stage_point(D, basis, [held_vals[i] for i in basis])
            if xk is None:
                return fail(f"level {k}: the stage's point is singular on the rows chosen independent")
            rk = D.dots(xk)
            for i, b in let_go.items():
                grown = D.independent([*basis, i])
                if len(grown) > len(basis) or rk[i] == b:  # (a value the stage leaves free, or at b)
                    held.append((i, 1 if states[i] == AT_UPPER else -1))
                    values.append(b)
                    basis = grown
                else:
                    states[i] = INSIDE
    held_vals = dict(zip((i for i, _ in held), values))
    basis = D.independent([i for i, _ in held])
    sign_of = dict(held)
    # (z's signs matter where a held row is signed, unless the free held rows span every direction:
    # then they alone cancel any gradient)
    need_z = any(sign_of[i] for i in basis) and len(D.independent([i for i, s in held if not s])) < D.n
    sol = _min_norm(D, basis, [held_vals[i] for i in basis], need_z=need_z)
    if sol is None:
        return fail("the held rows chosen independent are singular (a choice modulo the prime that "
                    "exact arithmetic refutes)")
    xs, z = sol
    r = D.dots(xs)
    # feasibility: the held rows at their values (a dependent one may not be), every other row
    # inside its bounds
    for (i, _), v in zip(held, values):
        if r[i] != v:
            return fail(f"{_where(h, i)}: held at its value by the active set read off x, but the exact "
                        f"x* misses it (its value is not reachable with the rows held with it)")
    for i, s in enumerate(states):
        if s == INSIDE and ((D.lo[i] is not None and r[i] < D.lo[i])
                            or (D.up[i] is not None and r[i] > D.up[i])):
            return fail(f"{_where(h, i)}: read as inside its bounds, but the exact x* leaves them"
                        + _huge_note(x, xs))
    viol = [_violation(D, i, r[i]) for i in range(D.m)]

    def candidates(upto: int) -> list:
        """The rows of stacked index < upto x* holds at a value (free) or at a bound (signed)."""
        out = []
        for i in range(upto):
            if h.lower[i] == h.upper[i] or viol[i] != 0:
                out.append((i, 0))
            elif D.up[i] is not None and r[i] == D.up[i]:
                out.append((i, 1))
            elif D.lo[i] is not None and r[i] == D.lo[i]:
                out.append((i, -1))
        return out

    for k, (T, w, B, lam) in enumerate(stages):
        if all(v == 0 for v in w) or not any(sign_of[i] for i in B):
            continue  # (g = 0, or multipliers of any sign: the stage's exact solve is its optimum)
        if lam is not None and _signs_ok([sign_of[i] for i in B], lam):
            continue
        from flint import fmpq_mat

        g = (D.mat(T).transpose() * fmpq_mat(len(T), 1, w)).entries()
        if lam is None and _exact_on_support(D, g, [(i, sign_of[i]) for i in B]):
            continue
        if not _multipliers_exist(D, g, candidates(int(h.starts[k]))):
            out = fail(f"level {k}: the exact x* is not optimal for its stage (no multipliers of the "
                       f"right sign cancel the gradient): the active set read off x is not the optimal one")
            if lam is not None:
                out.wrong_sign_rows = tuple(i for i, v in zip(B, lam) if sign_of[i] * v < 0)
            return out
    # the minimum-norm stage: x* + B^T lam = 0 with lam = -z
    if need_z and not _signs_ok([sign_of[i] for i in basis], [-v for v in z]) and not _multipliers_exist(
            D, xs, candidates(D.m)):
        return fail("the minimum-norm stage: the exact x* is not the minimum-norm point of the optimal set")
    sq = []
    for k in range(h.depth):
        s2 = _q(0.0)
        for i in range(h.starts[k], h.starts[k + 1]):
            s2 += viol[i] * viol[i]
        sq.append(s2)
    norms, xf = np.array([_sqrt_float(v) for v in sq]), np.array([_to_float(v) for v in xs])
    missed = _unrepresentable(h, x, xf, norms)
    if missed is not None:
        k, by = missed
        return fail(f"level {k} is rank-deficient only to float64 rounding: the exact optimum on the active set "
                    f"read off x has norm {np.linalg.norm(xf):.2g} and level norm {norms[k]:.3g}, which x* rounded "
                    f"to float64 misses by {by:.2g}, beyond 1e-9 of the level's terms at x (its rows are "
                    f"independent only in exact arithmetic: no double attains that optimum)")
    return Certificate(True, "", norms, xf, states, tuple(Fraction(int(v.p), int(v.q)) for v in sq),
                       tuple(Fraction(int(v.p), int(v.q)) for v in xs), rtol)


def _unrepresentable(h: Hierarchy, x: np.ndarray, xf: np.ndarray, norms: np.ndarray):
    """``(level, by)`` of the first level whose exact norm ``norms`` the rounded x* ``xf`` misses by
    more than the ``high`` profile's tolerance at the given point x (1e-9 of the level's terms
    there, hikbench.problems.verify.level_tolerances), else None. x*'s rounding moves each row by
    ~1e-16 of its terms at x*; beyond the terms at x only where x* is far larger than x and its
    rows cancel: levels whose rows are independent only to rounding (an x* of norm 1e13-5e16)."""
    from hikbench.problems.verify import PROFILES, level_norms, level_tolerances

    if not np.all(np.isfinite(xf)):
        return 0, math.inf
    with np.errstate(over="ignore", invalid="ignore"):
        miss = np.abs(level_norms(h, xf) - norms)
        off = np.flatnonzero(~(miss <= level_tolerances(h, x, PROFILES["high"].rtol)))
    return None if off.size == 0 else (int(off[0]), float(miss[off[0]]))
