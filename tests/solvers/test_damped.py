"""Weighted and damped IK (not strict hierarchies)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from baseline_cases import CASES, case

from hikbench.problems import generators as g
from hikbench.solvers.errors import SolverOptionError
from hikbench.problems.files import load
from hikbench.problems.hierarchy import Hierarchy, Level
from hikbench.problems.verify import level_norms, verify
from hikbench.solvers import registry
from hikbench.solvers.base import INFEASIBLE_LEVEL, MAX_ITERATIONS, OPTIMAL, UNSUPPORTED
from hikbench.solvers.damped import BOX_RTOL, box_limits, liegeois_gradient

DATA = Path(__file__).parent / "data"
NON_STRICT = ("weighted", "dls", "dls-liegeois")
#: verify() rtol on a consistent single-level problem: the regularisation /
#: damping biases the answer by about (lambda / sigma_min)^2
RTOL_CONSISTENT = {"weighted": 1e-8, "dls": 1e-6, "dls-liegeois": 1e-8}


def _with_box(h: Hierarchy, lo: float = -10.0, hi: float = 10.0) -> Hierarchy:
    box = Level(np.eye(h.n), np.full(h.n, lo), np.full(h.n, hi), "box")
    return Hierarchy.from_levels([box, *h], n=h.n)


@pytest.mark.parametrize("name", NON_STRICT)
def test_registered_as_non_strict(name):
    info = registry.get(name)
    assert not info.strict and info.supports_inequalities and not info.supports_warm_start


@pytest.mark.parametrize("name", NON_STRICT)
def test_consistent_single_level_is_solved(name):
    h = g.equality_stack(10, 1, 4, seed=0)
    if name == "dls-liegeois":
        h = _with_box(h)  # wide box: the limits do not bind
    res = registry.create(name).solve(h)
    assert res.status == OPTIMAL
    task = h[h.depth - 1]
    assert verify(h, res.x, np.linalg.pinv(task.A) @ task.lower, rtol=RTOL_CONSISTENT[name]).equal
    np.testing.assert_allclose(task.A @ res.x, task.lower, rtol=0, atol=RTOL_CONSISTENT[name] * 10)


@pytest.mark.parametrize("name", NON_STRICT)
@pytest.mark.parametrize("case_name", CASES)
def test_runs_on_every_case_and_is_judged_by_verification(name, case_name):
    """Status is optimal (or unsupported for dls-liegeois without a box level,
    or infeasible_level when it converged outside its box); how far x is from
    the lexicographic optimum is the verification's job, so here only: x
    finite, level norms computable, and dls-liegeois optimal only inside its box."""
    h = case(case_name)
    res = registry.create(name).solve(h)
    if name == "dls-liegeois" and box_limits(h) is None:
        assert res.status == UNSUPPORTED and "box level" in res.reason
        return
    allowed = (OPTIMAL, MAX_ITERATIONS) + ((INFEASIBLE_LEVEL,) if name == "dls-liegeois" else ())
    assert res.status in allowed, res.reason
    assert np.all(np.isfinite(level_norms(h, res.x)))
    if name == "dls-liegeois":
        _, qmin, qmax = box_limits(h)
        tol = BOX_RTOL * (1 + np.maximum(np.abs(np.where(np.isfinite(qmin), qmin, 0)),
                                         np.abs(np.where(np.isfinite(qmax), qmax, 0))))
        inside = bool(np.all((res.x >= qmin - tol) & (res.x <= qmax + tol)))
        assert (res.status == INFEASIBLE_LEVEL) == (not inside and res.status != MAX_ITERATIONS), res.reason
        if res.status == INFEASIBLE_LEVEL:
            assert "(box level) violated" in res.reason


def test_weighted_formula():
    h = g.random_hierarchy(6, 2, 3, seed=7)
    c = np.array([1.0, 0.1])
    res = registry.create("weighted", weights=c, regularization=1e-3).solve(h)
    J, e, C = h.A, h.lower, np.diag(c[h.level])
    expected = np.linalg.solve(J.T @ C @ J + 1e-3 * np.eye(6), J.T @ C @ e)  # (J^T C J + W)^-1 J^T C e
    np.testing.assert_allclose(res.x, expected, rtol=1e-10, atol=1e-12)


def test_weighted_ratio_approaches_hierarchy():
    """A small geometric ratio makes the weighted step favour level 0."""
    h = g.random_hierarchy(6, 2, 4, shared_rank=2, seed=1)  # conflicting levels
    strong = registry.create("weighted", ratio=1e-4, regularization=1e-12).solve(h).x
    even = registry.create("weighted", weights=[1.0, 1.0], regularization=1e-12).solve(h).x
    assert level_norms(h, strong)[0] < level_norms(h, even)[0]


def test_dls_formula():
    h = g.equality_stack(8, 2, 3, seed=3)
    lam = 0.3
    x = registry.create("dls", damping=lam).solve(h).x
    J, e = h.A, h.lower
    np.testing.assert_allclose(x, J.T @ np.linalg.solve(J @ J.T + lam ** 2 * np.eye(6), e), rtol=1e-10)


def test_inequality_rows_are_targets_only_when_violated():
    # one equality x0 + x1 = 2 and an inequality x0 <= 0.5 that the equality
    # alone violates (x = (1, 1)): the second pass pins x0 to 0.5
    h = Hierarchy.from_levels([Level.equality(np.array([[1.0, 1.0]]), [2.0]),
                               Level(np.array([[1.0, 0.0]]), np.array([-np.inf]), np.array([0.5]))])
    res = registry.create("weighted", weights=[1.0, 1.0], regularization=1e-12).solve(h)
    np.testing.assert_allclose(res.x, [0.5, 1.5], atol=1e-9)
    assert res.iterations == 2
    slack = Hierarchy.from_levels([Level.equality(np.array([[1.0, 1.0]]), [2.0]),
                                   Level(np.array([[1.0, 0.0]]), np.array([-np.inf]), np.array([5.0]))])
    res = registry.create("weighted", weights=[1.0, 1.0], regularization=1e-12).solve(slack)
    np.testing.assert_allclose(res.x, [1.0, 1.0], atol=1e-9)  # inactive row ignored
    assert res.iterations == 1


@pytest.mark.parametrize("name", ["weighted", "dls"])
@pytest.mark.parametrize("passes,status", [(1, MAX_ITERATIONS), (2, OPTIMAL)], ids=["limit-hit", "converged"])
def test_pass_limit_with_violated_rows_is_not_optimal(name, passes, status):
    """x0 + x1 = 2 violates x0 <= 0.5: one pass (equalities only) stops with
    that row violated (max_iterations, the reason counts it); a second pass
    targets it and converges (optimal)."""
    h = Hierarchy.from_levels([Level.equality(np.array([[1.0, 1.0]]), [2.0]),
                               Level(np.array([[1.0, 0.0]]), np.array([-np.inf]), np.array([0.5]))])
    res = registry.create(name, passes=passes).solve(h)
    assert res.status == status, res.reason
    assert res.iterations == passes
    if status == MAX_ITERATIONS:
        assert res.reason == (f"{name}: pass limit 1 reached with 1 inequality row(s) violated at x that are "
                              "not targets yet (option passes)")
        np.testing.assert_allclose(res.x[0], 1.0, atol=1e-3)  # the last iterate, the row violated
    else:
        np.testing.assert_allclose(res.x[0], 0.5, atol=1e-3)

# ------------------------------------------------------------ dls-liegeois

def test_liegeois_gradient_points_to_the_middle():
    qmin, qmax = np.array([-1.0, 0.0, -np.inf]), np.array([1.0, 4.0, 1.0])
    q = np.array([0.5, 1.0, 0.0])
    grad = liegeois_gradient(q, qmin, qmax)
    assert grad[0] < 0 and grad[1] > 0 and grad[2] == 0  # towards 0 and 2; one-sided: none
    # eq. (2) at q = 0.5 on [-1, 1]: 4 * (0 - 1) / (0.25 * 2.25)
    np.testing.assert_allclose(grad[0], 4 * (-1.0) / (0.25 * 2.25), rtol=1e-14)
    assert liegeois_gradient(np.array([0.0]), np.array([-1.0]), np.array([1.0]))[0] == 0.0
    # on a limit eq. (2) is infinite: 0 (x = 0 on a velocity bound of 0); outside: back inside
    np.testing.assert_array_equal(liegeois_gradient(np.array([0.0, 1.0]), np.array([0.0, -1.0]),
                                                    np.array([1.0, 1.0])), [0.0, 0.0])
    assert liegeois_gradient(np.array([2.0]), np.array([-1.0]), np.array([1.0]))[0] < 0


def test_box_limits_read_from_signed_unit_rows():
    A = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
    h = Hierarchy.from_levels([Level.equality(np.ones((1, 3)), [1.0]),
                               Level(A, np.array([-2.0, -3.0]), np.array([2.0, 1.0]))])
    k, qmin, qmax = box_limits(h)
    assert k == 1
    np.testing.assert_array_equal(qmin, [-1.0, -2.0, -np.inf])
    np.testing.assert_array_equal(qmax, [3.0, 2.0, np.inf])


def test_dls_liegeois_moves_away_from_limits_inside_the_null_space():
    """Task x0 + x1 = 0 (null space: x0 = -x1) under the box x0 in [-1, 3],
    x1 in [-3, 1]. Plain DLS gives x = 0; the joint-limit gradient pushes x0
    up and x1 down (towards the middles 1 and -1) along the null space only."""
    h = Hierarchy.from_levels([Level(np.eye(2), np.array([-1.0, -3.0]), np.array([3.0, 1.0]), "box"),
                               Level.equality(np.array([[1.0, 1.0]]), [0.0], "task")])
    plain = registry.create("dls").solve(h).x
    res = registry.create("dls-liegeois").solve(h)
    assert res.status == OPTIMAL
    np.testing.assert_allclose(plain, [0.0, 0.0], atol=1e-12)
    assert res.x[0] > 0.1 and res.x[1] < -0.1  # away from the limits, gradient sign
    np.testing.assert_allclose(res.x[0] + res.x[1], 0.0, atol=1e-10)  # task kept: null-space motion
    # converged where phi is stationary along the null space: symmetric box -> the middle (1, -1)
    np.testing.assert_allclose(res.x, [1.0, -1.0], atol=1e-6)


def test_weighted_without_regularisation_on_rank_deficient_task_fails_cleanly():
    h = Hierarchy.from_levels([Level.equality(np.array([[1.0, 1.0]]), [2.0])])
    res = registry.create("weighted", regularization=0.0).solve(h)
    assert res.status == "numerical_failure" and "factorisation failed" in res.reason


@pytest.mark.parametrize("seed, status, head", [
    # converges (||dx|| -> 0) in 5 iterations to max|x| ~ 6e3 on the box [-1, 1]: not optimal
    (1, INFEASIBLE_LEVEL, r"^dls-liegeois: converged in 5 iterations outside the limits: "),
    # no convergence, and the last iterate is outside the box too: the reason says both
    (0, MAX_ITERATIONS, r"^dls-liegeois: no convergence in 1000 iterations \(last \|\|dx\|\| = .*\); "),
], ids=["converged-outside-box", "max-iterations-outside-box"])
def test_dls_liegeois_outside_its_box_is_not_optimal(seed, status, head):
    """Two random problems (`hikbench generate random --param n=30 --param depth=5
    --param inequality=mixed`, seeds 0 and 1, saved in tests/solvers/data): the
    25 task rows push x far out of the level-0 box [-1, 1]^30, which the
    joint-limit gradient (null space only) cannot hold. The reason names the
    worst variable of the x returned, with its value and excess."""
    h = load(DATA / f"liegeois_outside_box_seed{seed}.npz")
    res = registry.create("dls-liegeois").solve(h)
    assert res.status == status
    assert level_norms(h, res.x)[0] > 1.0  # the box level really is violated
    worst = int(np.argmax(np.abs(res.x)))
    said = re.escape(f"level 0 (box level) violated: 30 of 30 variables outside their limits, worst "
                     f"x[{worst}] = {res.x[worst]:.6g} outside [-1, 1] by {abs(res.x[worst]) - 1:.3g}")
    assert re.match(head + said, res.reason), res.reason
    if status == INFEASIBLE_LEVEL:
        assert "the joint-limit gradient acts only in the null space of the task rows" in res.reason


def test_dls_liegeois_without_box_is_unsupported():
    res = registry.create("dls-liegeois").solve(g.equality_stack(5, 2, 2, seed=0))
    assert res.status == UNSUPPORTED
    assert "no level is a box level" in res.reason


def test_dls_liegeois_iteration_cap():
    h = _with_box(g.equality_stack(6, 1, 2, seed=0), -1.0, 2.0)
    res = registry.create("dls-liegeois", max_iter=2).solve(h)
    assert res.status == "max_iterations" and "no convergence in 2 iterations" in res.reason


@pytest.mark.parametrize("name, opts, match", [
    ("dls", {"damping": -1.0}, "damping"),
    ("weighted", {"ratio": 0.0}, "ratio"),
    ("weighted", {"weights": [1.0, np.nan]}, "weights"),
    ("dls-liegeois", {"alpha": np.inf}, "alpha"),
    ("dls-liegeois", {"max_iter": 0}, "max_iter"),
    ("dls", {"lambda_": 1.0}, "lambda_"),
], ids=["damping", "ratio", "weights", "alpha", "max_iter", "unknown"])
def test_bad_options(name, opts, match):
    with pytest.raises(SolverOptionError, match=match):
        registry.create(name, **opts)


def test_weights_length_mismatch_is_unsupported():
    res = registry.create("weighted", weights=[1.0, 2.0, 3.0]).solve(g.equality_stack(4, 2, 1, seed=0))
    assert res.status == UNSUPPORTED and "3 entries" in res.reason


def test_a_posture_task_is_not_taken_for_a_box():
    """Unit equality rows (x = target) are a task, not limits: dls-liegeois
    found no box in such a hierarchy and must say so rather than report the
    task's own violation as "outside the limits"."""
    h = Hierarchy.from_levels([Level.equality(np.ones((1, 3)), [3.0], "sum"),
                               Level.equality(np.eye(3), [0.5, 1.0, 1.5], "posture")])
    assert box_limits(h) is None
    res = registry.create("dls-liegeois").solve(h)
    assert res.status == "unsupported" and "box level" in res.reason
    # a free unit row does not make a box either; one finite inequality row does
    free = Level(np.eye(2), np.full(2, -np.inf), np.full(2, np.inf), "free")
    assert box_limits(Hierarchy.from_levels([free])) is None
    one = Level(np.eye(2), np.array([-np.inf, 0.5]), np.array([np.inf, 0.5]), "lock+free")
    assert box_limits(Hierarchy.from_levels([one])) is None  # an equality and a free row
    lim = Level(np.eye(2), np.array([-1.0, 0.5]), np.array([np.inf, 0.5]), "limit+lock")
    k, qmin, qmax = box_limits(Hierarchy.from_levels([lim]))
    assert k == 0
    np.testing.assert_array_equal(qmin, [-1.0, 0.5])
    np.testing.assert_array_equal(qmax, [np.inf, 0.5])
    # two rows on one variable (position and velocity limits): their intersection
    two = Level(np.array([[1.0, 0.0], [-1.0, 0.0]]), np.array([-2.0, -1.0]), np.array([1.0, 3.0]), "pos+vel")
    _, qmin, qmax = box_limits(Hierarchy.from_levels([two]))
    np.testing.assert_array_equal(qmin, [-2.0, -np.inf])
    np.testing.assert_array_equal(qmax, [1.0, np.inf])
