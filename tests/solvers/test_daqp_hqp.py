"""daqp-hqp, DAQP's own hierarchical QP: agreement with hcod on the row-normalised
hierarchy it claims (random hierarchies of every row kind, the benchmark's families),
its statuses, options, warm start, and how the benchmark judges it."""

from __future__ import annotations

import numpy as np
import pytest
from hik_strategies import hierarchies
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from hikbench.problems import generators as g
from hikbench.problems.hierarchy import Hierarchy, Level, row_normalised
from hikbench.problems.verify import verify
from hikbench.solvers import registry
from hikbench.solvers.base import (
    INFEASIBLE_LEVEL,
    MAX_ITERATIONS,
    NUMERICAL_FAILURE,
    OPTIMAL,
    ROW_NORMALISED,
    ROWS,
    UNSUPPORTED,
)
from hikbench.solvers.daqp_hqp import exit_status
from hikbench.solvers.errors import SolverOptionError

#: verify() tolerance against hcod on the row-normalised hierarchy: DAQP's slacks are soft
#: (rho_soft = 1e-9, primal_tol = 1e-9 at accuracy "high": levels met to ~1e-8 of their scale on
#: most levels, but an equality level of unit rows x0 = 0, -0.99978 x0 + 0.02083 x1 = 0.16662 ends
#: at a violation of 5.4e-7, where hcod's is 0): 1e-6 absolute beside 1e-6 of the level's terms
RTOL, ATOL = 1e-6, 1e-6
KINDS = ("none", "one-sided", "two-sided", "mixed")


def _hcod(h: Hierarchy):
    res = registry.create("hcod").solve(h)
    assert res.status == OPTIMAL, res.reason
    return res.x


def _agrees(h: Hierarchy, x) -> bool:
    hn = row_normalised(h)
    return verify(hn, x, _hcod(hn), rtol=RTOL, atol=ATOL).equal


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("box", [False, True], ids=["no-box", "box"])
def test_agrees_with_hcod_on_random_hierarchies_of_every_row_kind(kind, box):
    for seed in range(6):
        h = g.random_hierarchy(10, 3, [3, 4, 5], inequality=kind, box=box, equality_fraction=0.3,
                               shared_rank=[0, 1, 2], row_scale=100.0, seed=seed)
        res = registry.create("daqp-hqp").solve(h)
        assert res.status == OPTIMAL, (seed, res.reason)
        assert _agrees(h, res.x), seed


#: coefficients 0 or of magnitude 0.1..10: a row of norm 1e-78 (hypothesis' moderate floats) is
#: a row of norm 1 once normalised, which DAQP, scaling rows in floating point, does not meet
#: as hcod does on the normalised hierarchy
WELL_SCALED = st.one_of(st.just(0.0), st.floats(0.1, 10.0), st.floats(-10.0, -0.1))


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(hierarchies(max_n=5, max_depth=4, max_rows=3, coefficients=WELL_SCALED,
                   bounds=st.floats(-5.0, 5.0), names=False, x0=False, min_n=1))
@example(Hierarchy.from_levels([Level.equality(np.array([[1.0, 0.0], [-6.0, 0.125]]), [0.0, 1.0])]))  # (5.4e-7: ATOL)
def test_agrees_with_hcod_on_hypothesis_hierarchies(h):
    res = registry.create("daqp-hqp").solve(h)
    if res.status != OPTIMAL:
        # DAQP's own failure, said as one (exit 3 on 4 of 1500 such hierarchies, e.g. a level 0
        # holding one row twice with bounds x <= 1e-45 and x >= 1e-6): never a wrong "optimal"
        assert res.status == INFEASIBLE_LEVEL and res.reason.startswith("daqp-hqp: DAQP exit 3"), res.reason
        return
    assert _agrees(h, res.x)


@pytest.mark.parametrize("problem", ["equality-36x6x6", "ik-like-20", "ik-like-40", "depth-12-two-sided",
                                     *g.DEGENERATE_CASES])
def test_agrees_with_hcod_on_the_benchmark_families(problem):
    make = {"equality-36x6x6": lambda: g.equality_stack(36, 6, 6, seed=0),
            "ik-like-20": lambda: g.ik_like(20, seed=1), "ik-like-40": lambda: g.ik_like(40, seed=0),
            "depth-12-two-sided": lambda: g.random_hierarchy(36, 12, 6, inequality="two-sided", seed=0)}
    h = make[problem]() if problem in make else g.degenerate(problem, n=12, seed=0)
    res = registry.create("daqp-hqp").solve(h)
    assert res.status == OPTIMAL, res.reason
    assert _agrees(h, res.x)


def test_a_conflicting_level_is_met_on_normalised_rows_not_on_the_rows_as_given():
    # level 1: x = 2 and 10 x = 0 conflict; normalised rows: x = 2 and x = 0 -> x = 1;
    # as given: min (x - 2)^2 + (10 x)^2 -> x = 2/101
    h = Hierarchy.from_levels([Level.equality(np.array([[1.0], [10.0]]), [2.0, 0.0])])
    res = registry.create("daqp-hqp").solve(h)
    np.testing.assert_allclose(res.x, [1.0], atol=1e-6)
    assert verify(row_normalised(h), res.x, [1.0], rtol=1e-6).equal
    assert not verify(h, res.x, [2.0 / 101.0], rtol=1e-6).equal


