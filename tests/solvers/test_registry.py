"""The registry: lookup, and option-name validation in create()."""

import dataclasses

import numpy as np
import pytest

from hikbench.solvers.errors import SolverNotFoundError, SolverOptionError
from hikbench.solvers import _qp_backends as tables
from hikbench.solvers import registry
from hikbench.solvers.base import Solver, SolveResult
from hikbench.solvers.registry import SolverInfo


class _Opt(Solver):
    name = "test-opt"

    def __init__(self, tol: float = 1e-9, *, max_iter: int = 10):
        if tol <= 0:
            raise SolverOptionError(f"test-opt: tol must be > 0; got {tol}")
        self.tol, self.max_iter = tol, max_iter

    def solve(self, hierarchy):
        return SolveResult(x=None, status="unsupported")


class _Broken(Solver):
    name = "test-broken"

    def __init__(self, tol: float = 1.0):
        raise TypeError("a bug inside the constructor")

    def solve(self, hierarchy):  # pragma: no cover
        raise AssertionError


def _kwargs_factory(**options):
    return _Opt(**options)


@pytest.fixture
def fake_registry(monkeypatch):
    reg = dict(registry._load())
    for info in (SolverInfo("test-opt", "options", _Opt, options={"tol": 1e-6}),
                 SolverInfo("test-broken", "raises TypeError inside", _Broken),
                 SolverInfo("test-kwargs", "takes **options", _kwargs_factory)):
        reg[info.name] = info
    monkeypatch.setattr(registry, "_registry", reg)
    return reg


def test_create_passes_defaults_and_options(fake_registry):
    s = registry.create("test-opt", max_iter=3)
    assert (s.tol, s.max_iter) == (1e-6, 3)


@pytest.mark.parametrize("name, options, error, message", [
    ("test-opt", {"tolerance": 1.0}, SolverOptionError,
     r"solver 'test-opt': unknown option\(s\) 'tolerance'; allowed options: tol, max_iter"),
    ("yardstick", {"tol": 1.0}, SolverOptionError,
     r"solver 'yardstick': unknown option\(s\) 'tol'; allowed options: none"),
    ("test-opt", {"tol": -1.0}, SolverOptionError, r"test-opt: tol must be > 0; got -1.0"),
    # a TypeError raised inside a constructor is a bug, not a bad option: it propagates unchanged
    ("test-broken", {}, TypeError, r"a bug inside the constructor"),
    # a factory taking **options validates names itself
    ("test-kwargs", {"bogus": 1}, TypeError, r"unexpected keyword argument 'bogus'"),
    ("nope", {}, SolverNotFoundError, r"unknown solver 'nope' \(found solvers: .*yardstick"),
    ("test-otp", {}, SolverNotFoundError, r"unknown solver 'test-otp'; did you mean 'test-opt'\? \(found solvers: "),
], ids=["unknown option", "no options", "bad value", "constructor bug", "kwargs factory", "unknown solver",
        "misspelt solver"])
def test_create_errors(fake_registry, name, options, error, message):
    with pytest.raises(error, match=message):
        registry.create(name, **options)


def test_option_names(fake_registry):
    assert registry.option_names(fake_registry["test-opt"]) == ("tol", "max_iter")
    assert registry.option_names(fake_registry["test-kwargs"]) is None


@pytest.mark.parametrize(("x", "status"), [
    (np.array([1.0, -2.0, 3.0]), "optimal"),
    (np.array([1e200, -1e200]), "optimal"),  # x @ x would overflow: no warning, x is finite
    (np.array([1.0, np.nan]), "numerical_failure"),
    (np.array([np.inf, 1.0]), "numerical_failure"),
    (np.array([-np.inf, np.inf]), "numerical_failure"),
    (np.array([[1.0, np.nan]]), "numerical_failure"),  # not a vector: the full test
    (np.array([1, 2], dtype=np.int64), "optimal"),
    (np.zeros(0), "optimal"),
], ids=["finite", "huge-finite", "nan", "inf", "inf-minus-inf", "2d-nan", "int", "empty"])
def test_optimal_result_with_nonfinite_x_becomes_numerical_failure(x, status):
    r = SolveResult(x=x, status="optimal")
    assert r.status == status
    assert ("NaN or inf" in r.reason) == (status == "numerical_failure")


@pytest.mark.parametrize("reason", ["", "converged"], ids=["no reason", "a reason"])
def test_an_optimal_result_without_x_is_a_solver_error(reason):
    r = SolveResult(x=None, status="optimal", reason=reason)
    assert r.status == "error" and not r.ok
    assert r.reason == (f"{reason}; " if reason else "") + "status optimal with x None: expected x, shape (n,)"
    assert SolveResult(x=None, status="unsupported").status == "unsupported"  # no x is right there


def test_x_finite_is_the_callers_word_and_not_a_field():
    """x_finite=True (a solver whose compiled code tested every entry, as
    hcod's kernel does) skips the repeat of the test; it is init-only."""
    r = SolveResult(x=np.array([1.0, np.nan]), status="optimal", x_finite=True)
    assert r.status == "optimal" and "x_finite" not in {f.name for f in dataclasses.fields(r)}
    assert SolveResult(x=np.array([1.0, np.nan]), status="optimal").status == "numerical_failure"


# every solver of the project, listed without importing a backend (registry.available() at
# collection would import them all for any -k run)
_ALL = ("hcod", "yardstick", "cascade-cvxpy", *(f"cascade-{b}" for b in tables.BACKENDS), "nullspace-svd",
        "nullspace-cod", "pinv-all", "weighted", "dls", "dls-liegeois", "daqp-hqp")


