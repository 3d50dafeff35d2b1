"""Tail latency of `hikbench run`: how many repetitions a row gets (at least
``repeat``, up to ``samples`` within ``sample_time``) and its p50/p90/p99/max
columns (hikbench.bench.harness.timing)."""

import json
import time

import numpy as np
import pytest
from doubles import SleepSolver, spec, tiny
from hypothesis import given
from hypothesis import strategies as st

from hikbench.bench.cli import main
from hikbench.bench.harness.results import read_results
from hikbench.bench.harness.runner import _share
from hikbench.bench.harness.timing import SAMPLES, WALL_FACTOR, tail_columns, time_solves
from hikbench.bench.suites import SuiteError, suite_from_dict

PROBLEMS = [{"family": "equality", "params": {"n": 4, "depth": 1, "rows": 2}}]


class SlowBuild(SleepSolver):
    """Built in 20 ms, solved at once: a cold row's time goes to building."""

    def __init__(self):
        time.sleep(0.02)
        super().__init__(0.0)


@pytest.mark.parametrize("mode", ["cold", "warm"])
def test_a_solve_under_sample_time_over_samples_gets_every_sample(mode):
    t = time_solves(SleepSolver, tiny(), repeat=3, mode=mode, samples=SAMPLES, sample_time=1.0)
    assert t.samples_ns.shape == (SAMPLES,)
    assert t.samples_ns.max() < 1e9 / SAMPLES  # (the rule's premise: each solve under T / S)


def test_a_slow_solve_stops_once_its_samples_at_their_median_add_up_to_the_sample_time():
    budget = 0.02
    t = time_solves(lambda: SleepSolver(0.002), tiny(), repeat=2, samples=SAMPLES, sample_time=budget)
    s = t.samples_ns
    assert 2 < len(s) < SAMPLES
    k = len(s)  # it went on while below the budget, and stopped past it
    assert (k - 1) * np.median(s[:-1]) < budget * 1e9 <= k * np.median(s)


class PausedSolver(SleepSolver):
    """A fast solve, but every 10th call of the process waits 20 ms (a pause of the machine)."""

    calls = 0

    def solve(self, hierarchy):
        PausedSolver.calls += 1
        if PausedSolver.calls % 10 == 0:
            time.sleep(0.02)
        return super().solve(hierarchy)


def test_pauses_of_the_machine_do_not_end_a_fast_rows_sampling():
    """Ten pauses of 20 ms add up to twice the budget, their median is a fast solve's: the row
    still gets every sample, and its tail shows the pauses."""
    t = time_solves(PausedSolver, tiny(), repeat=3, mode="warm", samples=SAMPLES, sample_time=0.1)
    assert t.samples_ns.shape == (SAMPLES,)
    tail = tail_columns(t.samples_ns)
    assert tail["time_max_s"] >= 0.02 and tail["time_median_s"] < 1e-3


def test_a_cold_solver_slow_to_build_stops_at_the_wall_limit():
    budget = 0.01  # 10 x: 100 ms of wall time, 20 ms per fresh solver
    t0 = time.perf_counter()
    t = time_solves(SlowBuild, tiny(), repeat=1, samples=SAMPLES, sample_time=budget)
    assert 1 < len(t.samples_ns) <= WALL_FACTOR * budget / 0.02 + 1
    assert len(t.samples_ns) * np.median(t.samples_ns) < budget * 1e9  # (the solves alone would go on)
    assert time.perf_counter() - t0 < 1.0


@pytest.mark.parametrize("samples", [None, 1, 3], ids=["none", "fewer", "equal"])
def test_without_more_samples_than_repeat_the_count_is_repeat(samples):
    t = time_solves(SleepSolver, tiny(), repeat=3, samples=samples, sample_time=10.0)
    assert t.samples_ns.shape == (3,)


@given(st.lists(st.integers(1, 10**9), min_size=1, max_size=300))
def test_the_tail_columns_are_ordered_and_are_the_samples_percentiles(samples):
    c = tail_columns(samples)
    assert c["time_min_s"] <= c["time_median_s"] <= c["time_p90_s"] <= c["time_p99_s"] <= c["time_max_s"]
    s = np.asarray(samples, dtype=float) * 1e-9
    np.testing.assert_allclose([c["time_median_s"], c["time_min_s"], c["time_max_s"]],
                               [np.median(s), s.min(), s.max()], rtol=1e-12, atol=0)
    np.testing.assert_allclose(c["time_p99_s"], np.percentile(s, 99), rtol=1e-12, atol=0)


def test_no_samples_no_time_columns():
    assert tail_columns([]) == {}


