"""Random hierarchies and the named problem families of the sweeps.

Everything is deterministic for a seed (``numpy.random.default_rng(seed)``).

Construction of a level (:func:`random_hierarchy`): its row space is spanned by
``r_k`` orthonormal directions, ``shared`` of them drawn inside the row space of
the levels above (these conflict with the higher levels) and the rest in its
orthogonal complement. When the DOF are used up (the levels above span all of
R^n) the remaining directions are drawn from the higher row space too, so the
rank of a level is ``min(r_k, n)`` and its rank in the null space of the levels
above is ``min(r_k - min(shared_k, R_k), n - R_k)`` with ``R_k`` the rank of the
levels above (a request ``shared_k > R_k`` gets ``R_k`` shared dimensions). Then

    A_k = diag(d) U diag(s) B^T,     U (m_k, r_k), B (n, r_k) orthonormal columns,
    s = logspace(0, -log10(cond), r_k),   d = row scales, log-uniform in
    [row_scale^-1/2, row_scale^1/2].

Bounds are drawn relative to each row's norm so that row scaling does not
change which constraints are active.
"""

from __future__ import annotations

from collections.abc import Sequence
from numbers import Integral

import numpy as np

from hikbench.problems.errors import HikbenchError, UnknownFamilyError
from hikbench.problems.family import Family
from hikbench.problems.hierarchy import Hierarchy, Level, check_fits_in_memory, check_sizes_fit
from hikbench.problems.schema import Number, checked, short

__all__ = ["DEGENERATE_CASES", "FAMILIES", "INEQUALITY_MIXES", "Family", "all_families", "degenerate",
           "equality_stack",
           "generate", "ik_like", "random_hierarchy"]

INEQUALITY_MIXES = ("none", "one-sided", "two-sided", "mixed")


_INTEGER = Number(integer=True, whole_floats=True)  # (3.0 is 3; 2.5, "abc", True are errors, not truncated)
_SEED = Number(0, integer=True, whole_floats=True)    # a seed of numpy.random.default_rng


def _integer(v, label: str) -> int:
    """v as an int; HikbenchError ``LABEL must be an integer; got V`` otherwise."""
    return int(checked(_INTEGER, v, label, HikbenchError))


def _seed(seed) -> int:
    """A seed of numpy.random.default_rng: an integer >= 0."""
    return int(checked(_SEED, seed, "seed", HikbenchError))


def _number(v, label: str, field: Number) -> float:
    """v as a float when it fits ``field``; HikbenchError naming ``label`` otherwise."""
    return float(checked(field, v, label, HikbenchError))


def _per_level(value, depth: int, label: str) -> list[int]:
    if value is None:
        return [None] * depth
    if np.isscalar(value):
        return [_integer(value, label)] * depth
    vals = [_integer(v, label) for v in value]
    if len(vals) != depth:
        raise HikbenchError(f"{label} has {len(vals)} entries: expected one per level ({depth})")
    return vals


def _orthonormal(rng: np.random.Generator, n: int, k: int) -> np.ndarray:
    """k random orthonormal columns in R^n, shape (n, k)."""
    if k == 0:
        return np.zeros((n, 0))
    q, r = np.linalg.qr(rng.standard_normal((n, k)))
    return q * np.sign(np.diag(r))


def _complement(Q: np.ndarray, n: int) -> np.ndarray:
    """Orthonormal basis of the orthogonal complement of span(Q), shape (n, n - rank Q)."""
    if Q.shape[1] == 0:
        return np.eye(n)
    u, s, _ = np.linalg.svd(Q, full_matrices=True)
    r = int(np.sum(s > 1e-10))
    return u[:, r:]


