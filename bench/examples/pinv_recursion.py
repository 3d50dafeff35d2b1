"""A solver of your own in the benchmark: the template of README, "Adding a solver".

The classical null-space recursion with numpy's SVD (ICRA 2010, eq. 2): level
k's rows are met in the least-squares sense within the null space ``Z`` of the
levels above, shapes ``A_k (m_k, n)``, ``Z (n, n - r)`` with r the rank used so
far. Equality rows only: a problem with inequalities is declined
(``unsupported``, left out of the aggregates). Try it without registering it:

    hikbench solve PROBLEM.npz --solver bench/examples/pinv_recursion.py:PinvRecursion
    hikbench run --suite quick --solvers hcod bench/examples/pinv_recursion.py:PinvRecursion \\
        --out results/mine
"""

from __future__ import annotations

import numpy as np

from problems.hierarchy import Hierarchy
from solvers.base import OPTIMAL, Solver, SolveResult
from solvers.registry import SolverInfo, check_number


class PinvRecursion(Solver):
    name = "pinv-recursion"                  # the `solver` column of results.csv
    description = "null-space recursion with numpy's SVD (equality rows only)"
    supports_inequalities = False            # the harness still sends them; solve() declines
    supports_warm_start = False              # True: the benchmark also times `warm` re-solves

    def __init__(self, rcond: float = 1e-10):
        # options are keyword arguments: `--option rcond=1e-8`, `[[settings]]` of a suite;
        # a wrong value raises SolverOptionError (one line on the command line, exit 2)
        self.rcond = check_number(self.name, "rcond", rcond, low=0.0, high=1.0, low_open=True)

    def solve(self, hierarchy: Hierarchy) -> SolveResult:
        self.check_hierarchy(hierarchy)
        if hierarchy.has_inequalities:
            return self.unsupported(hierarchy, "equality rows only")
        x, Z = np.zeros(hierarchy.n), np.eye(hierarchy.n)
        for level in hierarchy:                          # level 0 first: A, lower, upper, name
            if level.rows == 0 or Z.shape[1] == 0:
                continue
            U, s, Vt = np.linalg.svd(level.A @ Z)        # J_k Z_{k-1} = U diag(s) V^T
            r = int(np.sum(s > self.rcond * s[0])) if s.size and s[0] > 0 else 0
            x = x + Z @ (Vt[:r].T @ ((U[:, :r].T @ (level.lower - level.A @ x)) / s[:r]))
            Z = Z @ Vt[r:].T
        # statuses: solvers.base.STATUSES; x is judged by the harness from x alone
        return SolveResult(x, OPTIMAL, iterations_per_level=(0,) * hierarchy.depth)


# What a package's entry point names (group "hikbench.solvers"): the solver
# then has a registry name, like the built-in ones (README, "Adding a solver").
SOLVERS = [SolverInfo(PinvRecursion.name, PinvRecursion.description, PinvRecursion,
                      supports_inequalities=False, supports_warm_start=False, strict=True)]
