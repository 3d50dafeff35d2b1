"""Hierarchies with inequalities at any level (docs/hcod.md, "Inequalities at any level"):
the degenerate families, IK-like problems, random and deep stacks, degenerate vertices, the
minimum-norm optimum, and hypothesis draws on a grid certified in exact arithmetic
(hikbench.problems.exact). Verdicts as in hcod_checks."""

from __future__ import annotations

import hik_strategies
import numpy as np
import pytest
from hcod_checks import GRID, RTOL, RTOL_ILL, check, reference_or_reject
from hypothesis import given, settings
from hypothesis import strategies as st

from hikbench.problems import generators as G
from hikbench.problems.hierarchy import Hierarchy, Level
from hikbench.problems.verify import level_norms, verify
from hikbench.solvers.base import OPTIMAL
from hikbench.solvers.hcod import HcodSolver


@pytest.mark.parametrize("case", G.DEGENERATE_CASES)
def test_degenerate_cases(case):
    rtol = RTOL_ILL if case == "badly_scaled" else RTOL
    for seed in range(2):
        check(G.degenerate(case, n=12, seed=seed), rtol=rtol)


@pytest.mark.parametrize("n", [8, 20], ids=lambda n: f"n{n}")
def test_ik_like(n):
    for seed in range(2):
        check(G.ik_like(n, seed), rtol=RTOL)


@settings(max_examples=25, deadline=None)
@given(n=st.integers(2, 12), depth=st.integers(1, 5), rows=st.integers(0, 6),
       inequality=st.sampled_from(["none", "one-sided", "two-sided", "mixed"]), box=st.booleans(),
       eqf=st.sampled_from([0.0, 0.3]), shared=st.integers(0, 2), seed=st.integers(0, 10_000))
def test_random_hierarchies(n, depth, rows, inequality, box, eqf, shared, seed):
    h = G.random_hierarchy(n, depth, rows, inequality=inequality, box=box, equality_fraction=eqf,
                           shared_rank=min(shared, rows), seed=seed)
    check(h, x_ref=reference_or_reject(h))


def test_deep_inequality_stack():
    h = G.random_hierarchy(10, 14, 3, inequality="mixed", box=True, seed=5)
    res, _ = check(h)
    assert len(res.iterations_per_level) == 15


def test_infeasible_top_level_keeps_its_slack():
    n = 4
    e0 = np.eye(n)[:1]
    h = Hierarchy.from_levels([Level(np.vstack([e0, e0]), [1.0, -np.inf], [np.inf, -1.0]),
                               Level.equality(np.eye(n), np.arange(n, dtype=float))], n=n)
    res, _ = check(h)
    np.testing.assert_allclose(level_norms(h, res.x)[0], np.sqrt(2.0), rtol=1e-12)
    np.testing.assert_allclose(res.x[1:], [1.0, 2.0, 3.0], atol=1e-12)


def test_min_norm_with_inequalities():
    # a free direction left by inactive inequalities: x must be the minimum-norm optimum
    h = Hierarchy.from_levels([Level(np.array([[1.0, 1.0, 0.0]]), [1.0], [np.inf])], n=3)
    res = HcodSolver().solve(h)
    np.testing.assert_allclose(res.x, [0.5, 0.5, 0.0], atol=1e-12)


@pytest.mark.parametrize("seed", range(3), ids=lambda s: f"seed{s}")
def test_degenerate_vertex(seed):
    """Many inequality rows through the start point u = 0 (a degenerate vertex:
    steps of length 0, ties): no cycling, the reference optimum."""
    rng = np.random.default_rng(seed)
    n = 4
    C = rng.standard_normal((16, n))
    C = np.vstack([C, C[:4], -C[4:6] * 0.0 + C[4:6]])  # duplicates
    h = Hierarchy.from_levels([Level(C, np.full(len(C), -np.inf), np.zeros(len(C))),
                               Level.equality(np.eye(n), 3 * rng.standard_normal(n))], n=n)
    res, _ = check(h)
    assert res.iterations < 200


@pytest.mark.parametrize("seed", range(4), ids=lambda s: f"seed{s}")
def test_min_norm_x_matches_reference_with_inequalities(seed):
    """Levels that leave freedom (12 DOF, 2 levels of 3 rows, under a box): x is
    the minimum-norm lexicographic optimum, like the reference's final stage."""
    h = G.random_hierarchy(12, 2, 3, inequality="mixed", box=True, seed=seed)
    res, x_ref = check(h)
    np.testing.assert_allclose(res.x, x_ref, rtol=0, atol=1e-8 * (1 + np.linalg.norm(x_ref)))


def test_large_problems():
    """n = 80 (IK-like, cold then warm: W explicit, then factored) and n = 60
    with general rows at every level."""
    h = G.ik_like(80, 0)
    s = HcodSolver()
    _, x_ref = check(h, solver=s)
    warm = s.solve(h)
    assert verify(h, warm.x, x_ref, rtol=RTOL).equal
    check(G.random_hierarchy(60, 4, 15, inequality="mixed", box=True, seed=1))


@settings(max_examples=40, deadline=None)
@given(h=hik_strategies.hierarchies(max_n=5, max_depth=4, max_rows=4, coefficients=GRID, bounds=GRID,
                                    x0=False, min_n=1))
def test_grid_random_hierarchies_match_reference(h):
    res = HcodSolver().solve(h)
    assert res.status == OPTIMAL, res.reason
    v = verify(h, res.x, reference_or_reject(h), rtol=1e-8)
    assert v.equal or (h.has_inequalities and v.lower == "a"), v  # (see hcod_checks.check)


@settings(max_examples=150, deadline=None)
@given(h=hik_strategies.hierarchies(max_n=5, max_depth=4, max_rows=4, coefficients=GRID, bounds=GRID,
                                    x0=False, min_n=1),
       warm_start=st.sampled_from(["none", "stage"]))
def test_grid_random_hierarchies_are_the_exact_optimum(h, warm_start):
    """The grid problems above judged without a reference: the active set read off hcod's x is
    certified in exact rational arithmetic (hikbench.problems.exact: feasible, KKT with signed multipliers at
    every stage, the minimum-norm point), and hcod's level norms are its exact ones at 1e-9 of
    each level's scale. (3000 examples per mode: every one certified.)"""
    from hikbench.problems.exact import certify
    from hikbench.problems.verify import level_scales

    res = HcodSolver(warm_start=warm_start).solve(h)
    assert res.status == OPTIMAL, res.reason
    cert = certify(h, res.x)
    assert cert.certified, cert.reason
    tol = 1e-9 * level_scales(h, cert.x) + 1e-12
    assert np.all(np.abs(level_norms(h, res.x) - cert.level_norms) <= tol), (level_norms(h, res.x), cert.level_norms)
