"""A solver returning a complex x gets status error with a reason naming it, never
an x silently cast to its real part (solvers/base.py checked_result; external
programs: bench/harness/external.py)."""

from __future__ import annotations

import json
import sys
import warnings

import numpy as np
import pytest
from doubles import tiny

from hikbench.bench.harness.external import run_external
from hikbench.bench.harness.timing import time_solves
from hikbench.solvers.base import OPTIMAL, Solver, SolveResult
from hikbench.solvers.yardstick import nullspace_yardstick


class ComplexSolver(Solver):
    """The right x, with a zero imaginary part: complex128."""

    name = "complex"

    def solve(self, hierarchy):
        return SolveResult(nullspace_yardstick(hierarchy) + 0j, OPTIMAL)


def test_an_in_process_solver_returning_complex_x_is_an_error_naming_it():
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # (numpy's ComplexWarning of a cast)
        t = time_solves(ComplexSolver, tiny(), repeat=2)
    assert t.result.status == "error" and t.result.x is None
    assert "complex" in t.result.reason and "complex128" in t.result.reason, t.result.reason


def test_a_solver_returning_real_x_of_python_floats_is_kept():
    class ListSolver(ComplexSolver):
        def solve(self, hierarchy):
            return SolveResult([float(v) for v in nullspace_yardstick(hierarchy)], OPTIMAL)

    assert time_solves(ListSolver, tiny()).result.status == "optimal"


WRITE = "import json, sys\nopen(sys.argv[1], 'w').write(sys.argv[2])\n"


@pytest.mark.parametrize("x, fragment", [
    (["(1+2j)", "0", "0", "0"], "element 0 is the string '(1+2j)', a complex number: x must be real"),
    ([0, "1e-3", 0, 0], "element 1 is the string '1e-3': expected a JSON number"),
    ([0, 0, True, 0], "element 2 is bool True"),
    ([[1, 0], [0, 0], [0, 0], [0, 0]], "element 0 is list"),
    ({"real": [0, 0, 0, 0], "imag": [1, 0, 0, 0]}, '"x" must be a list of 4 numbers; got dict'),
], ids=["complex string", "numeric string", "bool", "pairs", "object"])
def test_an_external_x_that_is_not_real_numbers_is_an_error_naming_it(tmp_path, x, fragment):
    prog = tmp_path / "write.py"
    prog.write_text(WRITE)
    arg = json.dumps({"x": x}).replace("'", "")
    job = {"solver": f"external:p={sys.executable} {prog} {{out}} '{arg}'", "hierarchy": tiny(n=4),
           "repeat": 1, "warmup": 0}
    res = run_external(job, timeout=30)
    assert res["status"] == "error" and res["x"] is None, res
    assert fragment in res["reason"], res["reason"]


def test_a_float64_x_stays_as_it_is():
    res = SolveResult(np.zeros(3), OPTIMAL)
    from hikbench.solvers.base import checked_result

    assert checked_result(res, tiny(n=3, depth=1, rows=1), ComplexSolver()) is res


class NoXSolver(ComplexSolver):
    """Says optimal and gives no x."""

    def solve(self, hierarchy):
        return SolveResult(None, OPTIMAL)


def test_an_in_process_solver_saying_optimal_without_x_is_an_error():
    from hikbench.bench.harness.worker import execute

    res = execute({"kind": "solve", "hierarchy": tiny(), "solver": f"{__file__}:NoXSolver", "options": {},
                   "mode": "cold", "repeat": 2, "warmup": 0})
    assert res["status"] == "error" and res["x"] is None, res
    assert "status optimal with x None: expected x, shape (n,)" in res["reason"], res["reason"]