def _bounds(rng: np.random.Generator, mix: str, norms: np.ndarray, m: int, equality_fraction: float):
    """Bounds of m rows of the inequality mix ``mix``, scaled by the row norms; each row's
    side: 0 equality, 1 upper bound only, 2 lower bound only, 3 both."""
    c = rng.standard_normal(m) * norms
    lower, upper = c.copy(), c.copy()  # equalities by default
    if mix == "none":
        return lower, upper
    width = rng.uniform(0.2, 1.0, m) * norms
    if mix == "one-sided":
        sides = np.where(rng.random(m) < 0.5, 1, 2)
    elif mix == "two-sided":
        sides = np.full(m, 3)
    else:  # mixed
        sides = rng.integers(1, 4, m)
    sides = np.where(rng.random(m) < equality_fraction, 0, sides)
    lower = np.where(sides == 1, -np.inf, np.where(sides == 3, c - width, c))
    upper = np.where(sides == 2, np.inf, np.where(sides == 3, c + width, c))
    # one-sided rows: A x <= c - width/2 (upper) or A x >= c + width/2 (lower) keeps some active
    upper = np.where(sides == 1, c - 0.5 * width, upper)
    lower = np.where(sides == 2, c + 0.5 * width, lower)
    return lower, upper


def random_hierarchy(n: int, depth: int, rows: int | Sequence[int], *, rank=None, shared_rank=0,
                     inequality: str = "none", box: bool = False, box_bound: float = 1.0,
                     equality_fraction: float = 0.0, cond: float = 1.0, row_scale: float = 1.0,
                     seed: int = 0) -> Hierarchy:
    """A random hierarchy (see the module docstring for the construction).

    Parameters
    ----------
    n : int
        Number of variables.
    depth : int
        Number of task levels (a box level, if any, comes on top of them).
    rows : int or sequence of int
        Rows per task level.
    rank : int or sequence of int, optional
        Rank of each level (default: min(rows, n)).
    shared_rank : int or sequence of int
        Dimensions of each level's row space taken inside the row space of the
        levels above (conflicts), at most the rank of the levels above (level 0,
        with no level above, gets 0).
    inequality : {"none", "one-sided", "two-sided", "mixed"}
        Row kinds of the task levels: equalities only, ``A x <= u`` or
        ``A x >= l``, ``l <= A x <= u``, or a random mix of all.
    box : bool
        Add a level 0 ``-box_bound <= x_i <= box_bound`` on every variable.
    equality_fraction : float in [0, 1]
        Fraction of the rows of inequality levels turned into equalities.
    cond : float >= 1
        Spread of the singular values of each level (largest / smallest).
    row_scale : float >= 1
        Spread of the row norms (largest / smallest, log-uniform).
    seed : int

    Returns
    -------
    Hierarchy with ``depth`` (+1 with box) levels.
    """
    n, depth = _integer(n, "n"), _integer(depth, "depth")
    if n < 1 or depth < 0:
        raise HikbenchError(f"need n >= 1 and depth >= 0; got n={n}, depth={depth}")
    if inequality not in INEQUALITY_MIXES:
        raise HikbenchError(f"inequality must be one of {INEQUALITY_MIXES}; got {inequality!r}")
    cond = _number(cond, "cond", Number(1, unit="largest / smallest singular value of a level"))
    row_scale = _number(row_scale, "row_scale", Number(1, unit="largest / smallest row norm"))
    box_bound = _number(box_bound, "box_bound", Number(0, unit="the box is -box_bound <= x_i <= box_bound"))
    _number(equality_fraction, "equality_fraction", Number(0, 1))
    rng = np.random.default_rng(_seed(seed))
    if rows is None or not np.isscalar(rows) and not isinstance(rows, (Sequence, np.ndarray)):
        raise HikbenchError(f"rows must be an integer or a list of integers, one per level; got {short(rows)}")
    total = depth * _integer(rows, "rows") if np.isscalar(rows) else sum(_integer(v, "rows") for v in rows)
    check_sizes_fit(n, depth + bool(box), total + n * bool(box), "random_hierarchy")
    m = _per_level(rows, depth, "rows")
    if any(mk < 0 for mk in m):
        raise HikbenchError(f"rows must be >= 0 (per level); got {rows!r}")
    r = [min(mk, n) if rk is None else rk for mk, rk in zip(m, _per_level(rank, depth, "rank"))]
    if shared_rank is None:  # (rank None means full rank; shared_rank has no such meaning)
        raise HikbenchError("shared_rank must be an integer >= 0 or one per level; got None")
    sh = _per_level(shared_rank, depth, "shared_rank")
    levels = []
    if box:
        levels.append(Level(np.eye(n), -box_bound * np.ones(n), box_bound * np.ones(n), "box"))
    R_hi = np.zeros((n, 0))  # orthonormal basis of the row space of the task levels above
    for k in range(depth):
        if not 0 <= r[k] <= m[k]:
            raise HikbenchError(f"level {k}: rank {r[k]} must be in [0, rows={m[k]}]")
        if sh[k] < 0 or sh[k] > r[k]:
            raise HikbenchError(f"level {k}: shared_rank {sh[k]} must be in [0, rank={r[k]}]")
        r_eff = min(r[k], n)
        free = n - R_hi.shape[1]
        new = min(r_eff - min(sh[k], R_hi.shape[1]), free)
        shared = r_eff - new
        B_new = _complement(R_hi, n) @ _orthonormal(rng, free, new) if new else np.zeros((n, 0))
        B_sh = R_hi @ _orthonormal(rng, R_hi.shape[1], shared) if shared else np.zeros((n, 0))
        B = np.hstack([B_sh, B_new])
        U = _orthonormal(rng, m[k], r_eff)
        s = np.logspace(0, -np.log10(cond), r_eff) if r_eff else np.zeros(0)
        d = np.exp(rng.uniform(-0.5, 0.5, m[k]) * np.log(row_scale))
        A = d[:, None] * ((U * s) @ B.T) * np.sqrt(n)  # entries of order 1
        norms = np.linalg.norm(A, axis=1)
        norms = np.where(norms > 0, norms, 1.0)
        lower, upper = _bounds(rng, inequality, norms, m[k], equality_fraction)
        levels.append(Level(A, lower, upper, f"task {k}"))
        if B_new.shape[1]:
            R_hi = np.hstack([R_hi, B_new])
    return Hierarchy.from_levels(levels, n=n)


