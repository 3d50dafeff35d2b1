"""Classical null-space recursions (ICRA 2010 sec. IV) and pinv-all."""

from __future__ import annotations

import numpy as np
import pytest
from baseline_cases import case, conditioned_stack
from hypothesis import given
from hypothesis import strategies as st

from hikbench.problems import generators as g
from hikbench.solvers.errors import SolverOptionError
from hikbench.problems.hierarchy import Hierarchy
from hikbench.problems.verify import level_norms, level_scales, verify
from hikbench.solvers import registry
from hikbench.solvers.base import OPTIMAL, UNSUPPORTED
from hikbench.solvers.nullspace import (
    flops_cod_all_at_once,
    flops_cod_recursion,
    flops_svd_all_at_once,
    flops_svd_recursion,
)
from hikbench.solvers.yardstick import yardstick_solution

STRICT = ("nullspace-svd", "nullspace-cod")
#: verify() rtol per solver on well-conditioned equality stacks (round-off only)
RTOL = {"nullspace-svd": 1e-11, "nullspace-cod": 1e-11}

EQUALITY_PROBLEMS = {
    "equality-36x6x6": lambda: g.equality_stack(36, 6, 6, seed=0),
    "rank-deficient": lambda: g.equality_stack(12, 5, 4, rank=2, seed=1),
    "saturated": lambda: g.degenerate("saturated", n=12),
    "saturated-24x6": lambda: g.equality_stack(36, 24, 6, seed=0),
    "rand-eq": lambda: case("rand-eq"),
    "conflicting": lambda: g.random_hierarchy(12, 4, 3, shared_rank=1, seed=3),
}


@pytest.mark.parametrize("name", STRICT)
@pytest.mark.parametrize("problem", list(EQUALITY_PROBLEMS), ids=list(EQUALITY_PROBLEMS))
def test_recursion_matches_reference(name, problem):
    h = EQUALITY_PROBLEMS[problem]()
    res = registry.create(name).solve(h)
    assert res.status == OPTIMAL
    v = verify(h, res.x, yardstick_solution(h), rtol=RTOL[name])
    assert v.equal, v
    # minimum-norm solution (u_0 = 0), like the reference
    np.testing.assert_allclose(res.x, yardstick_solution(h), rtol=0, atol=1e-8 * (1 + np.linalg.norm(res.x)))


@given(n=st.integers(2, 10), depth=st.integers(1, 5), rows=st.integers(1, 4), seed=st.integers(0, 10_000))
def test_recursions_match_reference_on_random_equality_stacks(n, depth, rows, seed):
    h = g.equality_stack(n, depth, rows, seed=seed)
    x_ref = yardstick_solution(h)
    for name in STRICT:
        res = registry.create(name).solve(h)
        assert res.status == OPTIMAL
        assert verify(h, res.x, x_ref, rtol=RTOL[name]).equal, name


@pytest.mark.parametrize("name", STRICT + ("pinv-all",))
def test_inequalities_are_unsupported(name):
    h = case("rand-mixed")
    res = registry.create(name).solve(h)
    assert res.status == UNSUPPORTED
    assert res.x is None
    assert "inequality row" in res.reason and res.reason.startswith(name)


@pytest.mark.parametrize("name", STRICT + ("pinv-all",))
def test_free_rows_are_named_as_free(name):
    """A free row (no bound) is declined too, but not called an inequality."""
    inf = np.inf
    h = Hierarchy([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]], [-inf, 0.0, 0.0], [inf, 1.0, 0.0], [0, 0, 1])
    assert registry.create(name).solve(h).reason == (f"{name}: equality hierarchies only; "
                                                     "level 0 has 1 inequality row(s), 1 free row(s)")
    free = Hierarchy([[1.0, 0.0], [1.0, 1.0]], [-inf, 0.0], [inf, 0.0], [0, 1])
    assert registry.create(name).solve(free).reason.endswith("level 0 has 1 free row(s)")


def test_pinv_all_is_not_a_hierarchy():
    info = registry.get("pinv-all")
    assert not info.strict
    h = g.degenerate("saturated", n=12)  # conflicting levels: stacking averages them
    res = registry.create("pinv-all").solve(h)
    assert res.status == OPTIMAL
    v = verify(h, res.x, yardstick_solution(h))
    assert v.level == 0 and v.lower == "b"  # worse than the hierarchy at the top level
    # on a consistent stack it is the minimum-norm solution of the stacked system
    h2 = g.equality_stack(10, 2, 3, seed=2)
    x = registry.create("pinv-all").solve(h2).x
    np.testing.assert_allclose(x, np.linalg.pinv(h2.A) @ h2.lower, rtol=1e-10, atol=1e-12)


# ----------------------------------------------------------- numerical drift

