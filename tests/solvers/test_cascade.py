"""Cascades of QPs: lexicographic agreement with the independent reference,
per backend, freeze mode and accuracy profile; failure modes as statuses.

Every (solver, profile, freeze, case) runs; the outcome is ``"ok"`` (status
optimal and :func:`hikbench.problems.verify.verify` finds no level that differs beyond
the tolerance of :data:`RTOL`), ``"differs"`` (status optimal but the
verification finds a level that differs: a wrong answer) or the status. The
expected outcome is ``"ok"`` unless :data:`KNOWN` records otherwise — those
entries are the backend failures observed where numpy's OpenBLAS runs its
"Haswell" kernels (AVX2 AMD EPYCs, and an AVX-512 Zen 5 whose environment
sets OPENBLAS_CORETYPE=Haswell; qpsolvers 4.13, osqp 1.1, proxsuite 0.8, clarabel 0.11,
daqp, quadprog, piqp 0.7, highspy), with the outcomes seen where it runs its
AVX-512 "SkylakeX" kernels (an AMD EPYC Zen 4, an Intel Xeon) in
:data:`KNOWN_SKYLAKEX`. On these borderline cases which frozen set a backend
calls infeasible follows the CPU's rounding, so every machine accepts "ok" or
the outcomes seen on either kind: a case that was "ok" on both and fails, or a
wrong answer ("differs") where none was seen, still shows up.
"""

from __future__ import annotations

import importlib
import re

import numpy as np
import pytest
from baseline_cases import BIG_CASES, CASES, case, reference
from hypothesis import assume, example, given, settings
from hypothesis import strategies as st

from hikbench.problems import generators as g
from hikbench.solvers.errors import SolverNotFoundError, SolverOptionError
from hikbench.problems.hierarchy import Hierarchy, Level
from hikbench.problems.verify import level_norms, verify
from hikbench.solvers import _qp_backends as tables
from hikbench.solvers import cascade, registry
from hikbench.solvers.base import ERROR, INFEASIBLE_LEVEL, MAX_ITERATIONS, NUMERICAL_FAILURE, OPTIMAL
from hikbench.solvers.yardstick import yardstick_solution

QP_SOLVERS = tuple(info.name for info in cascade.SOLVERS)
ALL_CASCADES = QP_SOLVERS + ("cascade-cvxpy",)

#: verify() rtol per accuracy profile and solver (10x the worst deviation seen
#: on CASES, rounded up to a decade). Level tolerance = rtol * level scale.
RTOL = {
    "high": {"cascade-osqp": 1e-8, "cascade-proxqp": 1e-8, "cascade-clarabel": 1e-8, "cascade-daqp": 1e-8,
             "cascade-quadprog": 1e-8, "cascade-piqp": 1e-7, "cascade-highs": 1e-6, "cascade-cvxpy": 1e-8},
    "default": {"cascade-osqp": 1e-3, "cascade-proxqp": 1e-3, "cascade-clarabel": 1e-8, "cascade-daqp": 1e-7,
                "cascade-quadprog": 1e-8, "cascade-piqp": 1e-7, "cascade-highs": 1e-6, "cascade-cvxpy": 1e-8},
    "low": {"cascade-osqp": 1e-4, "cascade-proxqp": 1e-3, "cascade-clarabel": 1e-5, "cascade-daqp": 1e-7,
            "cascade-quadprog": 1e-8, "cascade-piqp": 1e-3, "cascade-highs": 1e-6, "cascade-cvxpy": 1e-5},
}
#: freeze="relaxed" lets every frozen row move by delta (1e-9 at "high"); an
#: exact backend (quadprog) uses all of it, so its deeper levels move further.
RTOL_RELAXED = {"cascade-quadprog": 1e-5}

