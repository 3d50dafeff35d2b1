"""A solver of your own in the benchmark: the template of docs/adding-a-solver.md.

The numerical work is a function you already have: here the null-space
recursion of the external example (``nullspace_external.solve``: ICRA 2010,
eq. 2, numpy's SVD; A (m, n), lower / upper / level (m,)). The class around
it is what hikbench needs: a name, what it supports, options checked at
construction, and a SolveResult. Equality rows only: a problem with
inequalities is declined (``unsupported``, left out of the aggregates). Try it
without registering it:

    hikbench solve PROBLEM.npz --solver bench/examples/pinv_recursion.py:PinvRecursion
    hikbench run --suite quick --solvers hcod bench/examples/pinv_recursion.py:PinvRecursion \\
        --out results/mine
"""

from __future__ import annotations

from hikbench.bench.examples.nullspace_external import solve as nullspace_solve
from hikbench.problems.hierarchy import Hierarchy
from hikbench.solvers.base import OPTIMAL, Solver, SolveResult
from hikbench.solvers.registry import SolverInfo, check_number


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
        h = hierarchy  # A (m, n), lower, upper, level (m,), n, depth; `for level in h` gives each level
        if h.has_inequalities:
            return self.unsupported(h, "equality rows only")
        x = nullspace_solve(h.A, h.lower, h.upper, h.level, h.n, rtol=self.rcond)
        # statuses: hikbench.solvers.base.STATUSES; x is judged by the harness from x alone
        return SolveResult(x, OPTIMAL, iterations_per_level=(0,) * h.depth)


# What a package's entry point names (group "hikbench.solvers"): the solver
# then has a registry name, like the built-in ones (docs/adding-a-solver.md, "A registered name").
SOLVERS = [SolverInfo.of(PinvRecursion)]  # name, flags and option defaults read from the class
