"""hcod as a solver of the registry: its name and options (a bad option is a one-line
error), its statuses (optimal, max_iterations, numerical_failure; never an exception, never a
non-finite x), its result's fields and counters (iterations, activations, flops against the
paper's count), reset() and warmup(). docs/hcod.md: "Options", "Result"."""

from __future__ import annotations

import dataclasses
import re

import hik_strategies
import numpy as np
import pytest
from hypothesis import given, settings

from hikbench.problems import generators as G
from hikbench.problems.hierarchy import Hierarchy
from hikbench.solvers import registry
from hikbench.solvers.base import MAX_ITERATIONS, NUMERICAL_FAILURE, OPTIMAL, SolveResult
from hikbench.solvers.errors import SolverOptionError
from hikbench.solvers.hcod import HcodSolver


def test_registered():
    info = registry.get("hcod")
    assert info.supports_inequalities and info.supports_warm_start and info.strict
    assert isinstance(registry.create("hcod"), HcodSolver)


@pytest.mark.parametrize("option, value, expected", [
    ("warm_start", "always", "one of none, stage, time"),
    ("max_iterations", 0, "an integer >= 1 or None"),
    ("max_iterations", 2.5, "an integer >= 1 or None"),
    ("max_iterations", True, "an integer >= 1 or None"),
    ("rank_rtol", 2.0, "a finite number > 0 and < 1"),
    ("rank_rtol", 0.0, "a finite number > 0 and < 1"),
    ("rank_rtol", "1e-8", "a finite number > 0 and < 1"),
    ("min_norm", "yes", "True or False"),
    ("min_norm", 1, "True or False"),
], ids=["warm_start", "max_iterations-zero", "max_iterations-float", "max_iterations-bool", "rank_rtol-two",
        "rank_rtol-zero", "rank_rtol-str", "min_norm-str", "min_norm-int"])
def test_bad_options(option, value, expected):
    message = f"hcod: option {option}={value!r} is not allowed; expected {expected}"
    with pytest.raises(SolverOptionError, match="^" + re.escape(message) + "$"):
        HcodSolver(**{option: value})


def test_empty_hierarchy():
    h = Hierarchy(np.zeros((0, 3)), [], [], [], n=3, depth=2)
    res = HcodSolver().solve(h)
    assert res.status == OPTIMAL and res.iterations_per_level == (0, 0)
    np.testing.assert_array_equal(res.x, np.zeros(3))


def test_iteration_cap():
    h = G.ik_like(20, 0)
    res = HcodSolver(max_iterations=3).solve(h)
    assert res.status == MAX_ITERATIONS
    assert "iteration cap 3" in res.reason
    assert res.iterations == 3 and np.all(np.isfinite(res.x))


def test_counters():
    h = G.ik_like(20, 0)
    res = HcodSolver().solve(h)
    assert res.iterations == sum(res.iterations_per_level) + res.info["min_norm_iterations"]
    assert res.activations > 0 and res.flops > 0
    assert res.reason == "" and len(res.iterations_per_level) == h.depth
    assert np.isnan(res.build_time_s) and np.isnan(res.solve_time_s)


def test_solve_result_fields_in_order():
    """The inequality path builds its SolveResult positionally (keywords cost
    ~0.35 us per call): a reordered field would land its counters elsewhere."""
    names = [f.name for f in dataclasses.fields(SolveResult)]
    assert names == ["x", "status", "reason", "iterations", "iterations_per_level", "activations",
                     "deactivations", "flops", "build_time_s", "solve_time_s", "info"]


def test_flops_of_the_paper_example():
    """Sec. VI: m = 36 DOF, N = 6 compatible tasks of dimension n = 6.

    The paper splits the cost of task k into n (m^2 - m_f^2) for the projection
    ``J_k Z_{k-1}``, 2 n^2 m_f for the COD (19) and 3/2 (m - m_f)^2 for (30),
    m_f the DOF left free before the task, and quotes 26.9 Kflops in total.
    Summing those three terms gives 39.0 K; our counter (multiply-adds inside
    the kernels: lazy projection by the reflectors of the levels above,
    pivoted QR, solve, back-transformation) must land between the two, and a
    stack that goes on past saturation (24 levels) must cost the same."""
    h = G.equality_stack(36, 6, 6, seed=0)
    res = HcodSolver().solve(h)
    m, n = 36, 6
    terms = 0.0
    for k in range(6):
        m_f = m - k * n
        terms += n * (m * m - m_f * m_f) + 2 * n * n * m_f + 1.5 * (m - m_f) ** 2
    assert 26_900 <= res.flops <= terms
    deep = HcodSolver().solve(G.equality_stack(36, 24, 6, seed=0))
    assert deep.flops == res.flops  # levels after saturation cost nothing


@settings(max_examples=60, deadline=None)
@given(h=hik_strategies.hierarchies(max_n=5, max_depth=4, max_rows=4))
def test_never_raises_never_nan(h):
    """Any valid hierarchy, coefficients anywhere in the doubles (1e-308 .. 1e308):
    a status, never an exception, never a non-finite x."""
    s = HcodSolver()
    for _ in range(2):  # cold, then warm
        res = s.solve(h)
        assert res.status in (OPTIMAL, MAX_ITERATIONS, NUMERICAL_FAILURE)
        assert res.x is None or np.all(np.isfinite(res.x))
        if res.status != OPTIMAL:
            assert res.reason


def test_reset_and_warmup():
    from hikbench.solvers.hcod import warmup

    warmup()
    h = G.ik_like(12, 1)
    s = HcodSolver()
    cold = s.solve(h)
    warm = s.solve(h)
    assert warm.iterations < cold.iterations
    s.reset()
    again = s.solve(h)
    assert again.iterations == cold.iterations
    np.testing.assert_allclose(again.x, cold.x, atol=1e-12)