# (solver, profile, freeze, case) -> expected outcome when not "ok"
# Most are cascades that find a frozen level set infeasible (redundant frozen
# equalities that agree only up to round-off, or a feasible set shrunk to a
# point), iteration caps, and HiGHS returning "optimal" for a wrong x.
KNOWN: dict[tuple[str, str, str, str], str | tuple[str, ...]] = {
    # not reproducible run to run (4 of 5 runs infeasible): either outcome accepted
    ("cascade-proxqp", "low", "shift", "deg-deep_inequalities"): ("infeasible_level", "ok"),
    ("cascade-osqp", "high", "shift", "deg-badly_scaled"): "infeasible_level",
    ("cascade-osqp", "high", "shift", "deg-saturated"): "infeasible_level",
    ("cascade-osqp", "high", "equality", "deg-badly_scaled"): "infeasible_level",
    ("cascade-osqp", "high", "equality", "deg-saturated"): "max_iterations",
    ("cascade-osqp", "high", "relaxed", "deg-badly_scaled"): "infeasible_level",
    ("cascade-osqp", "default", "shift", "deg-badly_scaled"): "infeasible_level",
    ("cascade-osqp", "default", "shift", "deg-deep_inequalities"): "max_iterations",
    ("cascade-osqp", "default", "shift", "deg-equalities_in_inequality_levels"): "max_iterations",
    ("cascade-osqp", "low", "shift", "deg-badly_scaled"): "infeasible_level",
    ("cascade-osqp", "low", "shift", "deg-deep_inequalities"): "max_iterations",
    # ok where the CPU has no AVX-512 (proxsuite takes its AVX2 code path: other rounding)
    ("cascade-proxqp", "high", "shift", "deg-rank_deficient"): ("infeasible_level", "ok"),
    ("cascade-proxqp", "high", "shift", "deg-badly_scaled"): "infeasible_level",
    ("cascade-proxqp", "high", "shift", "deg-deep_inequalities"): "infeasible_level",
    ("cascade-proxqp", "high", "equality", "deg-badly_scaled"): "infeasible_level",
    ("cascade-proxqp", "high", "relaxed", "ik-like-8"): "infeasible_level",
    ("cascade-proxqp", "high", "relaxed", "deg-infeasible_top"): "infeasible_level",
    ("cascade-proxqp", "high", "relaxed", "deg-badly_scaled"): "infeasible_level",
    ("cascade-proxqp", "high", "relaxed", "deg-deep_inequalities"): "infeasible_level",
    ("cascade-proxqp", "high", "relaxed", "deg-saturated"): "infeasible_level",
    ("cascade-proxqp", "default", "shift", "deg-infeasible_top"): "infeasible_level",
    ("cascade-proxqp", "default", "shift", "deg-badly_scaled"): "infeasible_level",
    ("cascade-proxqp", "default", "shift", "deg-deep_inequalities"): "infeasible_level",
    ("cascade-proxqp", "default", "shift", "deg-equalities_in_inequality_levels"): "infeasible_level",
    ("cascade-proxqp", "low", "shift", "deg-badly_scaled"): "infeasible_level",
    ("cascade-proxqp", "low", "shift", "deg-equalities_in_inequality_levels"): "infeasible_level",
    ("cascade-clarabel", "high", "shift", "deg-badly_scaled"): "numerical_failure",
    ("cascade-clarabel", "high", "equality", "ik-like-8"): "infeasible_level",
    ("cascade-clarabel", "high", "equality", "deg-badly_scaled"): "numerical_failure",
    ("cascade-clarabel", "high", "relaxed", "deg-badly_scaled"): "numerical_failure",
    ("cascade-clarabel", "default", "shift", "ik-like-8"): "infeasible_level",
    ("cascade-clarabel", "low", "shift", "ik-like-8"): "infeasible_level",
    ("cascade-daqp", "high", "shift", "deg-badly_scaled"): "infeasible_level",
    ("cascade-daqp", "high", "shift", "deg-deep_inequalities"): "infeasible_level",
    ("cascade-daqp", "high", "shift", "deg-equalities_in_inequality_levels"): "infeasible_level",
    ("cascade-daqp", "high", "equality", "deg-badly_scaled"): "infeasible_level",
    ("cascade-daqp", "high", "equality", "deg-deep_inequalities"): "infeasible_level",
    ("cascade-daqp", "high", "relaxed", "deg-badly_scaled"): "infeasible_level",
    ("cascade-daqp", "high", "relaxed", "deg-deep_inequalities"): "infeasible_level",
    ("cascade-daqp", "high", "relaxed", "deg-saturated"): "infeasible_level",
    ("cascade-daqp", "default", "shift", "deg-badly_scaled"): "infeasible_level",
    ("cascade-daqp", "default", "shift", "deg-equalities_in_inequality_levels"): "infeasible_level",
    ("cascade-daqp", "low", "shift", "deg-badly_scaled"): "infeasible_level",
    ("cascade-daqp", "low", "shift", "deg-equalities_in_inequality_levels"): "infeasible_level",
    ("cascade-quadprog", "high", "shift", "ik-like-8"): "infeasible_level",
    ("cascade-quadprog", "high", "shift", "deg-rank_deficient"): "infeasible_level",
    ("cascade-quadprog", "high", "shift", "deg-infeasible_top"): "infeasible_level",
    ("cascade-quadprog", "high", "shift", "deg-badly_scaled"): "infeasible_level",
    ("cascade-quadprog", "high", "shift", "deg-deep_inequalities"): "infeasible_level",
    ("cascade-quadprog", "high", "shift", "deg-saturated"): "infeasible_level",
    ("cascade-quadprog", "high", "shift", "deg-equalities_in_inequality_levels"): "infeasible_level",
    ("cascade-quadprog", "high", "equality", "ik-like-8"): "infeasible_level",
    ("cascade-quadprog", "high", "equality", "deg-rank_deficient"): "infeasible_level",
    ("cascade-quadprog", "high", "equality", "deg-infeasible_top"): "infeasible_level",
    ("cascade-quadprog", "high", "equality", "deg-deep_inequalities"): "infeasible_level",
    ("cascade-quadprog", "high", "equality", "deg-saturated"): "infeasible_level",
    ("cascade-quadprog", "high", "equality", "deg-equalities_in_inequality_levels"): "infeasible_level",
    ("cascade-quadprog", "default", "shift", "ik-like-8"): "infeasible_level",
    ("cascade-quadprog", "default", "shift", "deg-rank_deficient"): "infeasible_level",
    ("cascade-quadprog", "default", "shift", "deg-infeasible_top"): "infeasible_level",
    ("cascade-quadprog", "default", "shift", "deg-badly_scaled"): "infeasible_level",
    ("cascade-quadprog", "default", "shift", "deg-deep_inequalities"): "infeasible_level",
    ("cascade-quadprog", "default", "shift", "deg-saturated"): "infeasible_level",
    ("cascade-quadprog", "default", "shift", "deg-equalities_in_inequality_levels"): "infeasible_level",
    ("cascade-quadprog", "low", "shift", "ik-like-8"): "infeasible_level",
    ("cascade-quadprog", "low", "shift", "deg-rank_deficient"): "infeasible_level",
    ("cascade-quadprog", "low", "shift", "deg-infeasible_top"): "infeasible_level",
    ("cascade-quadprog", "low", "shift", "deg-badly_scaled"): "infeasible_level",
    ("cascade-quadprog", "low", "shift", "deg-deep_inequalities"): "infeasible_level",
    ("cascade-quadprog", "low", "shift", "deg-saturated"): "infeasible_level",
    ("cascade-quadprog", "low", "shift", "deg-equalities_in_inequality_levels"): "infeasible_level",
    ("cascade-piqp", "high", "shift", "deg-badly_scaled"): "max_iterations",
    ("cascade-piqp", "high", "equality", "ik-like-8"): "max_iterations",
    ("cascade-piqp", "high", "equality", "deg-badly_scaled"): "max_iterations",
    ("cascade-piqp", "high", "relaxed", "deg-rank_deficient"): "max_iterations",
    ("cascade-piqp", "high", "relaxed", "deg-badly_scaled"): "max_iterations",
    ("cascade-piqp", "default", "shift", "deg-deep_inequalities"): "max_iterations",
    ("cascade-piqp", "low", "shift", "deg-badly_scaled"): "max_iterations",
    ("cascade-piqp", "low", "shift", "deg-deep_inequalities"): "max_iterations",
    ("cascade-highs", "high", "shift", "deg-badly_scaled"): "differs",
    ("cascade-highs", "high", "equality", "rand-mixed"): "differs",
    ("cascade-highs", "high", "equality", "deg-duplicate_rows"): "differs",
    ("cascade-highs", "high", "equality", "deg-badly_scaled"): "differs",
    ("cascade-highs", "high", "equality", "deg-free_rows"): "differs",
    ("cascade-highs", "high", "relaxed", "ik-like-8"): "infeasible_level",
    ("cascade-highs", "high", "relaxed", "deg-infeasible_top"): "infeasible_level",
    ("cascade-highs", "high", "relaxed", "deg-badly_scaled"): "differs",
    ("cascade-highs", "high", "relaxed", "deg-deep_inequalities"): "infeasible_level",
    ("cascade-highs", "high", "relaxed", "deg-saturated"): "infeasible_level",
    ("cascade-highs", "default", "shift", "deg-badly_scaled"): "differs",
    ("cascade-highs", "low", "shift", "deg-badly_scaled"): "differs",
    ("cascade-cvxpy", "high", "shift", "deg-badly_scaled"): "error",
    ("cascade-cvxpy", "high", "equality", "ik-like-8"): "infeasible_level",
    ("cascade-cvxpy", "high", "equality", "deg-badly_scaled"): "error",
    ("cascade-cvxpy", "high", "relaxed", "deg-badly_scaled"): "error",
    ("cascade-cvxpy", "default", "shift", "ik-like-8"): "infeasible_level",
    ("cascade-cvxpy", "low", "shift", "ik-like-8"): "infeasible_level",
}

