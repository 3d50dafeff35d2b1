"""Option values of the built-in solvers: a wrong type or range raises
SolverOptionError at construction, naming solver, option, value and what is
expected (the shared checks of hikbench.solvers.registry); valid values pass."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from hikbench.solvers.errors import SolverOptionError
from hikbench.solvers import registry
from hikbench.solvers.registry import check_choice, check_int, check_number, check_numbers

CASCADES = ("osqp", "proxqp", "clarabel", "daqp", "quadprog", "piqp", "highs", "cvxpy")
NUMBER_GE0 = "a finite number >= 0"


def _param(solver, option, value, expected, id_):
    skip = solver not in registry.available()
    return pytest.param(solver, option, value, expected, id=id_,
                        marks=[pytest.mark.skip(reason=f"{solver} is not installed")] if skip else [])


BAD = [
    _param("dls", "damping", "abc", NUMBER_GE0, "dls-damping-str"),
    _param("dls", "damping", [1], NUMBER_GE0, "dls-damping-list"),
    _param("dls", "damping", True, NUMBER_GE0, "dls-damping-bool"),
    _param("dls", "damping", -1.0, NUMBER_GE0, "dls-damping-negative"),
    _param("dls", "damping", math.nan, NUMBER_GE0, "dls-damping-nan"),
    _param("dls", "passes", 2.5, "an integer >= 1", "dls-passes-float"),
    _param("dls", "passes", True, "an integer >= 1", "dls-passes-bool"),
    _param("dls-liegeois", "alpha", "abc", NUMBER_GE0 + " or None", "liegeois-alpha-str"),
    _param("dls-liegeois", "alpha", math.inf, NUMBER_GE0 + " or None", "liegeois-alpha-inf"),
    _param("dls-liegeois", "tol", "abc", "a finite number > 0", "liegeois-tol-str"),
    _param("dls-liegeois", "tol", 0.0, "a finite number > 0", "liegeois-tol-zero"),
    _param("dls-liegeois", "damping", "abc", NUMBER_GE0, "liegeois-damping-str"),
    _param("dls-liegeois", "max_iter", "10", "an integer >= 1", "liegeois-max_iter-str"),
    _param("weighted", "regularization", "abc", NUMBER_GE0, "weighted-regularization-str"),
    _param("weighted", "ratio", 0.0, "a finite number > 0", "weighted-ratio-zero"),
    _param("weighted", "weights", "abc", "a non-empty list of finite numbers >= 0, one weight per level",
           "weighted-weights-str"),
    _param("weighted", "weights", [1, 2, 3, 4, 5, math.nan], "a non-empty list of finite numbers >= 0",
           "weighted-weights-nan"),
    _param("weighted", "weights", "[1,2,3,4,5,nan]", "a non-empty list of finite numbers >= 0",
           "weighted-weights-cli-nan"),  # what the CLI passes on: not JSON, so the string itself
    _param("weighted", "weights", {"a": 1}, "a non-empty list of finite numbers >= 0",
           "weighted-weights-dict"),
    _param("weighted", "weights", [], "a non-empty list of finite numbers >= 0", "weighted-weights-empty"),
    _param("weighted", "weights", [[1.0, 2.0]], "a non-empty list of finite numbers >= 0",
           "weighted-weights-nested"),
    _param("weighted", "weights", [1.0, -1.0], "a non-empty list of finite numbers >= 0",
           "weighted-weights-negative"),
    _param("weighted", "weights", [1.0, True], "a non-empty list of finite numbers >= 0",
           "weighted-weights-bool"),
    _param("nullspace-svd", "rank_rtol", "abc", "a finite number >= 0 and < 1", "nullspace-svd-rank_rtol-str"),
    _param("nullspace-cod", "rank_rtol", "abc", "a finite number >= 0 and < 1", "nullspace-cod-rank_rtol-str"),
    _param("nullspace-cod", "rank_rtol", 1.0, "a finite number >= 0 and < 1", "nullspace-cod-rank_rtol-one"),
    _param("pinv-all", "rank_rtol", [0.1], "a finite number >= 0 and < 1", "pinv-all-rank_rtol-list"),
    *[_param(f"cascade-{b}", opt, "abc", NUMBER_GE0 + " or None", f"cascade-{b}-{opt}")
      for b in CASCADES for opt in ("regularization", "relax_delta", "slack_tol")],
    _param("cascade-osqp", "max_iter", 1.5, "an integer >= 1 or None", "cascade-osqp-max_iter-float"),
    _param("cascade-osqp", "freeze", ["shift"], "one of shift, equality, relaxed",
           "cascade-osqp-freeze-list"),
    _param("cascade-osqp", "accuracy", 1, "one of high, default, low", "cascade-osqp-accuracy-int"),
    _param("cascade-cvxpy", "solver", ["OSQP"], "one of CLARABEL, OSQP, PIQP, PROXQP, SCS",
           "cascade-cvxpy-solver-list"),
]


@pytest.mark.parametrize("solver, option, value, expected", BAD)
def test_bad_option_value_raises_at_construction(solver, option, value, expected):
    message = f"{solver}: option {option}={value!r} is not allowed; expected {expected}"
    with pytest.raises(SolverOptionError, match="^" + re.escape(message)):
        registry.create(solver, **{option: value})


@pytest.mark.parametrize("solver, options, attr, stored", [
    ("dls", {"damping": 0}, "damping", 0.0),
    ("dls", {"damping": np.float32(0.5)}, "damping", 0.5),
    ("dls", {"passes": np.int64(2)}, "passes", 2),
    ("dls-liegeois", {"alpha": None}, "alpha", None),
    ("weighted", {"weights": (1, 0.5)}, "weights", [1.0, 0.5]),
    ("weighted", {"weights": np.array([1.0, 0.0])}, "weights", [1.0, 0.0]),
    ("nullspace-svd", {"rank_rtol": 0}, "rank_rtol", 0.0),
    ("cascade-osqp", {"slack_tol": 1e-6, "max_iter": 50}, "slack_tol", 1e-6),
], ids=["int", "numpy-float", "numpy-int", "none", "tuple", "array", "zero", "cascade"])
def test_valid_option_values_are_kept(solver, options, attr, stored):
    if solver not in registry.available():
        pytest.skip(f"{solver} is not installed")
    value = getattr(registry.create(solver, **options), attr)
    if isinstance(stored, list):
        np.testing.assert_array_equal(value, stored)
        assert value.dtype == float
    else:
        assert value == stored and type(value) is type(stored)


@pytest.mark.parametrize("call, message", [
    (lambda: check_number("s", "o", 1.0, low=0, high=1, high_open=True),
     "o=1.0 is not allowed; expected a finite number >= 0 and < 1"),
    (lambda: check_number("s", "o", 0, low=0, high=1, low_open=True), "expected a finite number > 0 and <= 1"),
    (lambda: check_number("s", "o", 2, high=1), "expected a finite number <= 1"),
    (lambda: check_number("s", "o", None), "o=None is not allowed; expected a finite number"),
    (lambda: check_int("s", "o", 0, low=1, none_ok=True), "expected an integer >= 1 or None"),
    (lambda: check_choice("s", "o", "x", ("a", "b")), "o='x' is not allowed; expected one of a, b"),
    (lambda: check_numbers("s", "o", [1, "2"], what="one each"),
     "expected a non-empty list of finite numbers, one each"),
], ids=["high-open", "low-open", "high", "none", "int-none", "choice", "numbers"])
def test_check_helpers_messages(call, message):
    with pytest.raises(SolverOptionError, match=re.escape(message)):
        call()
