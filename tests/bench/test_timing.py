"""hikbench.bench.harness.timing: a row reports its worst timed repetition, not only the last
(a solver whose answer changes between repetitions is judged on its worst)."""

import numpy as np
import pytest
from doubles import FlakySolver, spec, tiny, write_suite

from hikbench.bench.cli import main
from hikbench.bench.harness.results import read_results
from hikbench.bench.harness.timing import reported_result, time_solves
from hikbench.solvers.base import MAX_ITERATIONS, OPTIMAL, SolveResult
from hikbench.solvers.yardstick import nullspace_yardstick


@pytest.fixture
def h():
    return tiny(seed=3, n=6, depth=2, rows=2)


@pytest.mark.parametrize("mode", ["cold", "warm"])
def test_a_repetition_worse_than_the_last_is_the_one_reported(h, mode):
    FlakySolver.calls = 0  # one warm-up solve, then 3 timed: the last (the 4th call) is correct
    t = time_solves(FlakySolver, h, repeat=3, mode=mode)
    assert FlakySolver.calls % 2 == 0  # the last timed solve was the correct one
    np.testing.assert_allclose(t.result.x, nullspace_yardstick(h) + 1.0, rtol=0, atol=1e-12)
    assert "of 3 is reported: its x is above the last's at level 0" in t.result.reason
    assert t.samples_ns.shape == (3,)


def test_repetitions_with_one_answer_report_the_last(h):
    x = nullspace_yardstick(h)
    results = [SolveResult(x.copy(), OPTIMAL, iterations=i) for i in (1, 2, 3)]
    results[0].x[0] += 1e-13  # within 1e-9 of the level's scale
    got = reported_result(results, h)
    assert got is results[-1] and got.reason == ""


def test_a_better_earlier_repetition_is_not_reported(h):
    x = nullspace_yardstick(h)
    results = [SolveResult(x, OPTIMAL), SolveResult(x + 1.0, OPTIMAL)]
    assert reported_result(results, h) is results[-1]


def test_the_worst_of_several_worse_repetitions_is_reported(h):
    x = nullspace_yardstick(h)
    results = [SolveResult(x + 1.0, OPTIMAL), SolveResult(x + 5.0, OPTIMAL), SolveResult(x + 2.0, OPTIMAL),
               SolveResult(x, OPTIMAL)]
    got = reported_result(results, h)
    np.testing.assert_allclose(got.x, x + 5.0, rtol=0, atol=0)
    assert got.reason.startswith("repetition 2 of 4 is reported")


def test_a_status_other_than_optimal_before_an_optimal_last_is_reported(h):
    x = nullspace_yardstick(h)
    results = [SolveResult(x, OPTIMAL), SolveResult(x, MAX_ITERATIONS, reason="cap 10 hit"),
               SolveResult(x, OPTIMAL)]
    got = reported_result(results, h)
    assert got.status == MAX_ITERATIONS
    assert got.reason == "cap 10 hit; repetition 2 of 3 is reported: the last gave status optimal"


def test_a_run_row_of_a_solver_wrong_on_an_earlier_repetition_is_not_verified(tmp_path):
    suite = write_suite(tmp_path / "s.toml", [spec("FlakySolver")], grid={"n": [6], "depth": [2]},
                        repeat=4, modes=("cold",))
    out = tmp_path / "out"
    assert main(["run", "--quiet", "--suite", str(suite), "--out", str(out)]) == 0
    (row,) = read_results(out).to_dict("records")
    assert row["status"] == OPTIMAL
    assert not row["verified"]
    assert "of 4 is reported: its x is above the last's" in row["reason"]