# The outcomes that differ where numpy's OpenBLAS runs its SkylakeX kernels (an AMD EPYC Zen 4, the same package versions, three runs gave the same; an AMD EPYC
# Zen 5 with these kernels gives the same but osqp's first entry): the test problems and the backends'
# NumPy steps round differently and, on these borderline cases, so does which frozen set they
# call infeasible.
KNOWN_SKYLAKEX: dict[tuple[str, str, str, str], str | tuple[str, ...]] = {
    # "ok" on the Zen 4; on the Zen 5 with SkylakeX kernels level 0 is 1.9e-3 above the optimum
    # (within the tolerance) and level 4 lower by 1.02 times its tolerance: either accepted
    ("cascade-osqp", "default", "shift", "deg-equalities_in_inequality_levels"): ("ok", "differs"),
    ("cascade-proxqp", "high", "shift", "rand-mixed"): "differs",  # level 3 1.6e-5 above the reference
    ("cascade-proxqp", "high", "shift", "deg-rank_deficient"): "ok",
    ("cascade-proxqp", "high", "equality", "rand-mixed"): "differs",
    ("cascade-proxqp", "high", "equality", "deg-deep_inequalities"): "infeasible_level",
    ("cascade-proxqp", "high", "relaxed", "rand-mixed"): "differs",
    ("cascade-proxqp", "default", "shift", "deg-rank_deficient"): "infeasible_level",
    ("cascade-proxqp", "default", "shift", "deg-infeasible_top"): "ok",
    ("cascade-proxqp", "default", "shift", "deg-equalities_in_inequality_levels"): "ok",
    ("cascade-proxqp", "low", "shift", "deg-equalities_in_inequality_levels"): "ok",
    ("cascade-daqp", "high", "relaxed", "deg-equalities_in_inequality_levels"): "infeasible_level",
    ("cascade-daqp", "default", "shift", "deg-equalities_in_inequality_levels"): "ok",
    ("cascade-daqp", "low", "shift", "deg-equalities_in_inequality_levels"): "ok",
    ("cascade-quadprog", "high", "shift", "deg-rank_deficient"): "ok",
    ("cascade-quadprog", "high", "equality", "deg-rank_deficient"): "ok",
    ("cascade-quadprog", "high", "equality", "deg-badly_scaled"): "infeasible_level",
    ("cascade-quadprog", "default", "shift", "deg-rank_deficient"): "ok",
    ("cascade-quadprog", "low", "shift", "deg-rank_deficient"): "ok",
    ("cascade-highs", "high", "relaxed", "deg-equalities_in_inequality_levels"): "infeasible_level",
}


