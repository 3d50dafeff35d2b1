"""Problems at the ends of the double range: bounds scaled down to 1e-300 (the solver scales
bounds by a power of 2, docs/hcod.md "Tolerances"), rows of subnormal coefficients, pivots of
norm under 1e-150, rows from 1e-150 to 1e150 in one problem. Each is solved, or refused with a
status, never a non-finite x."""

from __future__ import annotations

import numpy as np
import pytest
from hcod_checks import RTOL

from hikbench.problems import generators as G
from hikbench.problems.hierarchy import Hierarchy, Level
from hikbench.problems.verify import level_norms, verify
from hikbench.solvers.base import OPTIMAL
from hikbench.solvers.hcod import HcodSolver
from hikbench.solvers.yardstick import yardstick_solution


def test_never_nan_on_huge_and_tiny_rows():
    rng = np.random.default_rng(1)
    A = rng.standard_normal((6, 5)) * np.array([1e-150, 1e150, 1, 1e-8, 1e8, 1])[:, None]
    h = Hierarchy.from_levels([Level(A[:3], -np.ones(3), np.ones(3)), Level.equality(A[3:], np.ones(3))], n=5)
    res = HcodSolver().solve(h)
    assert res.x is None or np.all(np.isfinite(res.x))


SCALED_CASES = {  # seeds whose `time` re-solve at bounds x 1e-9 goes wrong without the factor (below)
    "ik-like-5": lambda: G.ik_like(20, 5),
    "ik-like-11": lambda: G.ik_like(20, 11),
    "ik-like-21": lambda: G.ik_like(20, 21),
    "random-mixed-32": lambda: G.generate("random", seed=32, n=20, depth=4, rows=8, inequality="mixed"),
    "random-mixed-51": lambda: G.generate("random", seed=51, n=20, depth=4, rows=8, inequality="mixed"),
    "equality": lambda: G.equality_stack(20, 4, 6, seed=0),
}


@pytest.fixture(scope="module")
def scaled_case_reference():
    cache = {}

    def get(case):
        if case not in cache:
            h = SCALED_CASES[case]()
            cache[case] = (h, yardstick_solution(h))
        return cache[case]
    return get


@pytest.mark.parametrize("warm_start", ["none", "stage", "time"])
@pytest.mark.parametrize("scale", [1e-9, 1e-30, 1e-300], ids=lambda s: f"x{s:g}")
@pytest.mark.parametrize("case", list(SCALED_CASES))
def test_bounds_of_any_magnitude_give_the_scaled_minimisers(case, scale, warm_start, scaled_case_reference):
    """Every bound times ``scale``: the lexicographic optima are the problem's times ``scale``
    (the problem is homogeneous in (x, bounds)). hcod's tolerances have absolute parts
    (``1e-9 (||a|| (1 + ||u||) + 1)`` for a warm step) made for bounds not far below 1: unscaled,
    bounds x 1e-9 make a `time` re-solve of the same problem accept shifted points violating level
    0 by up to 7.3 times the problem's own size (15 of 60 IK-like n=20 seeds, 7 of 60 random
    mixed ones). ``._setup.load`` multiplies bounds all below 2^-10 (levels scaled) by a power
    of 2 that brings the largest into [1, 2) and divides x by it. Judged at the unscaled
    problem's scale, where verify's ``1 +`` parts are those of an O(1) problem."""
    h0, x_ref = scaled_case_reference(case)
    h = h0.with_bounds(h0.lower * scale, h0.upper * scale)
    s = HcodSolver(warm_start=warm_start)
    res = s.solve(h)
    if warm_start == "time":
        res = s.solve(h)  # (the re-solve, from the record)
    assert res.status == OPTIMAL, res.reason
    v = verify(h0, res.x / scale, x_ref, rtol=RTOL)
    assert v.equal or (h0.has_inequalities and v.lower == "a"), (v, level_norms(h0, res.x / scale))


@pytest.mark.parametrize("warm_start", ["none", "stage", "time"])
@pytest.mark.parametrize("n", [1, 2], ids=lambda n: f"n{n}")
def test_a_level_of_subnormal_rows_is_solved(n, warm_start):
    """``a x = b`` with every a_i = -2.225e-309 and b = -1.113e-308 (subnormal doubles): x_i =
    b / (n a_i) (minimum norm), the level met. Each level is scaled by ``1 / ||A_k||_F``, which
    overflows below ~5.6e-309 (the level multiplied by inf, the solve would end in
    ``numerical_failure``, "x is not finite"). The scale is at most 2^1023, which brings
    this level to a norm of 0.2-0.28."""
    a, b = -2.225e-309, -1.113e-308
    h = Hierarchy(np.full((1, n), a), [b], [b], [0])
    res = HcodSolver(warm_start=warm_start).solve(h)
    assert res.status == OPTIMAL, res.reason
    np.testing.assert_allclose(res.x, np.full(n, b / (n * a)), rtol=1e-12)
    assert level_norms(h, res.x)[0] <= 5e-324 * n


@pytest.mark.parametrize("warm_start", ["none", "stage", "time"])
def test_a_pivot_of_norm_under_1e150_gets_a_finite_reflector(warm_start):
    """n = 1. Level 0: x >= 1e-7; level 1: -10 x in [-6.745, 1], 3e-154 x >= 1e-10, -3.6e-164 x
    = -1 (a hypothesis draw of floats in [-10, 10]). Level 1 wants x larger: its two tiny rows
    are violated, and level 0's row leaves W. Scaled by the level's norm, the row of norm
    3e-154 is a pivot at its own norm (the wide-level rule), and its Householder reflector's
    ``1 / nrm^2`` overflows (mode ``none`` would end in ``numerical_failure``) unless the
    reflector scales such a vector by a power of 2 first, as it does. The optimum: x anywhere
    in [1e-7, 0.6745] meets row 0 of level 1 and leaves the tiny rows' violations the same to 1e-164."""
    h = Hierarchy([[-1.0], [-10.0], [3e-154], [-3.6e-164]], [-np.inf, -6.745, 1e-10, -1.0],
                  [-1e-7, 1.0, np.inf, -1.0], [0, 1, 1, 1])
    res = HcodSolver(warm_start=warm_start).solve(h)
    assert res.status == OPTIMAL, res.reason
    assert 1e-7 <= res.x[0] <= 0.6745 * (1 + 1e-15), res.x
    v = verify(h, res.x, yardstick_solution(h), rtol=RTOL)
    assert v.equal, v
