"""Solvers that break the harness rather than the solve: one `run` cannot construct (refused
before any job, exit 2), one whose result cannot be pickled (status error with the cause),
one that writes into the worker's job channel (its real answer is still its row)."""

from pathlib import Path

import numpy as np
import pytest
from doubles import solve_job, tiny, write_suite

from hikbench.bench.cli import main
from hikbench.bench.harness.isolation import IsolatedWorker
from hikbench.solvers.yardstick import nullspace_yardstick

FAULTS = str(Path(__file__).with_name("fault_doubles.py"))


def fault(name: str) -> str:
    return f"{FAULTS}:{name}"


@pytest.mark.parametrize("where", ["suite", "--solvers"])
def test_run_refuses_a_solver_it_cannot_construct_before_any_job(tmp_path, capsys, where):
    """It gave one error row per job and exit 0 (solve refused it with exit 2)."""
    solvers = [fault("NeedsArgSolver")] if where == "suite" else ["yardstick"]
    path = write_suite(tmp_path / "s.toml", solvers, grid={"n": [4]}, modes=("cold",))
    extra = ["--solvers", fault("NeedsArgSolver")] if where == "--solvers" else []
    out = tmp_path / "out"
    assert main(["run", "--quiet", "--suite", str(path), "--out", str(out), *extra]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("hikbench run: error: "), err
    assert "solver 'needs-arg'" in err[0] and "'alpha'" in err[0], err
    assert not (out / "results.csv").exists()


def test_solve_refuses_the_same_solver(capsys, tmp_path):
    from hikbench.problems.files import save_npz

    save_npz(tiny(), tmp_path / "p.npz")
    assert main(["solve", str(tmp_path / "p.npz"), "--solver", fault("NeedsArgSolver")]) == 2
    assert "'alpha'" in capsys.readouterr().err


def test_a_result_that_cannot_be_pickled_is_an_error_row_with_its_cause():
    """It was `crashed` "worker process exited with code 1", the cause in worker.log only."""
    with IsolatedWorker() as w:
        res = w.run(solve_job(fault("UnpicklableResultSolver")), timeout=10.0)
        again = w.run(solve_job(fault("ChannelWriterSolver")), timeout=10.0)  # the worker goes on
    assert res["status"] == "error", res
    assert "cannot be sent back" in res["reason"] and "lambda" in res["reason"], res["reason"]
    assert again["status"] == "optimal", again


@pytest.mark.parametrize("garbage, times", [
    ("ff" * 8, 1),                      # a header announcing 2**64 - 1 bytes
    ("0400000000000000" + "00" * 4, 1),  # a header announcing 4 bytes, then 4 bytes that are no pickle
    (b"not a frame\n".hex(), 1),
    ("ab" * 4096, 64),                  # 512 KiB
], ids=["huge-size", "small-size", "text", "half-megabyte"])
def test_a_solver_writing_into_the_job_channel_still_gets_its_answer(garbage, times):
    """It was status `timeout` (the harness waited for the bytes the garbage announced)."""
    job = {**solve_job(fault("ChannelWriterSolver")), "options": {"garbage": garbage, "times": times}}
    with IsolatedWorker() as w:
        res = w.run(job, timeout=10.0)
        again = w.run(solve_job(fault("ChannelWriterSolver")), timeout=10.0)
    assert res["status"] == "optimal", res
    np.testing.assert_allclose(res["x"], nullspace_yardstick(tiny()), rtol=1e-12, atol=1e-12)
    assert again["status"] == "optimal", again