def expected_outcome(key: tuple[str, str, str, str]) -> tuple[str, ...]:
    """The outcomes accepted for ``key``: "ok", and those :data:`KNOWN` and :data:`KNOWN_SKYLAKEX` record
    for it (the two kinds of OpenBLAS kernels seen; KNOWN_SKYLAKEX holds only where the second
    differs). A recorded failure is a borderline case: on a third machine (an Intel Xeon with the
    Haswell kernels solves quadprog's shifted infeasible_top) it may be solved."""
    haswell = KNOWN.get(key, "ok")
    accepted = ["ok"]
    for seen in (haswell, KNOWN_SKYLAKEX.get(key, haswell)):
        accepted += [seen] if isinstance(seen, str) else list(seen)
    return tuple(dict.fromkeys(accepted))


#: the regularisation of the matrix's outcomes (each backend's before the sweep of docs/solvers.md)
MATRIX_REGULARIZATION = {"cascade-quadprog": 1e-10}


def outcome(name: str, profile: str, freeze: str, case_name: str):
    """The outcome at the backend's tolerance preset ``profile`` and ``freeze`` (the other settings
    fixed: the swept defaults of tables.SETTINGS are the sweep's to judge)."""
    h = case(case_name)
    res = registry.create(name, freeze=freeze, tolerances=profile,
                          regularization=MATRIX_REGULARIZATION.get(name, 1e-12)).solve(h)
    if res.status != OPTIMAL:
        return res.status, res
    rtol = RTOL[profile][name]
    if freeze == "relaxed":
        rtol = max(rtol, RTOL_RELAXED.get(name, 0.0))
    verdict = verify(h, res.x, reference(case_name), rtol=rtol)
    return ("ok" if verdict.equal else "differs"), res


def _matrix():
    for name in ALL_CASCADES:
        for freeze in cascade.FREEZE_MODES:
            for c in CASES:
                yield pytest.param(name, "high", freeze, c, id=f"{name}-high-{freeze}-{c}")
        for profile in ("default", "low"):
            for c in CASES:
                yield pytest.param(name, profile, "shift", c, id=f"{name}-{profile}-shift-{c}")


@pytest.mark.parametrize("name, profile, freeze, case_name", list(_matrix()))
def test_cascade_matches_reference_or_known_status(name, profile, freeze, case_name):
    got, res = outcome(name, profile, freeze, case_name)
    assert got in expected_outcome((name, profile, freeze, case_name)), f"{res.status}: {res.reason}"
    if res.status != OPTIMAL:
        assert f"level {res.info['failed_level']}" in res.reason
        assert res.reason.startswith(name)


# (solver, freeze, case) -> expected outcome when not "ok", accuracy "high"
KNOWN_BIG: dict[tuple[str, str, str], str] = {
    ("cascade-osqp", "shift", "equality-36x8x6"): "max_iterations",
    ("cascade-osqp", "equality", "equality-36x8x6"): "max_iterations",
    ("cascade-osqp", "relaxed", "ik-like-20"): "max_iterations",
    ("cascade-osqp", "relaxed", "ik-like-40"): "max_iterations",
    ("cascade-osqp", "relaxed", "equality-36x8x6"): "max_iterations",
    ("cascade-proxqp", "relaxed", "ik-like-20"): "infeasible_level",
    ("cascade-proxqp", "relaxed", "equality-36x8x6"): "infeasible_level",
    ("cascade-clarabel", "shift", "equality-36x8x6"): "numerical_failure",
    ("cascade-clarabel", "equality", "equality-36x8x6"): "numerical_failure",
    ("cascade-clarabel", "relaxed", "equality-36x8x6"): "differs",
    ("cascade-daqp", "shift", "ik-like-20"): "infeasible_level",
    ("cascade-daqp", "relaxed", "ik-like-20"): "infeasible_level",
    ("cascade-daqp", "relaxed", "equality-36x8x6"): "infeasible_level",
    ("cascade-quadprog", "shift", "ik-like-20"): "infeasible_level",
    ("cascade-quadprog", "shift", "ik-like-40"): "infeasible_level",
    ("cascade-quadprog", "shift", "equality-36x8x6"): "infeasible_level",
    ("cascade-quadprog", "equality", "ik-like-20"): "infeasible_level",
    ("cascade-quadprog", "equality", "ik-like-40"): "infeasible_level",
    ("cascade-quadprog", "equality", "equality-36x8x6"): "infeasible_level",
    ("cascade-piqp", "relaxed", "ik-like-40"): "max_iterations",
    ("cascade-highs", "equality", "ik-like-40"): "differs",
    ("cascade-highs", "equality", "random-20"): "differs",
    ("cascade-highs", "relaxed", "ik-like-20"): "infeasible_level",
    ("cascade-highs", "relaxed", "equality-36x8x6"): "infeasible_level",
    ("cascade-cvxpy", "shift", "equality-36x8x6"): "error",
    ("cascade-cvxpy", "equality", "equality-36x8x6"): "error",
}


