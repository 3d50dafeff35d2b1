"""The isolated worker process of a job (hikbench.bench.harness.isolation, docs/running.md
"Isolation"): a timed-out solve is killed with every process its solver started, and a solver
that reads its standard input reads nothing (the job channel is not its stdin)."""

from doubles import solve_job, spec


class SpawnThenHangSolver:
    """Starts a helper process (its pid written to the file named by the option), then hangs."""

    def __init__(self, pidfile: str):
        self.pidfile = pidfile

    def solve(self, h):
        import subprocess
        import sys
        import time

        helper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
        with open(self.pidfile, "w") as f:
            f.write(str(helper.pid))
        while True:
            time.sleep(0.05)


def _gone(pid: int, within: float = 5.0) -> bool:
    """The process ``pid`` is dead (or a zombie) within ``within`` seconds."""
    import os
    import time
    from pathlib import Path

    end = time.monotonic() + within
    while time.monotonic() < end:
        stat = Path(f"/proc/{pid}/stat")
        if not stat.exists() or stat.read_text().rsplit(")", 1)[1].split()[0] == "Z":
            return True
        time.sleep(0.05)
    os.kill(pid, 9)  # (the test's own helper: do not leave it behind)
    return False


def test_a_timed_out_solve_leaves_no_helper_process_behind(tmp_path):
    """A timeout kills the processes the solver started with the worker: left running, they
    would burn CPU through the timings of the rest of the run, and after it."""
    from hikbench.bench.harness.isolation import IsolatedWorker

    pidfile = tmp_path / "helper.pid"
    job = {**solve_job(f"{__file__}:SpawnThenHangSolver"), "options": {"pidfile": str(pidfile)}}
    with IsolatedWorker() as w:
        res = w.run(job, timeout=1.0)
    assert res["status"] == "timeout", res
    assert _gone(int(pidfile.read_text())), "the solver's helper process outlived the timed-out worker"


class ReadsStdinSolver:
    """Reads its standard input (a prompt, a library probing stdin), then solves."""

    def solve(self, h):
        import sys

        from hikbench.solvers.base import OPTIMAL, SolveResult
        from hikbench.solvers.yardstick import nullspace_yardstick

        data = sys.stdin.buffer.read(4)
        return SolveResult(nullspace_yardstick(h), OPTIMAL, reason=f"stdin gave {data!r}")


def test_a_solver_reading_stdin_reads_nothing_instead_of_the_job_channel():
    """The worker's stdin is not the job channel: a solver reading stdin gets nothing at once
    (reading the channel, it would wait until the job timeout: a `timeout` row whose reason
    blames the solver's speed), and the channel still works after it."""
    from hikbench.bench.harness.isolation import IsolatedWorker

    with IsolatedWorker() as w:
        res = w.run(solve_job(f"{__file__}:ReadsStdinSolver"), timeout=3.0)
        again = w.run(solve_job(spec("SleepSolver")), timeout=3.0)  # the channel still works
    assert (res["status"], res["reason"]) == ("optimal", "stdin gave b''"), res
    assert again["status"] == "optimal", again