def test_its_claim_follows_the_option_normalised():
    info = registry.get("daqp-hqp")
    assert registry.create("daqp-hqp").judged_on == ROW_NORMALISED
    assert registry.create("daqp-hqp", normalised=False).judged_on == ROWS
    assert info.judged_on(info.options) == ROW_NORMALISED
    assert info.judged_on({**info.options, "normalised": False}) == ROWS


def test_iteration_cap_is_a_max_iterations_status():
    res = registry.create("daqp-hqp", iter_limit=2).solve(g.ik_like(20, seed=0))
    assert res.status == MAX_ITERATIONS
    assert "iteration limit, 2" in res.reason


@pytest.mark.parametrize("exitflag, iterations, status", [
    (1, 5, OPTIMAL), (2, 5, OPTIMAL), (3, 5, INFEASIBLE_LEVEL), (3, 100, MAX_ITERATIONS),
    (-1, 5, INFEASIBLE_LEVEL), (-2, 5, NUMERICAL_FAILURE), (-4, 100, MAX_ITERATIONS), (-6, 0, NUMERICAL_FAILURE),
    (-8, 0, UNSUPPORTED), (-99, 0, NUMERICAL_FAILURE),
], ids=["optimal", "soft-optimal", "level-failed", "level-at-cap", "infeasible", "cycle", "iterlimit",
        "overdetermined", "unsupported", "unknown"])
def test_daqp_exit_flags_map_to_statuses(exitflag, iterations, status):
    assert exit_status(exitflag, iterations, iter_limit=100)[0] == status


@pytest.mark.parametrize("row", [np.ones((1, 3)), np.zeros((1, 3))], ids=["free-row", "zero-row"])
def test_a_hierarchy_constraining_nothing_gives_x_zero(row):
    h = Hierarchy(row, [-np.inf] if row.any() else [1.0], [np.inf], [0], depth=2)
    res = registry.create("daqp-hqp").solve(h)
    assert res.status == OPTIMAL
    np.testing.assert_array_equal(res.x, np.zeros(3))


def test_warm_re_solve_starts_from_the_last_multipliers_and_stays_right():
    h = g.ik_like(20, seed=1)
    warm, cold = registry.create("daqp-hqp"), registry.create("daqp-hqp", warm_start="none")
    first, again = warm.solve(h), warm.solve(h)
    c1, c2 = cold.solve(h), cold.solve(h)
    assert not first.info["warm_started"] and again.info["warm_started"] and not c2.info["warm_started"]
    assert again.iterations <= first.iterations and c2.iterations == c1.iterations
    assert _agrees(h, again.x)
    other = g.ik_like(12, seed=0)  # (another shape: cold again)
    assert not warm.solve(other).info["warm_started"]


@pytest.mark.parametrize("options, match", [
    ({"eps": 0.0}, "eps=0.0"), ({"rho_soft": -1.0}, "rho_soft"), ({"accuracy": "best"}, "accuracy"),
    ({"normalised": 1}, "normalised"), ({"iter_limit": 0}, "iter_limit"), ({"warm_start": "stage"}, "warm_start"),
], ids=["eps", "rho_soft", "accuracy", "normalised", "iter_limit", "warm_start"])
def test_wrong_option_values_are_refused_naming_the_option(options, match):
    with pytest.raises(SolverOptionError, match=match):
        registry.create("daqp-hqp", **options)


def test_list_solvers_shows_it(capsys):
    from hikbench.bench.cli import main

    assert main(["list", "solvers"]) == 0
    assert "daqp-hqp" in capsys.readouterr().out


@pytest.fixture(scope="module")
def reach_steps():
    """The reach scenario's hierarchies (talos) at steps 26 and 27 of hcod's closed loop: the
    right hand out of reach (level 3's slack nonzero) and arm joints at their velocity limits."""
    pytest.importorskip("pinocchio")
    from hikbench.bench.scenarios.runner import run_scenario
    from hikbench.problems.robots.scenarios import load_scenario

    steps = []
    run_scenario(load_scenario("reach"), "hcod", {}, warm_start="time", steps=28, repeat=1,
                 on_step=lambda k, h, res: steps.append(h))
    return steps[26:28]


def test_on_the_reach_stack_its_limits_hold_while_every_level_is_met(reach_steps):
    # levels 0-2 (joint and velocity limits, CoM, feet) are all met: daqp-hqp meets the limits
    # exactly and returns hcod's point; the error of docs/peers.md ("daqp-hqp on the reach
    # scenario") comes in only with the levels below, whose slacks are nonzero
    from hikbench.problems.verify import violation

    for h in reach_steps:
        assert h.names[:3] == ("joint_limits", "com", "feet")
        keep = h.level <= 2
        met = Hierarchy(h.A[keep], h.lower[keep], h.upper[keep], h.level[keep])
        res = registry.create("daqp-hqp").solve(met)
        assert res.status == OPTIMAL, res.reason
        assert violation(met, res.x)[met.level == 0].max() <= 1e-12
        assert _agrees(met, res.x)
        full = registry.create("daqp-hqp").solve(h)
        assert full.status in (OPTIMAL, INFEASIBLE_LEVEL) and full.x is not None
        # (measured: 1.3e-8 and 2.2e-8 above the limits, the scenario's check allows 1e-9)
        assert violation(h, full.x)[h.level == 0].max() <= 1e-6