@pytest.mark.slow
@pytest.mark.parametrize("name, freeze, case_name",
                         [pytest.param(n, f, c, id=f"{n}-{f}-{c}") for n in ALL_CASCADES
                          for f in cascade.FREEZE_MODES for c in BIG_CASES])
def test_cascade_on_family_sized_problems(name, freeze, case_name):
    got, res = outcome(name, "high", freeze, case_name)
    assert got in ("ok", KNOWN_BIG.get((name, freeze, case_name), "ok")), f"{res.status}: {res.reason}"


@pytest.mark.parametrize("name", ALL_CASCADES)
def test_times_and_iterations_recorded(name):
    h = case("rand-mixed")
    res = registry.create(name).solve(h)
    assert res.status == OPTIMAL
    assert res.build_time_s > 0 and res.solve_time_s > 0
    assert len(res.iterations_per_level) == h.depth
    assert res.iterations == sum(res.iterations_per_level)


WARM_CASES = ("rand-mixed", "rand-two-sided", "rand-one-sided-conflict", "deg-free_rows")


@pytest.mark.parametrize("name", [n for n in QP_SOLVERS if tables.WARM_START[n[8:]]])
def test_warm_resolve_gives_same_answer(name):
    """On each case whose cold solve matches the reference (ProxQP's does not
    on rand-mixed under OpenBLAS's SkylakeX kernels: level 3 1.6e-5 above it,
    see KNOWN_SKYLAKEX), a warm re-solve on the same object gives the same
    answer; at least three cases are checked."""
    assert registry.get(name).supports_warm_start
    rtol = RTOL["high"][name]
    checked, first_its, again_its = [], 0, 0
    for c in WARM_CASES:
        h = case(c)
        solver = registry.create(name)
        first = solver.solve(h)
        if first.status != OPTIMAL or not verify(h, first.x, reference(c), rtol=rtol).equal:
            continue
        again = solver.solve(h)
        assert again.status == OPTIMAL, c
        assert verify(h, again.x, first.x, rtol=rtol).equal, c
        checked.append(c)
        first_its += first.iterations
        again_its += again.iterations
    assert len(checked) >= 3, checked
    if name == "cascade-proxqp":  # primal warm start pays off for ProxQP (rand-mixed: 28 -> 10 iterations);
        assert again_its < first_its  # OSQP gets x only (no duals), DAQP reports none


def test_warm_start_flags_follow_backend_table():
    for name in QP_SOLVERS:
        assert registry.get(name).supports_warm_start == tables.WARM_START[name[8:]]
    assert not registry.get("cascade-cvxpy").supports_warm_start


# ----------------------------------------------------------------- failures

def _tiny() -> Hierarchy:
    return Hierarchy.from_levels([Level.equality(np.eye(2, 3), [1.0, 2.0]),
                                  Level.equality(np.ones((1, 3)), [0.0])])


def test_backend_exception_becomes_error_status(monkeypatch):
    import qpsolvers

    calls = []

    def boom(problem, solver, **kw):
        calls.append(solver)
        if len(calls) == 2:
            raise RuntimeError("injected failure")
        return real(problem, solver, **kw)

    real = qpsolvers.solve_problem
    monkeypatch.setattr(qpsolvers, "solve_problem", boom)
    res = registry.create("cascade-clarabel").solve(_tiny())
    assert res.status == ERROR
    assert "level 1" in res.reason and "RuntimeError: injected failure" in res.reason
    assert res.x is not None and res.x.shape == (3,)  # the point after level 0


def test_nan_from_backend_becomes_numerical_failure(monkeypatch):
    import qpsolvers

    def nan_solution(problem, solver, **kw):
        sol = qpsolvers.Solution(problem)
        sol.found = True
        sol.x = np.full(problem.P.shape[0], np.nan)
        return sol

    monkeypatch.setattr(qpsolvers, "solve_problem", nan_solution)
    res = registry.create("cascade-daqp").solve(_tiny())
    assert res.status == NUMERICAL_FAILURE
    assert "level 0" in res.reason and "NaN" in res.reason
    assert res.x is None


def test_iteration_limit_becomes_max_iterations():
    res = registry.create("cascade-osqp", max_iter=1).solve(case("rand-mixed"))
    assert res.status == MAX_ITERATIONS
    assert f"level {res.info['failed_level']}: backend osqp hit its iteration limit" in res.reason