def equality_stack(n: int, depth: int, rows: int, seed: int = 0, rank: int | None = None) -> Hierarchy:
    """``depth`` equality levels of ``rows`` rows each, A entries N(0,1),
    targets N(0,1); full row rank unless ``rank`` is given (then each level is
    a random rank-``rank`` matrix with N(0,1)-like entries). The levels beyond
    sum(ranks) > n are decided by the ones above (saturated stack)."""
    n, depth, rows = (_integer(v, label) for v, label in ((n, "n"), (depth, "depth"), (rows, "rows")))
    if n < 1 or depth < 0 or rows < 0:
        raise HikbenchError(f"need n >= 1, depth >= 0, rows >= 0; got n={n}, depth={depth}, rows={rows}")
    check_sizes_fit(n, depth, depth * rows, "equality_stack")
    if rank is not None:
        rank = _integer(rank, "rank")
    rng = np.random.default_rng(_seed(seed))
    levels = []
    for k in range(depth):
        if rank is None:
            A = rng.standard_normal((rows, n))
        else:
            if not 0 <= rank <= min(rows, n):
                raise HikbenchError(f"rank {rank} must be in [0, min(rows, n) = {min(rows, n)}]")
            A = rng.standard_normal((rows, rank)) @ rng.standard_normal((rank, n)) / np.sqrt(max(rank, 1))
        levels.append(Level.equality(A, rng.standard_normal(rows), f"task {k}"))
    return Hierarchy.from_levels(levels, n=n)


