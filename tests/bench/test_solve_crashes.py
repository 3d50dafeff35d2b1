"""``hikbench solve`` reports a solver that kills its process (segfault, abort,
sys.exit) as status ``crashed`` with the signal or exit code, exit 1, like
``run`` (bench/commands/solve.py runs the solver in a forked child)."""

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
    (f"{CRASH}:ChattyExitSolver", "exited with code 0 before it answered"),
], ids=["segfault", "abort", "sys.exit(3)", "os._exit(0)"])
def test_a_solver_ending_its_process_is_reported_crashed(tmp_path, solver, how):
    code, out, err = _solve(tmp_path, solver)
    assert code == 1, (code, out, err)
    assert f"status      crashed (solver process {how})" in out, out
    assert "Traceback" not in err, err


def test_a_crash_in_json_is_one_object(tmp_path):
    code, out, _ = _solve(tmp_path, spec("SegfaultSolver"), "--json")
    assert code == 1
    got = json.loads(out)
    assert got["status"] == "crashed" and got["reason"] == "solver process killed by signal SIGSEGV"
    assert got["x"] is None and got["time_s"] is None


def test_a_wrong_option_is_still_a_one_line_user_error(tmp_path):
    code, out, err = _solve(tmp_path, "yardstick", "--option", "nope=1")
    assert code == 2 and len(err.strip().splitlines()) == 1 and "nope" in err, err
    assert out == ""


def test_a_normal_solve_answers_from_the_child(tmp_path):
    code, out, err = _solve(tmp_path, spec("SleepSolver"), "--json", "--repeat", "2")
    assert code == 0, err
    got = json.loads(out)
    assert got["status"] == "optimal" and len(got["x"]) == 6 and got["iterations"] == 1
    assert got["time_s"]["min"] <= got["time_s"]["median"]