def test_highs_has_an_iteration_cap_by_default():
    """HiGHS's QP iteration limit defaults to 2^31 - 1: on degenerate/badly_scaled seed 1 its
    level-2 QP looped for more than 10 minutes (solve and scenario hung; run lost a row after
    the first-solve timeout). With the default cap it answers at once. (In a child process
    killed after 120 s: no Python signal handler interrupts a loop in C.)"""
    import subprocess
    import sys

    pytest.importorskip("highspy")
    code = ("from problems import generators as g; from solvers import registry; "
            "h = g.generate('degenerate', seed=1, case='badly_scaled'); "
            "print(registry.create('cascade-highs').solve(h).status)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    assert out.stdout.split()[-1] in (OPTIMAL, INFEASIBLE_LEVEL, MAX_ITERATIONS), out.stdout


def test_infeasible_after_freezing_names_the_level():
    # level 0 fixes x0 = 0, level 1 asks x0 >= 1 (slack -1). With slack_tol = 10
    # the "equality" freeze keeps that row as an inequality at its own bound,
    # so levels 0 and 1 frozen together are inconsistent: level 2 is infeasible.
    h = Hierarchy.from_levels([Level.equality(np.array([[1.0, 0.0]]), [0.0]),
                               Level(np.array([[1.0, 0.0]]), np.array([1.0]), np.array([np.inf])),
                               Level.equality(np.array([[0.0, 1.0]]), [1.0])])
    res = registry.create("cascade-quadprog", freeze="equality", slack_tol=10.0).solve(h)
    assert res.status == INFEASIBLE_LEVEL
    assert res.reason.startswith("cascade-quadprog: level 2: infeasible after freezing levels 0..1")



def _fail_at_call(monkeypatch, fail_call: int):
    """qpsolvers.solve_problem with no solution (status not reported) at call fail_call (1-based)."""
    import qpsolvers

    real = qpsolvers.solve_problem
    calls = []

    def no_solution(problem, solver, **kw):
        calls.append(solver)
        if len(calls) == fail_call:
            return qpsolvers.Solution(problem)  # found None, x None: what a silent backend gives
        return real(problem, solver, **kw)

    monkeypatch.setattr(qpsolvers, "solve_problem", no_solution)


@pytest.mark.parametrize("levels, fail_call, expect", [
    # x0, x1 <= 0 and x0 + x1 >= 0, then (1, 1) wanted: x = 0 with 3 rows active on 2 variables
    ([Level(np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]]), np.array([-np.inf, -np.inf, 0.0]),
            np.array([0.0, 0.0, np.inf])),
      Level.equality(np.eye(2), [1.0, 1.0]), Level.equality(np.array([[1.0, -1.0]]), [0.5])], 3,
     ("level 2: backend daqp found no solution (status not reported by qpsolvers) of a feasible QP: "
      "x of level 1 satisfies the frozen rows of levels 0..1 to NUM, with 5 of them active on n = 2 "
      "variables (more than n: degenerate)")),
    ([Level.equality(np.array([[1.0, 0.0]]), [2.0]), Level.equality(np.array([[0.0, 1.0]]), [3.0])], 2,
     ("level 1: backend daqp found no solution (status not reported by qpsolvers) of a feasible QP: "
      "x of level 0 satisfies the frozen rows of levels 0..0 to NUM, with 1 of them active on n = 2 "
      "variables")),
], ids=["degenerate-vertex", "feasible"])
def test_no_solution_of_a_feasible_level_says_so(monkeypatch, levels, fail_call, expect):
    # a level's QP has slacks: it is feasible when x of the level above satisfies the frozen rows,
    # and a backend without a solution then failed (it is not "infeasible")
    _fail_at_call(monkeypatch, fail_call)
    res = registry.create("cascade-daqp").solve(Hierarchy.from_levels(levels))
    assert res.status == INFEASIBLE_LEVEL
    assert res.reason.startswith("cascade-daqp: ")
    # (the violation at x is rounding: its digits are the backend's)
    assert re.fullmatch(re.escape(expect).replace("NUM", r"\d\.\de[+-]\d\d"), res.reason[len("cascade-daqp: "):])
    assert res.x is not None


def test_truly_infeasible_level_names_the_violated_row(monkeypatch):
    # as test_infeasible_after_freezing_names_the_level, with a backend that reports nothing:
    # x of level 1 violates the frozen row x0 >= 1 (kept at its own bound) by 1
    _fail_at_call(monkeypatch, 3)
    h = Hierarchy.from_levels([Level.equality(np.array([[1.0, 0.0]]), [0.0]),
                               Level(np.array([[1.0, 0.0]]), np.array([1.0]), np.array([np.inf])),
                               Level.equality(np.array([[0.0, 1.0]]), [1.0])])
    res = registry.create("cascade-daqp", freeze="equality", slack_tol=10.0).solve(h)
    assert res.status == INFEASIBLE_LEVEL
    assert res.reason == ("cascade-daqp: level 2: infeasible after freezing levels 0..1 (backend daqp found "
                          "no solution, status not reported by qpsolvers; x of level 1 violates the frozen row 0 "
                          "of level 1 by 1.0e+00)")