def test_svd_projector_update_drifts_on_ill_conditioned_saturated_stack():
    """24 levels x 6 rows at n = 36 with level 0 of condition 1e8.

    Why it differs: update (14) forms ``(J P)^+ (J P)`` explicitly, whose
    round-off is about eps * cond(J_0) = 1e-8, so P_6 is not zero but ~1e-8
    after the 6 levels that use up the 36 DOF. The levels past saturation see
    ``J_k P_6`` with singular values ~1e-8 ||J_k|| > rank_rtol ||J_k|| and are
    "solved" through that noise: huge steps that destroy level 0. The update
    (15) ``P - Y Y^T`` with an orthonormal Y keeps P_6 at round-off (1e-15),
    the deep levels get rank 0, and the COD recursion stays within 1e-9 on
    the levels that decide x and ~1e-8 relative on the saturated ones."""
    h = conditioned_stack(36, 24, 6, conds=[1e8], seed=0)
    x_ref = yardstick_solution(h)
    svd = registry.create("nullspace-svd").solve(h)
    cod = registry.create("nullspace-cod").solve(h)
    assert svd.info["ranks"][6:] != (0,) * 18  # noise counted as rank
    assert cod.info["ranks"][6:] == (0,) * 18
    v_svd = verify(h, svd.x, x_ref, rtol=1e-9)
    assert v_svd.level == 0 and v_svd.lower == "b"  # the verification says so, at the top level
    rel_cod = np.abs(level_norms(h, cod.x) - level_norms(h, x_ref)) / level_scales(h, x_ref)
    assert rel_cod[:6].max() < 1e-9
    assert rel_cod.max() < 1e-7


def test_svd_projector_update_leaks_into_ill_conditioned_top_level():
    """4 levels x 6 rows at n = 36 (not saturated), level 0 of condition 1e8,
    targets 10 N(0,1). The inaccurate projector of (14) lets the lower levels'
    steps leak into level 0's row space: level 0's norm deviates by ~1e-8
    relative; with (15) it stays at round-off (~1e-16)."""
    h = conditioned_stack(36, 4, 6, conds=[1e8], target_scale=10.0, seed=0)
    x_ref = yardstick_solution(h)
    rel = {}
    for name in STRICT:
        x = registry.create(name).solve(h).x
        rel[name] = np.abs(level_norms(h, x) - level_norms(h, x_ref)) / level_scales(h, x_ref)
    assert rel["nullspace-svd"][0] > 1e-9
    assert verify(h, registry.create("nullspace-svd").solve(h).x, x_ref, rtol=1e-9).level == 0
    assert rel["nullspace-cod"].max() < 1e-12


# ---------------------------------------------------------------- flops

def test_flop_counts_match_paper_section_vi():
    # 36 DOF, 6 tasks of 6 rows (paper: 168, 124, 1213, 69.5 Kflops)
    assert flops_svd_recursion(36, [6] * 6) == pytest.approx(168e3, rel=0.01)
    assert flops_cod_recursion(36, [6] * 6) == pytest.approx(124e3, rel=0.02)
    assert flops_svd_all_at_once(36, 36) == pytest.approx(1213e3, rel=0.01)
    assert flops_cod_all_at_once(36, 36) == pytest.approx(69.5e3, rel=0.10)


def test_flop_formula_terms():
    # one level of r rows on n variables, terms as documented in hikbench.solvers.nullspace
    n, r = 10, 3
    assert flops_svd_recursion(n, [r]) == (n * n * r + (6 * n * r * r + 20 * r ** 3) + n * n * r
                                           + 2 * n * r + r * r + r)
    assert flops_cod_recursion(n, [r]) == round(n * n * r + 4 * r * r * (n - r / 3) + n * n * r + 2 * n * r
                                                + r * r + r * r / 2)
    assert flops_svd_recursion(n, [0, r]) == flops_svd_recursion(n, [r])


@pytest.mark.parametrize("name, fn", [("nullspace-svd", flops_svd_recursion),
                                      ("nullspace-cod", flops_cod_recursion)],
                         ids=["nullspace-svd", "nullspace-cod"])
def test_solvers_report_flops(name, fn):
    h = g.equality_stack(36, 6, 6, seed=0)
    assert registry.create(name).solve(h).flops == fn(36, [6] * 6)


def test_bad_option():
    with pytest.raises(SolverOptionError, match="rank_rtol"):
        registry.create("nullspace-svd", rank_rtol=-1)
    with pytest.raises(SolverOptionError, match="colour"):
        registry.create("nullspace-cod", colour="red")


@pytest.mark.parametrize("cls_name", ["NullspaceSVD", "NullspaceCOD"])
@pytest.mark.parametrize("rank", [3, 2, 0], ids=["full-row-rank", "rank-deficient", "zero"])
def test_pseudo_inverse_and_projector_update_formulas(cls_name, rank):
    """apply_pinv = (J P)^+ (eqs. (11) / (13)); the update term is
    (J P)^+ (J P) (eq. (14)) for SVD and Y Y^T (eq. (15)) for COD, both the
    orthogonal projector on the row space of J P."""
    import hikbench.solvers.nullspace as ns

    rng = np.random.default_rng(rank)
    M = rng.standard_normal((3, rank)) @ rng.standard_normal((rank, 7)) if rank else np.zeros((3, 7))
    solver = getattr(ns, cls_name)()
    apply_pinv, update, r = solver._step(M, thr=1e-10 * max(np.linalg.norm(M, 2), 1.0))
    assert r == rank
    pinv = np.linalg.pinv(M)
    v = rng.standard_normal(3)
    np.testing.assert_allclose(apply_pinv(v), pinv @ v, rtol=1e-10, atol=1e-12)
    if rank:
        np.testing.assert_allclose(update, pinv @ M, rtol=1e-10, atol=1e-12)