@pytest.mark.parametrize("keys, repeat, samples", [
    ({}, 5, SAMPLES),
    ({"repeat": 9}, 9, None),
    ({"repeat": 3, "samples": 100}, 3, 100),
    ({"samples": 20}, 5, 20),
], ids=["default-adaptive", "repeat-alone-fixed", "both", "samples-alone"])
def test_a_suite_that_sets_repeat_alone_fixes_the_count(keys, repeat, samples):
    s = suite_from_dict({**keys, "problems": PROBLEMS}, "s")
    assert (s.repeat, s.samples, s.sample_time) == (repeat, samples, 0.1)


@pytest.mark.parametrize("keys, message", [
    ({"samples": 0}, "samples = 0: expected an integer >= 1"),
    ({"sample_time": 0}, "sample_time = 0: expected a number of seconds > 0"),
], ids=["samples-0", "sample-time-0"])
def test_bad_sample_keys_are_refused(keys, message):
    with pytest.raises(SuiteError, match=message):
        suite_from_dict({**keys, "problems": PROBLEMS}, "s")


def test_rounds_share_the_samples():
    assert [_share(100, 3, r) for r in range(3)] == [34, 33, 33]
    assert _share(None, 3, 0) is None


def test_a_run_times_a_fast_row_to_its_samples_and_repeat_on_the_command_line_fixes_it(tmp_path):
    import tomli_w

    suite = tmp_path / "s.toml"
    suite.write_bytes(tomli_w.dumps({"samples": 40, "warmup": 0, "timeout": 20.0, "modes": ["cold"],
                                     "solvers": [spec("SleepSolver")], "problems": PROBLEMS}).encode())
    out = tmp_path / "out"
    assert main(["run", "--quiet", "--suite", str(suite), "--out", str(out)]) == 0
    (row,) = read_results(out).to_dict("records")
    assert row["repeat"] == 40 and len(json.loads(row["samples_ns"])) == 40
    assert (row["time_min_s"] <= row["time_median_s"] <= row["time_p90_s"] <= row["time_p99_s"]
            <= row["time_max_s"])
    assert row["time_max_s"] == max(json.loads(row["samples_ns"])) * 1e-9
    assert main(["run", "--quiet", "--suite", str(suite), "--out", str(out), "--repeat", "2", "--rerun"]) == 0
    (row,) = read_results(out).to_dict("records")
    assert row["repeat"] == 2
    session = json.loads((out / "run.json").read_text())["sessions"]
    assert [(s["repeat"], s["samples"]) for s in session] == [(5, 40), (2, None)]


def _tail_row(label, problem, strict, verified, times, status="optimal", repeat=100):
    return {"label": label, "problem": problem, "strict": strict, "verified": verified, "status": status,
            "repeat": repeat, **dict(zip(("time_median_s", "time_p90_s", "time_p99_s", "time_max_s"), times))}


def test_the_tail_table_takes_medians_over_the_rows_that_count():
    """A strict solver over its verified rows, a non-strict one over every row with a time."""
    import pandas as pd

    from hikbench.bench.analysis.tail import tail_table

    d = pd.DataFrame([
        _tail_row("a", "p1", True, True, (1.0, 2.0, 3.0, 4.0)),
        _tail_row("a", "p2", True, True, (3.0, 4.0, 5.0, 8.0), repeat=40),
        _tail_row("a", "p3", True, False, (100.0, 100.0, 100.0, 900.0)),  # not verified: left out
        _tail_row("b", "p1", False, False, (10.0, 10.0, 20.0, 40.0)),
        _tail_row("b", "p2", False, False, (np.nan,) * 4, status="unsupported"),
    ])
    a, b = tail_table(d, strict={"a"})
    assert (a["solver"], a["rows"], a["samples_per_row"], a["worst_problem"]) == ("a", 2, 70.0, "p2")
    np.testing.assert_allclose([a["p50_s"], a["p90_s"], a["p99_s"], a["max_s"], a["worst_s"]],
                               [2.0, 3.0, 4.0, 6.0, 8.0], rtol=1e-12, atol=0)
    np.testing.assert_allclose(a["p99_over_p50"], (3.0 + 5.0 / 3.0) / 2, rtol=1e-12, atol=0)
    assert (b["solver"], b["rows"], b["worst_s"], b["p99_over_p50"]) == ("b", 1, 40.0, 2.0)


def test_the_report_shows_the_tail_per_solver(declining_run, tmp_path):
    import shutil

    run = tmp_path / "run"
    shutil.copytree(declining_run, run)
    assert main(["report", str(run)]) == 0
    data = json.loads((run / "report.json").read_text())
    rows = data["tail"]["cold"]
    assert {r["solver"] for r in rows} == {"nullspace-svd", "yardstick"}
    for r in rows:
        assert r["p50_s"] <= r["p90_s"] <= r["p99_s"] <= r["max_s"] <= r["worst_s"], r
    md = (run / "report.md").read_text()
    assert "## Tail latency" in md and "[Tail latency](#tail-latency)" in md
    (table,) = [t for t in data["tables"] if t["key"] == "tail"]
    assert table["columns"][4:8] == ["p50 [us]", "p90 [us]", "p99 [us]", "max [us]"]