def test_the_violated_frozen_row_is_named_in_its_level_past_free_rows_and_empty_levels():
    # A_f holds the non-free rows only: its row 1 is row 2 of level 2 (level 1 empty, two free rows)
    free = [-np.inf, np.inf]
    h = Hierarchy.from_levels([
        Level(np.array([[1.0, 1.0], [1.0, 0.0]]), np.array([free[0], 0.0]), np.array([free[1], 0.0])),
        Level(np.zeros((0, 2)), np.zeros(0), np.zeros(0)),
        Level(np.array([[1.0, 1.0], [0.0, 2.0], [0.0, 1.0]]), np.array([free[0], free[0], 1.0]),
              np.array([free[1], free[1], np.inf])),
        Level.equality(np.array([[1.0, 1.0]]), [0.0])])
    A_f = np.array([[1.0, 0.0], [0.0, 1.0]])
    why = cascade._no_solution("daqp", "s", h, 3, A_f, np.array([0.0, 1.0]), np.array([0.0, np.inf]), np.zeros(2))
    assert why == ("infeasible after freezing levels 0..2 (backend daqp found no solution, status s; x of "
                   "level 2 violates the frozen row 2 of level 2 by 1.0e+00)")


# ------------------------------------------------------------------ options

@pytest.mark.parametrize("opts, match", [
    ({"freeze": "melt"}, "freeze='melt'"),
    ({"accuracy": "best"}, "accuracy='best'"),
    ({"regularization": -1.0}, "regularization"),
    ({"max_iter": 0}, "max_iter"),
    ({"bogus": 1}, "bogus"),
], ids=["freeze", "accuracy", "regularization", "max_iter", "unknown"])
def test_bad_options_raise(opts, match):
    with pytest.raises(SolverOptionError, match=match):
        registry.create("cascade-osqp", **opts)


def test_quadprog_has_no_iteration_limit_option():
    with pytest.raises(SolverOptionError, match="quadprog has no iteration limit"):
        registry.create("cascade-quadprog", max_iter=10)


def test_cvxpy_solver_option():
    with pytest.raises(SolverOptionError, match="'bogus'"):
        registry.create("cascade-cvxpy", bogus=1)
    with pytest.raises(SolverOptionError, match="solver='GUROBI'"):
        registry.create("cascade-cvxpy", solver="GUROBI")
    res = registry.create("cascade-cvxpy", solver="OSQP").solve(case("rand-eq"))
    assert res.status == OPTIMAL
    assert verify(case("rand-eq"), res.x, reference("rand-eq"), rtol=1e-8).equal


def test_accuracy_tables_cover_every_backend_and_profile():
    for backend in tables.BACKENDS:
        assert set(tables.ACCURACY[backend]) == set(tables.PROFILES)
        high = tables.ACCURACY[backend]["high"]
        for key, value in high.items():
            if "rel" in key:
                assert value == 0.0, f"{backend}: relative tolerance {key} must be off in 'high'"
            elif "tol" in key or "eps" in key:
                assert value == 1e-9, f"{backend}: {key} must be 1e-9 in 'high'"


@pytest.mark.parametrize("name", ALL_CASCADES)
def test_the_swept_settings_are_the_defaults_at_each_profile_and_listed(name, capsys):
    """tables.SETTINGS (docs/solvers.md, "Fair settings") is what a cascade built with only
    ``accuracy`` runs with, what it reports (Solver.settings: column solver_settings) and what
    ``hikbench list solvers --settings`` shows; an option given replaces its row's value."""
    from hikbench.bench.cli import main

    if name not in registry.available():
        pytest.skip(f"{name} is not installed")
    backend = name.removeprefix("cascade-")
    assert main(["list", "solvers", "--settings"]) == 0
    lines = [line.split() for line in capsys.readouterr().out.splitlines()]
    for profile in tables.PROFILES:
        chosen = tables.SETTINGS[backend][profile]
        got = registry.create(name, accuracy=profile).settings()
        assert {k: got[k] for k in ("tolerances", "freeze", "regularization")} == \
            {k: chosen[k] for k in ("tolerances", "freeze", "regularization")}
        if chosen["max_iter"] is not None:
            assert got["max_iter"] == chosen["max_iter"]
        line = next(w for w in lines if w[:2] == [name, f"accuracy={profile}"])
        assert f"freeze={chosen['freeze']}" in line and f"regularization={chosen['regularization']:g}" in line
        other = "relaxed" if chosen["freeze"] != "relaxed" else "shift"
        assert registry.create(name, accuracy=profile, freeze=other).settings() == {**got, "freeze": other}


def test_list_settings_is_for_solvers_only(capsys):
    from hikbench.bench.cli import main

    assert main(["list", "robots", "--settings"]) == 2
    assert capsys.readouterr().err.strip() == ("hikbench list: error: --settings: only with `hikbench list "
                                               "solvers`, not 'robots'")


def test_missing_backend_is_absent_and_says_how_to_install(monkeypatch):
    import qpsolvers

    others = [s for s in qpsolvers.available_solvers if s != "highs"]
    monkeypatch.setattr(qpsolvers, "available_solvers", others)
    try:
        mod = importlib.reload(cascade)
        assert "cascade-highs" not in [i.name for i in mod.SOLVERS]
        assert "pip install highspy" in mod.MISSING["cascade-highs"]
        monkeypatch.setattr(registry, "_registry", None)
        monkeypatch.setattr(registry, "_missing", {})
        with pytest.raises(SolverNotFoundError, match="pip install highspy"):
            registry.get("cascade-highs")
    finally:
        monkeypatch.undo()
        importlib.reload(cascade)


