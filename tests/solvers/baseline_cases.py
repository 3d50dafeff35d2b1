"""Small test problems shared by the baseline-solver tests (kept small: QP
cascades cost a few ms per level)."""

from __future__ import annotations

from functools import cache

import numpy as np

from hikbench.problems import generators as g
from hikbench.problems.hierarchy import Hierarchy, Level
from hikbench.solvers.yardstick import yardstick_solution

#: name -> builder; random families and every degenerate case at n = 8
CASE_BUILDERS = {
    "rand-eq": lambda: g.random_hierarchy(8, 3, 3, seed=1),
    "rand-mixed": lambda: g.random_hierarchy(8, 3, 3, inequality="mixed", box=True, seed=2),
    "rand-two-sided": lambda: g.random_hierarchy(8, 3, 3, inequality="two-sided", seed=3),
    "rand-one-sided-conflict": lambda: g.random_hierarchy(8, 3, 3, inequality="one-sided", shared_rank=1,
                                                          seed=4),
    "ik-like-8": lambda: g.ik_like(8, seed=0),
    **{f"deg-{c}": (lambda c=c: g.degenerate(c, n=8)) for c in g.DEGENERATE_CASES},
}
CASES = tuple(CASE_BUILDERS)
#: family-sized problems for the slow tests
BIG_CASE_BUILDERS = {
    "ik-like-20": lambda: g.ik_like(20, seed=0),
    "ik-like-40": lambda: g.ik_like(40, seed=0),
    "random-20": lambda: g.generate("random", seed=0),
    "equality-36x8x6": lambda: g.equality_stack(36, 8, 6, seed=0),
}
CASE_BUILDERS.update(BIG_CASE_BUILDERS)
BIG_CASES = tuple(BIG_CASE_BUILDERS)
EQUALITY_CASES = ("rand-eq", "deg-saturated")


@cache
def case(name: str) -> Hierarchy:
    return CASE_BUILDERS[name]()


@cache
def reference(name: str) -> np.ndarray:
    return yardstick_solution(case(name))


def conditioned_stack(n: int, depth: int, rows: int, conds, target_scale: float = 1.0,
                      seed: int = 0) -> Hierarchy:
    """Equality levels ``A_k = U diag(logspace(0, -log10 cond_k)) V^T sqrt(n)``
    (U, V random orthonormal), targets N(0, target_scale^2); cond_k = 1 for
    the levels past ``len(conds)``."""
    rng = np.random.default_rng(seed)
    levels = []
    for k in range(depth):
        c = conds[k] if k < len(conds) else 1.0
        U = np.linalg.qr(rng.standard_normal((rows, rows)))[0]
        V = np.linalg.qr(rng.standard_normal((n, rows)))[0]
        A = (U * np.logspace(0, -np.log10(c), rows)) @ V.T * np.sqrt(n)
        levels.append(Level.equality(A, target_scale * rng.standard_normal(rows), f"level {k}"))
    return Hierarchy.from_levels(levels, n=n)