def ik_like(n: int, seed: int = 0) -> Hierarchy:
    """The IK-like family of hcod's speed table (README).

    Level 0: box ``-0.5 <= x_i <= 0.5`` on every variable (identity rows);
    level 1: 6 equalities, A N(0,1), targets N(0,1); level 2: ``2n // 3``
    one-sided rows ``A x <= N(0,1) - 0.5``; level 3: 6 equalities, targets
    ``3 N(0,1)`` (they conflict with the box); level 4: posture
    ``x = 0.1 N(0,1)`` (n rows, A = I).
    """
    n = _integer(n, "n")
    if n < 1:
        raise HikbenchError(f"ik_like needs n >= 1; got {n}")
    rng = np.random.default_rng(_seed(seed))
    m2 = 2 * n // 3
    A1, b1 = rng.standard_normal((6, n)), rng.standard_normal(6)
    A2, u2 = rng.standard_normal((m2, n)), rng.standard_normal(m2) - 0.5
    A3, b3 = rng.standard_normal((6, n)), 3.0 * rng.standard_normal(6)
    b4 = 0.1 * rng.standard_normal(n)
    return Hierarchy.from_levels([
        Level(np.eye(n), -0.5 * np.ones(n), 0.5 * np.ones(n), "box"),
        Level.equality(A1, b1, "task 1"),
        Level(A2, np.full(m2, -np.inf), u2, "one-sided"),
        Level.equality(A3, b3, "task 3 (conflicting)"),
        Level.equality(np.eye(n), b4, "posture"),
    ], n=n)


DEGENERATE_CASES = ("duplicate_rows", "rank_deficient", "empty_levels", "infeasible_top",
                    "badly_scaled", "deep_inequalities", "free_rows", "saturated",
                    "equalities_in_inequality_levels")


def degenerate(case: str, n: int = 12, seed: int = 0) -> Hierarchy:
    """A degenerate hierarchy of the named case (see DEGENERATE_CASES):

    * ``duplicate_rows``: a level with a row repeated (with a conflicting
      target) and a row copied from the level above;
    * ``rank_deficient``: levels of 6 rows with rank 2 and 3;
    * ``empty_levels``: empty levels at the top, in the middle and at the end;
    * ``infeasible_top``: level 0 asks ``x_0 >= 1`` and ``x_0 <= -1`` and
      ``sum(x) >= n`` inside a box: the top level has a nonzero optimal slack;
    * ``badly_scaled``: row norms spread over 1e-4 .. 1e4;
    * ``deep_inequalities``: 12 levels of mixed inequalities under a box;
    * ``free_rows``: free rows (both bounds infinite) mixed in every level;
    * ``saturated``: 8 equality levels of 3 rows at n = 12 (sum of ranks 24 > n);
    * ``equalities_in_inequality_levels``: mixed levels where 40 % of the rows
      are equalities.
    """
    n = _integer(n, "n")
    if n < 1:
        raise HikbenchError(f"degenerate needs n >= 1; got {n}")
    rng = np.random.default_rng(_seed(seed))
    if case == "duplicate_rows":
        h = random_hierarchy(n, 3, 4, inequality="mixed", seed=seed)
        lv = list(h)
        A1 = np.vstack([lv[1].A, lv[1].A[:1], lv[0].A[:1]])
        lo1 = np.concatenate([lv[1].lower, lv[1].lower[:1] + 1.0, lv[0].lower[:1] - 1.0])
        up1 = np.concatenate([lv[1].upper, lv[1].upper[:1] + 1.0, lv[0].upper[:1] - 1.0])
        lv[1] = Level(A1, lo1, up1, "duplicates")
        return Hierarchy.from_levels(lv, n=n)
    if case == "rank_deficient":
        return random_hierarchy(n, 3, 6, rank=[2, 3, 6], inequality="mixed", box=True, seed=seed)
    if case == "empty_levels":
        h = random_hierarchy(n, 2, 4, inequality="mixed", seed=seed)
        empty = Level(np.zeros((0, n)), np.zeros(0), np.zeros(0), "empty")
        return Hierarchy.from_levels([empty, h[0], empty, h[1], empty], n=n)
    if case == "infeasible_top":
        e0 = np.zeros((1, n))
        e0[0, 0] = 1.0
        top = Level(np.vstack([e0, e0, np.ones((1, n)), np.eye(n)]),
                    np.concatenate([[1.0, -np.inf, float(n)], -0.5 * np.ones(n)]),
                    np.concatenate([[np.inf, -1.0, np.inf], 0.5 * np.ones(n)]), "infeasible")
        rest = random_hierarchy(n, 2, 4, inequality="mixed", seed=seed)
        return Hierarchy.from_levels([top, *rest], n=n)
    if case == "badly_scaled":
        return random_hierarchy(n, 4, 4, inequality="mixed", box=True, row_scale=1e8, seed=seed)
    if case == "deep_inequalities":
        return random_hierarchy(n, 12, 3, inequality="mixed", box=True, seed=seed)
    if case == "free_rows":
        h = random_hierarchy(n, 3, 4, inequality="mixed", seed=seed)
        lv = []
        for L in h:
            free = rng.standard_normal((2, n))
            lv.append(Level(np.vstack([L.A, free]), np.concatenate([L.lower, [-np.inf] * 2]),
                            np.concatenate([L.upper, [np.inf] * 2]), L.name))
        return Hierarchy.from_levels(lv, n=n)
    if case == "saturated":
        return equality_stack(n, 8, 3, seed=seed)
    if case == "equalities_in_inequality_levels":
        return random_hierarchy(n, 4, 5, inequality="mixed", equality_fraction=0.4, box=True, seed=seed)
    raise UnknownFamilyError(f"unknown degenerate case {case!r}; expected one of {', '.join(DEGENERATE_CASES)}")