def test_freeze_modes_keep_x_feasible():
    h = g.random_hierarchy(6, 2, 3, inequality="mixed", seed=5)
    x = np.random.default_rng(0).standard_normal(6)
    lv = h[0]
    for mode in cascade.FREEZE_MODES:
        lo, up, w = cascade.freeze_level(mode, lv.A, lv.lower, lv.upper, x, slack_tol=1e-9, delta=1e-6)
        r = lv.A @ x
        assert np.all(r >= lo - 1e-12) and np.all(r <= up + 1e-12), mode
    np.testing.assert_allclose(w, lv.A @ x - np.clip(lv.A @ x, lv.lower, lv.upper), rtol=0, atol=0)


# ------------------------------------------------------- random hierarchies

#: backends (freeze "shift", accuracy "high") that solved all of 200 random
#: unsaturated hierarchies (depth * rows < n, n <= 9) in a survey; on the same
#: survey osqp hit max_iterations twice, quadprog and proxqp reported
#: infeasible levels, piqp max_iterations, highs no solution: those backends
#: are covered by the explicit KNOWN table above instead
# cascade-daqp fails ~3 % of these (infeasible_level after freezing; 31 of 1200 in a survey), so it
# is not in the property test; its failures are in the known-status tables.
ROBUST = ("cascade-clarabel",)


@settings(max_examples=10)
@given(n=st.integers(4, 9), depth=st.integers(1, 3), rows=st.integers(1, 3),
       inequality=st.sampled_from(g.INEQUALITY_MIXES), box=st.booleans(), seed=st.integers(0, 10_000))
@example(n=9, depth=3, rows=1, inequality="none", box=True, seed=1143)
def test_robust_cascades_match_reference_on_random_hierarchies(n, depth, rows, inequality, box, seed):
    """Equal to the reference, or lower below a level the cascade left above the reference's
    within the tolerance (which leaves the levels below room to look better: docs/verification.md,
    "Limits of double precision"). n = 9, 3 levels of 1 row under a box, seed 1143: Clarabel's level 2 at
    0.10578903903 against the exact optimum 0.10578903733, level 3 then 6.8e-6 lower."""
    assume(depth * rows < n)
    h = g.random_hierarchy(n, depth, rows, inequality=inequality, box=box, seed=seed)
    x_ref = yardstick_solution(h)
    for name in ROBUST:
        res = registry.create(name).solve(h)
        assert res.status == OPTIMAL, res.reason
        v = verify(h, res.x, x_ref, rtol=RTOL["high"][name])
        if not v.equal:
            above = level_norms(h, res.x)[:v.level] - level_norms(h, x_ref)[:v.level]
            assert v.lower == "a" and np.any(above > 0), (name, v, above)


def test_equality_freeze_pins_only_rows_with_nonzero_slack():
    A = np.eye(3)
    lower, upper = np.array([0.0, -np.inf, -1.0]), np.array([0.0, 1.0, 1.0])
    x = np.array([0.5, 2.0, 0.0])  # row 0 off its equality, row 1 above its bound, row 2 inside
    lo, up, w = cascade.freeze_level("equality", A, lower, upper, x, slack_tol=1e-9, delta=0.0)
    np.testing.assert_array_equal(w, [0.5, 1.0, 0.0])
    np.testing.assert_array_equal(lo, [0.5, 2.0, -1.0])
    np.testing.assert_array_equal(up, [0.5, 2.0, 1.0])
    lo, up, _ = cascade.freeze_level("shift", A, lower, upper, x, 1e-9, 0.0)
    np.testing.assert_array_equal(lo, [0.5, -np.inf, -1.0])
    np.testing.assert_array_equal(up, [0.5, 2.0, 1.0])
    lo, up, _ = cascade.freeze_level("relaxed", A, lower, upper, x, 1e-9, 0.25)
    np.testing.assert_array_equal(lo, [0.25, -np.inf, -1.25])
    np.testing.assert_array_equal(up, [0.75, 2.25, 1.25])


def test_level_qp_is_the_documented_qp():
    """z = (x, w): cost 1/2 ||w||^2 + eps/2 ||x||^2; (x, w(x)) is feasible
    with w(x) = A_k x - clip(A_k x, lower_k, upper_k)."""
    h = g.random_hierarchy(5, 2, 3, inequality="mixed", seed=9)
    hi, lv = h[0], h[1]
    x = np.random.default_rng(1).standard_normal(5)
    lo_f, up_f, _ = cascade.freeze_level("shift", hi.A, hi.lower, hi.upper, x, 1e-9, 0.0)
    P, G, hv, Aeq, beq = cascade.level_qp(hi.A, lo_f, up_f, lv.A, lv.lower, lv.upper, eps=1e-12)
    r = lv.A @ x
    z = np.concatenate([x, r - np.clip(r, lv.lower, lv.upper)])
    np.testing.assert_array_equal(np.diag(P), np.concatenate([np.full(5, 1e-12), np.ones(3)]))
    assert G is None or np.all(G @ z <= hv + 1e-12)
    assert Aeq is None or np.allclose(Aeq @ z, beq, atol=1e-12)
