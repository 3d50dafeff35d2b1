"""The first-solve allowance of a worker (docs/running.md, "Isolation", "First solve"): the
untimed first solve of a solver gets ``first_solve_timeout`` when that is larger than the job
timeout, and the job timeout covers it otherwise; the full allowance is given once per solver
and worker (after a restart: the job timeout plus twice the first solve it took);
``run --first-solve-timeout`` overrides the suite's."""

import pandas as pd
import pytest
from doubles import solve_job, spec, tiny


@pytest.mark.parametrize("first_timeout", [None, 1.0], ids=["no-allowance", "allowance-not-larger"])
def test_the_job_timeout_includes_the_first_solve_when_there_is_no_larger_allowance(first_timeout):
    """Without a larger first-solve allowance the job's deadline covers its first (untimed)
    solve, not restarted after it: a job of 2 x 0.6 s does not pass a 1 s hard limit."""
    from hikbench.bench.harness.isolation import IsolatedWorker

    job = {**solve_job(spec("SleepSolver")), "options": {"delay": 0.6}}  # first solve + 1 repetition
    with IsolatedWorker() as w:
        res = w.run(job, timeout=1.0, first_timeout=first_timeout)
    assert res["status"] == "timeout", res
    assert "1 s timeout" in res["reason"]


def test_a_solver_that_hangs_on_every_problem_gets_the_first_solve_allowance_once():
    """A solver whose first solve ran past the allowance gets only the job timeout in the
    restarted process: a backend hanging on every problem costs the job timeout per row, not
    the first-solve allowance (300 s by default) each time."""
    import time

    from hikbench.bench.harness.isolation import IsolatedWorker

    job = solve_job(spec("HangSolver"))
    with IsolatedWorker() as w:
        first = w.run(job, timeout=0.3, first_timeout=2.0)
        t0 = time.monotonic()
        again = w.run(job, timeout=0.3, first_timeout=2.0)
        took = time.monotonic() - t0
    assert first["status"] == "timeout" and "2 s allowed for the first solve;" in first["reason"], first
    assert again["status"] == "timeout", again
    assert again["reason"] == ("no answer within the 0.3 s timeout (no first-solve allowance: this solver's "
                               "first solve ran past the 2 s allowance earlier in this worker); worker killed")
    assert took < 1.5  # the job timeout, not the 2 s allowance (process start included)


def test_after_a_restart_a_solver_gets_twice_its_first_solve_not_the_full_allowance():
    """A solver that completed its first solve, then hung on a later problem: in the
    restarted process its next job gets the job timeout plus twice the first solve it took (its
    caches are on disk), not the full allowance, and a slow first solve still fits."""
    import time

    from hikbench.bench.harness.isolation import IsolatedWorker

    narrow = {**solve_job(spec("HangOnWideSolver")), "hierarchy": tiny(n=4)}
    wide = {**narrow, "hierarchy": tiny(n=8)}
    with IsolatedWorker() as w:
        assert w.run(narrow, timeout=0.3, first_timeout=20.0)["status"] == "optimal"
        hung = w.run(wide, timeout=0.3, first_timeout=20.0)  # warmed in this process: the job timeout
        t0 = time.monotonic()
        again = w.run(wide, timeout=0.3, first_timeout=20.0)  # a fresh process
        took = time.monotonic() - t0
        slow = solve_job(spec("FirstSlowSolver"))  # 1 s first solve in every process
        assert w.run(slow, timeout=0.3, first_timeout=20.0)["status"] == "optimal"
        w.kill()
        assert w.run(slow, timeout=0.3, first_timeout=20.0)["status"] == "optimal"  # 0.3 + 2 x ~1 s
    assert hung["status"] == "timeout" and hung["reason"] == "no answer within the 0.3 s timeout; worker killed"
    assert again["status"] == "timeout", again
    assert "allowed for the first solve (after a restart: the job timeout plus twice this solver's first solve " \
           "before," in again["reason"], again
    assert took < 5  # not the 20 s allowance


@pytest.mark.parametrize("flag, status", [(None, "timeout"), ("5", "optimal")], ids=["suite", "flag"])
def test_first_solve_timeout_flag(tmp_path, flag, status):
    """``run --first-solve-timeout`` overrides the suite's allowance:
    a 1 s first solve under the suite's 0.5 s limit times out, under the flag's 5 s it
    is given its time, and run.json records the allowance used."""
    import json

    from doubles import write_suite

    from hikbench.bench.cli import main

    suite = write_suite(tmp_path / "s.toml", [spec("FirstSlowSolver")], grid={"n": [4], "depth": [1]},
                        modes=("cold",), repeat=1, timeout=0.5)
    out = tmp_path / "out"
    argv = ["run", "--quiet", "--suite", str(suite), "--out", str(out)]
    assert main(argv + (["--first-solve-timeout", flag] if flag else [])) == 0
    rows = pd.read_csv(out / "results.csv")
    assert list(rows["status"]) == [status], rows[["status", "reason"]]
    assert json.loads((out / "run.json").read_text())["suite"]["first_solve_timeout"] == float(flag or 0.5)


def test_first_solve_timeout_flag_must_be_positive(capsys):
    from hikbench.bench.cli import main

    assert main(["run", "--first-solve-timeout", "0"]) == 2
    assert "--first-solve-timeout must be a number of seconds > 0; got 0.0" in capsys.readouterr().err