FAMILIES: dict[str, Family] = {f.name: f for f in (
    Family("equality", "equality levels, A and targets N(0,1), full rank unless rank is given",
           equality_stack, {"n": 36, "depth": 6, "rows": 6, "rank": None}),
    Family("dof-sweep", "equality stack at fixed depth and task size, sweeping the DOF n",
           equality_stack, {"n": 36, "depth": 5, "rows": 6, "rank": None},
           sweep={"n": [12, 18, 24, 36, 50, 80, 120]}),
    Family("depth-sweep", "equality stack at fixed DOF, sweeping the depth past saturation",
           equality_stack, {"n": 36, "depth": 6, "rows": 6, "rank": None},
           sweep={"depth": [1, 2, 3, 4, 6, 8, 12, 16, 24]}),
    Family("ik-like", "box, 6 equalities, 2n/3 one-sided rows, 6 conflicting equalities, posture",
           ik_like, {"n": 20}, sweep={"n": [20, 40, 80]}),
    Family("random", "random hierarchy: ranks, conflicts, inequality mix, conditioning, row scaling",
           random_hierarchy, {"n": 20, "depth": 4, "rows": 5, "rank": None, "shared_rank": 0,
                              "inequality": "mixed", "box": True, "box_bound": 1.0, "equality_fraction": 0.0,
                              "cond": 1.0, "row_scale": 1.0}),
    Family("degenerate", "degenerate cases: " + ", ".join(DEGENERATE_CASES),
           degenerate, {"case": "rank_deficient", "n": 12}, sweep={"case": list(DEGENERATE_CASES)}),
)}


def all_families() -> dict[str, Family]:
    """The named families: :data:`FAMILIES` and the robot stacks'
    (``hikbench.problems.robots.testsets.ROBOT_FAMILIES``: ``robot-stack``, params
    ``stack``, ``robot`` (a name or a .urdf path), ``srdf``, ``floating_base``, ``reference``;
    pinocchio is imported on its first problem), and the test sets' ``testset`` and ``hard``
    (:func:`hikbench.problems.testset.testset_families`)."""
    from hikbench.problems.robots.testsets import ROBOT_FAMILIES  # (it imports Family from here)
    from hikbench.problems.testset import testset_families

    return {**FAMILIES, **ROBOT_FAMILIES, **testset_families()}


def generate(family: str, seed: int = 0, **params) -> Hierarchy:
    """Generate one problem of a named family (see :func:`all_families`)."""
    families = all_families()
    if family not in families:
        raise UnknownFamilyError(f"unknown family {family!r}; expected one of {', '.join(families)}")
    return families[family].generate(seed=seed, **params)
