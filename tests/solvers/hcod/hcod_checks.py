"""Checks shared by the hcod tests: the verdict against the yardstick, trajectories of
drifting problems, the grid of hypothesis draws, the saved problems (tests/solvers/data).

Every verdict is computed from x (hikbench.problems.verify), never from the solver's
status. Well-conditioned problems: level norms equal to the yardstick's to
``rtol = 1e-9`` of each level's scale, lexicographically. Ill-conditioned ones
(row norms spread over 1e8, ``cond`` up to 1e6): ``rtol = 1e-7`` (the
round-off of the projections grows with the condition number of the levels),
and where conflicting levels make x itself ill-determined (the least-squares
error ~ eps cond^2 ||residual||) only the top level is compared: the slow
conditioning sweep (test_sweeps.py), whose tally docs/verification.md quotes
("What the yardstick gives"; "Limits of double precision").
Ill-posed problems -- a level coupled to the freedom left by the levels above
only through entries ~1e-9 of its norm, near the rank threshold -- can have
lexicographic optima that differ by O(1) at a lower level while the higher
levels agree to 1e-9: there the solver and the yardstick may legitimately
disagree, and the hypothesis tests draw from a grid (:data:`GRID`) that avoids them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from hypothesis import reject
from hypothesis import strategies as st

from hikbench.problems.hierarchy import Hierarchy
from hikbench.problems.verify import level_norms, verify
from hikbench.solvers.base import OPTIMAL
from hikbench.solvers.hcod import HcodSolver
from hikbench.solvers.yardstick import YardstickError as ReferenceFailure
from hikbench.solvers.yardstick import yardstick_solution

#: the saved problems of the solver tests
DATA = Path(__file__).parents[1] / "data"
RTOL = 1e-9
RTOL_ILL = 1e-7


def reference_or_reject(h: Hierarchy):
    """The reference x; in a hypothesis test, an example the reference itself
    cannot solve (a QP backend failure) gives no verdict and is rejected."""
    try:
        return yardstick_solution(h)
    except ReferenceFailure:
        reject()


def check(h: Hierarchy, rtol: float = RTOL, solver: HcodSolver | None = None, x_ref=None):
    res = (solver or HcodSolver()).solve(h)
    assert res.status == OPTIMAL, res.reason
    assert res.x is not None and np.all(np.isfinite(res.x))
    if x_ref is None:
        x_ref = yardstick_solution(h)
    v = verify(h, res.x, x_ref, rtol=rtol)
    # With inequalities the reference is a polished QP cascade: where its x is
    # lexicographically *worse* than the solver's (which cannot happen against an exact
    # optimum), the reference missed the optimum -- e.g. random_hierarchy(10, 3, 1,
    # inequality="one-sided", equality_fraction=0.3, shared_rank=1, seed=1688): level 1 is
    # feasible (hcod: norm 0) but the reference leaves 0.47. Equality problems: exact match.
    assert v.equal or (h.has_inequalities and v.lower == "a"), (v, level_norms(h, res.x), level_norms(h, x_ref))
    return res, x_ref


def drifting(h: Hierarchy, drift: float, seed: int, steps: int = 8):
    """A trajectory from h: at each step A's nonzeros and the finite bounds move by
    ``drift`` N(0, 1) (equality rows stay equalities, upper >= lower)."""
    rng = np.random.default_rng(seed)
    A, lo, up = h.A.copy(), h.lower.copy(), h.upper.copy()
    for _ in range(steps):
        A = A + drift * rng.standard_normal(A.shape) * (A != 0)
        d = drift * rng.standard_normal(h.rows)
        lo2 = np.where(np.isfinite(lo), lo + d, lo)
        up2 = np.where(np.isfinite(up), up + d, up)
        up = np.where(lo == up, lo2, np.maximum(up2, lo2))
        lo = lo2
        yield Hierarchy(A, lo, up, h.level, n=h.n, depth=h.depth)


#: coefficients and bounds on a grid of quarters in [-10, 10]: exact degeneracies (duplicate,
#: dependent, zero rows, exact conflicts) without the tiny couplings (a 1e-200 entry) that make
#: a problem ill-posed -- there the lexicographic optimum moves by O(1) for a 1e-9 change of a
#: higher level, below any tolerance (see this module's docstring)
GRID = st.integers(-40, 40).map(lambda v: v / 4.0)
