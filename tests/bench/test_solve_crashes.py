"""``hikbench solve`` reports a solver that kills its process (segfault, abort,
sys.exit) as status ``crashed`` with the signal or exit code, and one that never
returns as status ``timeout``, exit 1, like ``run`` (bench/commands/solve.py runs
the solve in the isolated worker of ``run``: bench/harness/isolation.py)."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest
from clitools import start
from doubles import spec, tiny

from hikbench.problems.files import save_npz

CRASH = Path(__file__).with_name("crash_doubles.py")


def _solve(tmp_path, solver: str, *extra):
    save_npz(tiny(), tmp_path / "p.npz")
    proc = start(["solve", tmp_path / "p.npz", "--solver", solver, *extra], tmp_path,
                 stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    out, err = proc.communicate(timeout=120)
    return proc.returncode, out, err


@pytest.mark.parametrize("solver, how", [
    (spec("SegfaultSolver"), "killed by signal SIGSEGV"),
    (f"{CRASH}:AbortSolver", "killed by signal SIGABRT"),
    (f"{CRASH}:ExitSolver", "exited with code 3"),
    (f"{CRASH}:ChattyExitSolver", "exited with code 0"),
], ids=["segfault", "abort", "sys.exit(3)", "os._exit(0)"])
def test_a_solver_ending_its_process_is_reported_crashed(tmp_path, solver, how):
    code, out, err = _solve(tmp_path, solver)
    assert code == 1, (code, out, err)
    assert f"status      crashed (worker process {how})" in out, out
    assert "Traceback" not in err, err


def test_a_crash_in_json_is_one_object(tmp_path):
    code, out, _ = _solve(tmp_path, spec("SegfaultSolver"), "--json")
    assert code == 1
    got = json.loads(out)
    assert got["status"] == "crashed" and got["reason"] == "worker process killed by signal SIGSEGV"
    assert got["x"] is None and got["time_s"] is None


@pytest.mark.parametrize("solver, first", [(spec("HangSolver"), "2"), (spec("SpinSolver"), "2")],
                         ids=["python-sleep-loop", "numba-loop-holding-the-gil"])
def test_a_solver_that_never_returns_is_a_one_line_timeout(tmp_path, solver, first):
    """A hang costs the allowance and a `timeout` line, exit 1: not a hung command."""
    import time

    t0 = time.monotonic()
    code, out, err = _solve(tmp_path, solver, "--timeout", "1", "--first-solve-timeout", first)
    assert code == 1, (code, out, err)
    assert out.splitlines()[1] == ("status      timeout (no answer within the 2 s allowed for the first solve; "
                                   "worker killed)"), out
    assert time.monotonic() - t0 < 60 and "Traceback" not in err, err


def test_a_hang_after_the_first_solve_gets_the_job_timeout_in_json(tmp_path):
    code, out, _ = _solve(tmp_path, f"{CRASH}:HangAfterFirstSolver", "--timeout", "1", "--json")
    got = json.loads(out)
    assert code == 1 and got["status"] == "timeout" and got["x"] is None and got["time_s"] is None
    assert got["reason"] == "no answer within the 1 s timeout; worker killed"


def test_the_timeouts_must_be_seconds(tmp_path):
    code, out, err = _solve(tmp_path, "yardstick", "--timeout", "0")
    assert code == 2 and err.strip().endswith("--timeout must be a number of seconds > 0; got 0.0"), err


def test_a_wrong_option_is_still_a_one_line_user_error(tmp_path):
    code, out, err = _solve(tmp_path, "yardstick", "--option", "nope=1")
    assert code == 2 and len(err.strip().splitlines()) == 1 and "nope" in err, err
    assert out == ""


def test_a_normal_solve_answers_from_the_worker(tmp_path):
    code, out, err = _solve(tmp_path, spec("SleepSolver"), "--json", "--repeat", "2")
    assert code == 0, err
    got = json.loads(out)
    assert got["status"] == "optimal" and len(got["x"]) == 6 and got["iterations"] == 1
    assert got["time_s"]["min"] <= got["time_s"]["median"]