def test_every_solver_of_the_project_is_installed():
    """Every backend is a dependency in pyproject.toml: a broken install fails here instead of
    the tests parametrized over the installed solvers quietly running fewer cases (and _ALL is
    the registry)."""
    missing = registry.missing()
    peers = {"soth", "lexls", "nipm-hlsp"}  # (C++ peers: listed once built by `make peers`, docs/peers.md)
    assert {k: v for k, v in missing.items() if k not in peers} == {}
    assert set(_ALL) == set(registry.available()) - peers
    built = peers & set(registry.available())
    assert built in (set(), peers) and all("run `make peers`" in missing[p] for p in peers - built)


@pytest.mark.parametrize("name", _ALL)
@pytest.mark.parametrize("bad, got", [(None, "NoneType"), (np.eye(2), "numpy.ndarray"), ("tiny.npz", "str")],
                         ids=["none", "ndarray", "str"])
@pytest.mark.parametrize("kind", ["inequalities", "equalities"])
def test_solve_of_a_non_hierarchy_names_the_solver_and_the_expected_type(name, bad, got, kind):
    """The Python boundary of solve(): a TypeError naming the solver, the expected type and
    what it got -- before any solve and after one (hcod's re-solve paths compare identities,
    one for each kind of hierarchy)."""
    import re

    from hikbench.problems.hierarchy import Hierarchy, Level

    solver = registry.create(name)
    msg = rf"^{re.escape(name)}\.solve expects a hikbench\.problems\.hierarchy\.Hierarchy .*got {re.escape(got)}$"
    with pytest.raises(TypeError, match=msg):
        solver.solve(bad)
    top = (Level(np.eye(2), -np.ones(2), np.ones(2)) if kind == "inequalities"
           else Level.equality(np.array([[1.0, -1.0]]), [0.1]))
    h = Hierarchy.from_levels([top, Level.equality(np.ones((1, 2)), [0.5])], n=2)
    assert solver.solve(h).status in ("optimal", "unsupported")
    with pytest.raises(TypeError, match=msg):
        solver.solve(bad)


def _empty_levels(n: int):
    from hikbench.problems.hierarchy import Hierarchy

    return Hierarchy(np.zeros((2, n)), [1.0, -1.0], [1.0, -1.0], [0, 1], n=n, depth=2)  # two equalities


@pytest.mark.parametrize("name", _ALL)
def test_a_problem_larger_than_the_memory_is_refused_before_any_allocation(name):
    """A valid hierarchy whose n x n matrix of doubles would not fit (SOTH's ``variable size
    100000000000`` with no rows): a HikbenchError naming the solver, n and both sizes, not
    numpy's MemoryError traceback (1e11) or hours of swapping (3e9)."""
    from hikbench.problems.errors import HikbenchError, ProblemTooLargeError
    from hikbench.problems.hierarchy import MEMORY_BYTES, Hierarchy

    n = 10 ** 11
    h = Hierarchy(np.zeros((0, n)), [], [], [], n=n, depth=1)
    with pytest.raises(ProblemTooLargeError, match=rf"^{name}: n = {n} variables: one n x n matrix of doubles "
                                                   rf"needs 7\.45e\+13 GiB, more than this machine's "
                                                   rf"[0-9.]+ GiB of memory$") as err:
        registry.create(name).solve(h)
    assert isinstance(err.value, HikbenchError) and isinstance(err.value, MemoryError)
    largest = int((MEMORY_BYTES / 8) ** 0.5)  # the largest n whose n x n matrix fits
    registry.create(name).check_hierarchy(Hierarchy(np.zeros((0, largest)), [], [], [], n=largest, depth=1))
    with pytest.raises(ProblemTooLargeError):
        registry.create(name).check_hierarchy(Hierarchy(np.zeros((0, largest + 1)), [], [], [], n=largest + 1,
                                                        depth=1))


@pytest.mark.parametrize("name", _ALL)
def test_no_variables_is_solved_by_every_solver(name):
    """n = 0: x in R^0 is decided, every solver says optimal with an empty x (cascade-cvxpy
    raised on cvxpy's Variable(0) before; its row was an error). dls-liegeois needs a box level,
    which no row of R^0 is."""
    res = registry.create(name).solve(_empty_levels(0))
    if name == "dls-liegeois":
        assert (res.status, res.x) == ("unsupported", None)
        assert "needs per-variable limits: no level is a box level" in res.reason
        return
    assert res.status == "optimal", res.reason
    assert res.x.shape == (0,)


def test_cascade_factories_are_named_by_their_module():
    """`hikbench list`/registry.available() showed <class 'abc.Cascade_clarabel'>."""
    factory = registry.get("cascade-daqp").factory
    assert (factory.__module__, factory.__qualname__) == ("hikbench.solvers.cascade", "Cascade_daqp")


@pytest.mark.parametrize("problem", ["ik-like", "equality"])
@pytest.mark.parametrize("name", sorted(registry.available()))
def test_a_dropped_solver_is_freed_without_the_collector(name, problem):
    """The benchmark times cold solves with the collector off and a fresh solver each: a solver
    held in a reference cycle (hcod's run closure once held the solver) keeps every dropped
    solver and its workspaces, and each solve then touches fresh pages (cold IK-like n=80 went
    from 187 to 411 us in `hikbench run`)."""
    import gc
    import weakref

    from hikbench.problems.generators import equality_stack, ik_like

    h = ik_like(12, 0) if problem == "ik-like" else equality_stack(12, 3, 3)
    s = registry.create(name)
    gc.collect()
    gc.disable()
    try:
        s.solve(h)
        s.solve(h)
        ref = weakref.ref(s)
        del s
        assert ref() is None
    finally:
        gc.enable()
