"""Runs at scale: Dask executors and the robustness of a run (user-audit defects)."""

from __future__ import annotations

import threading
import time

import pandas as pd
import pytest
from doubles import spec, tiny

from hikbench.bench.harness.executors import DaskExecutor

NO_DASHBOARD = {"dashboard_address": "127.0.0.1:0", "scheduler_kwargs": {"dashboard": False}}  # no port warning


@pytest.fixture(scope="module")
def cluster():
    """A long-lived Dask cluster (in-process, one single-threaded worker) that several runs share."""
    from distributed import LocalCluster

    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, **NO_DASHBOARD) as c:
        yield c


def _solve_job(solver: str, repeat: int = 1) -> dict:
    return {"kind": "solve", "hierarchy": tiny(), "solver": solver, "options": {}, "mode": "cold",
            "repeat": repeat, "warmup": 1}


def _run_on(cluster, items) -> list:
    """(tag, result) of each item, run on ``cluster`` by a DaskExecutor."""
    ex = DaskExecutor(scheduler=cluster.scheduler_address)
    try:
        return list(ex.map(items))
    finally:
        ex.close()


def test_a_second_run_on_the_same_cluster_solves_with_the_edited_solver_file(cluster, tmp_path):
    """Each Dask worker kept one isolated process for its whole life: a second run on a
    long-lived cluster solved with the module of the first run, after the user edited it."""
    path = tmp_path / "mysolver.py"
    text = ("from hikbench.solvers.base import Solver, SolveResult\n"
            "class Versioned(Solver):\n"
            "    name = 'versioned'\n"
            "    def solve(self, h):\n"
            "        return SolveResult(None, 'numerical_failure', reason='version {v}')\n")
    reasons = []
    for version in (1, 2):
        path.write_text(text.format(v=version))
        ((_, res),) = _run_on(cluster, [(0, _solve_job(f"{path}:Versioned"), 10.0)])
        reasons.append(res["reason"])
    assert reasons == ["version 1", "version 2"]


class KillParentSolver:
    """Kills the process that started the isolated worker (here: the Dask worker), like an
    OOM kill of the worker: the job takes its Dask worker down every time it runs."""

    def solve(self, h):
        import os
        import signal
        import time

        os.kill(os.getppid(), signal.SIGKILL)
        time.sleep(30)


@pytest.mark.slow
def test_jobs_that_kill_their_dask_worker_cost_their_rows_only():
    """A job that killed its Dask worker: KilledWorker escaped from DaskExecutor.map (the run
    lost); then, with Dask's defaults, a finished result still on the dying worker or a job
    queued on it was computed again and died with it (a healthy row `crashed`), and under
    repeated deaths the local cluster dropped its nannies (no worker left: the run hung)."""
    killer, healthy = _solve_job(f"{__file__}:KillParentSolver"), _solve_job("hcod")
    items = [(f"kill{i}", killer, 20.0) for i in range(20)] + [(f"ok{i}", healthy, 20.0) for i in range(10)]
    ex = DaskExecutor(workers=2)
    try:
        res = dict(ex.map(items))
    finally:
        ex.close()
    assert sorted(res) == sorted(tag for tag, _, _ in items)
    assert {tag: r["status"] for tag, r in res.items() if tag.startswith("ok")} == {
        f"ok{i}": "optimal" for i in range(10)}
    for i in range(20):
        r = res[f"kill{i}"]
        assert r["status"] == "crashed", r
        assert "died while this job was running on it, also when it ran again alone" in r["reason"], r
        assert "KilledWorker" in r["reason"], r


def test_a_local_cluster_left_without_workers_ends_the_run_with_an_error(monkeypatch):
    """The local cluster lost every worker (its nannies dropped under repeated worker deaths;
    here the cluster is scaled to 0): the run waited for them forever, silently."""
    import hikbench.bench.harness.executors
    from hikbench.problems.errors import HikbenchError

    monkeypatch.setattr(hikbench.bench.harness.executors, "NO_WORKER_GRACE", 1.0)
    ex = DaskExecutor(workers=1)
    try:
        ex.cluster.scale(0)
        while ex.client.nthreads():
            time.sleep(0.05)
        with pytest.raises(HikbenchError, match=r"dask-local:1: the local Dask cluster has had no worker for 1 s "
                                                r".*run the same command again to resume"):
            list(ex.map([(0, _solve_job("hcod"), 10.0)]))
    finally:
        ex.close()


@pytest.mark.parametrize("error, message", [
    (ValueError("no answer"), r"the watchdog could not ask the cluster for its workers \(ValueError: no answer\)"),
    (ConnectionResetError("reset by peer"), (r"the local Dask cluster has had no worker for 1 s \(it could not "
                                             r"be asked: ConnectionResetError: reset by peer\)")),
], ids=["unexpected-error", "connection-error"])
def test_a_watchdog_whose_polls_fail_ends_the_run_with_an_error(monkeypatch, error, message):
    """An error in the watchdog's poll ended only its thread (an unexpected one), or the
    watchdog without a word (a connection error while the client still ran): the run went on
    unguarded (a local cluster losing its workers would then hang). A connection error counts as
    no worker, for the grace."""
    import hikbench.bench.harness.executors
    from hikbench.problems.errors import HikbenchError

    monkeypatch.setattr(hikbench.bench.harness.executors, "NO_WORKER_GRACE", 1.0)
    ex = DaskExecutor(workers=1)
    try:
        def broken():
            raise error
        monkeypatch.setattr(ex.client, "nthreads", broken)
        with pytest.raises(HikbenchError, match=message + r".*run the same command again"):
            list(ex.map([(0, {**_solve_job(spec("SleepSolver")), "options": {"delay": 5.0}}, 30.0)]))
    finally:
        monkeypatch.undo()
        ex.close()


def test_an_external_cluster_without_workers_is_waited_for_with_a_warning(monkeypatch, capsys):
    """A cluster whose workers all left mid-run: the run waited without a word."""
    from distributed import LocalCluster

    import hikbench.bench.harness.executors

    monkeypatch.setattr(hikbench.bench.harness.executors, "NO_WORKER_GRACE", 0.5)
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, **NO_DASHBOARD) as c:
        ex = DaskExecutor(scheduler=c.scheduler_address)
        back = threading.Timer(5.0, c.scale, args=(1,))  # a worker comes back (the warning: after ~2 s)
        try:
            c.scale(0)
            while ex.client.nthreads():
                time.sleep(0.05)
            back.start()
            res = dict(ex.map([(0, _solve_job(spec("SleepSolver")), 10.0)]))
        finally:
            back.cancel()
            ex.close()
    assert res[0]["status"] == "optimal", res[0]
    assert f"hikbench: dask:{c.scheduler_address} has had no worker for 0.5 s; 1 jobs wait" in capsys.readouterr().err


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
    """Only the worker was killed on a timeout: a process the solver started kept running
    (and burning CPU through the timings of the rest of the run, and after it)."""
    from hikbench.bench.harness.isolation import IsolatedWorker

    pidfile = tmp_path / "helper.pid"
    job = {**_solve_job(f"{__file__}:SpawnThenHangSolver"), "options": {"pidfile": str(pidfile)}}
    with IsolatedWorker() as w:
        res = w.run(job, timeout=1.0)
    assert res["status"] == "timeout", res
    assert _gone(int(pidfile.read_text())), "the solver's helper process outlived the timed-out worker"


class _ReferenceCrashes:
    """An executor whose reference jobs come back ``crashed`` (a killed worker, a lost Dask
    worker); the solves run for real."""

    name = "reference-crashes"

    def __init__(self, log):
        from hikbench.bench.harness.executors import SerialExecutor

        self.inner = SerialExecutor(log=log)

    def map(self, items):
        for tag, job, timeout in items:
            if job["kind"] == "yardstick":
                yield tag, {"status": "crashed", "reason": "worker process killed by signal SIGKILL",
                            "x": None, "samples_ns": []}
            else:
                yield from self.inner.map([(tag, job, timeout)])

    def close(self):
        self.inner.close()


def test_a_crashed_reference_is_computed_again_by_the_next_run(tmp_path):
    """A reference that timed out or crashed was cached in OUT/reference/: every later run
    of that --out reused the failure, and none of its rows could be verified."""
    from doubles import write_suite

    from hikbench.bench.harness.results import read_results
    from hikbench.bench.harness.runner import run_suite
    from hikbench.bench.suites import load_suite

    suite = load_suite(str(write_suite(tmp_path / "s.toml", [spec("SleepSolver")],
                                       grid={"n": [4], "depth": [1]})))
    out = tmp_path / "out"
    first = _ReferenceCrashes(out / "worker.log")
    try:
        run_suite(suite, out, executor=first, quiet=True, limit=1)  # the cold row; its reference crashed
    finally:
        first.close()
    run_suite(suite, out, quiet=True)  # the warm row
    df = read_results(out).set_index("mode")
    assert "reference crashed" in df.loc["cold", "reason"] and pd.isna(df.loc["cold", "verified"])
    assert df.loc["warm", "verified"] is True, df.loc["warm", "reason"]


def test_a_scheduler_without_workers_is_a_one_line_error(tmp_path, capsys, monkeypatch):
    """The run waited forever, silently, for a worker that never came."""
    from clitools import assert_user_error, run
    from distributed import LocalCluster
    from doubles import write_suite

    import hikbench.bench.harness.executors

    monkeypatch.setattr(hikbench.bench.harness.executors, "_CONNECT_TIMEOUT", 1.0)
    suite = write_suite(tmp_path / "s.toml", [spec("SleepSolver")], grid={"n": [4], "depth": [1]})
    with LocalCluster(n_workers=0, processes=False, **NO_DASHBOARD) as c:
        code, _, err = run(capsys, "run", "--quiet", "--suite", suite, "--out", tmp_path / "out",
                           "--scheduler", c.scheduler_address)
    assert_user_error(code, err, f"scheduler {c.scheduler_address} has no worker", "dask worker")
    assert not (tmp_path / "out" / "results.csv").exists()


def test_a_scheduler_that_fails_while_waiting_for_workers_leaves_no_client_open(cluster, monkeypatch):
    """Only a timeout while waiting for a worker closed the client: any other error left
    its connection to the scheduler open for the rest of the process."""
    from distributed import Client

    real_close = Client.close
    closed = []
    made = []  # the executor's client (another test's client, collected meanwhile, may close too)

    def lost(self, *args, **kwargs):
        made.append(self)
        raise RuntimeError("the scheduler went away")

    def recording_close(self, *args, **kwargs):
        closed.append(self)
        return real_close(self, *args, **kwargs)

    monkeypatch.setattr(Client, "wait_for_workers", lost)
    monkeypatch.setattr(Client, "close", recording_close)
    with pytest.raises(RuntimeError, match="went away"):
        DaskExecutor(scheduler=cluster.scheduler_address)
    assert len(made) == 1
    assert [c for c in closed if c is made[0]] == made and made[0].status == "closed"


def test_closing_a_local_cluster_whose_client_fails_to_close_still_stops_it(monkeypatch):
    """DaskExecutor.close left the local cluster's worker processes running when the
    client's close raised; the cluster and its dask settings must be undone all the same."""
    import dask
    from distributed import Client

    real_close = Client.close
    failing = []  # the executor's client: any other client that the garbage collector closes
    # meanwhile (from an earlier test) closes as usual

    def failing_close(self, *args, **kwargs):
        if any(self is c for c in failing):
            raise RuntimeError("the client could not close")
        return real_close(self, *args, **kwargs)

    monkeypatch.setattr(Client, "close", failing_close)  # (before: the executor keeps the bound close)
    ex = DaskExecutor(workers=1)
    failing.append(ex.client)
    try:
        assert dask.config.get("distributed.scheduler.allowed-failures") == 0
        with pytest.raises(RuntimeError, match="could not close"):
            ex.close()
        assert ex.cluster.status.name == "closed"
        assert dask.config.get("distributed.scheduler.allowed-failures") != 0
    finally:  # (nothing left behind for the later tests, whatever failed above; the real close back
        # first: the client's __del__ closes it again)
        monkeypatch.setattr(Client, "close", real_close)
        ex.client.close()
        ex.cluster.close()


def test_workers_run_next_to_another_cluster_gives_no_port_warning(tmp_path):
    """--workers N bound the scheduler's HTTP server to port 8787: next to any other Dask
    cluster every run warned "Port 8787 is already in use. Perhaps you already have a
    cluster running?"."""
    import socket
    import warnings

    taken = socket.socket()
    try:
        taken.bind(("127.0.0.1", 8787))
        taken.listen()
    except OSError:  # already taken by another cluster: the case of the defect anyway
        taken.close()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        ex = DaskExecutor(workers=1)
        ex.close()
    taken.close()
    assert not [w for w in caught if "8787" in str(w.message)], [str(w.message) for w in caught]


def _write_run(out, problems, solver="s") -> str:
    """A run directory whose results.csv holds one verified cold row per problem id."""
    import json

    from hikbench.bench.harness.results import ResultsWriter

    with ResultsWriter(out) as w:
        for p in problems:
            w.write({"problem": p, "solver": solver, "settings": "default", "mode": "cold", "status": "optimal",
                     "verified": True, "samples_ns": json.dumps([1000, 1010, 1020]), "time_median_s": 1.01e-6,
                     "calib_ns": 1_000_000, "host": "h"})
    return str(out)


def test_compare_with_no_case_in_common_is_an_error_not_a_pass(tmp_path, capsys):
    """compare exited 0 ("0 slower") after comparing nothing: a CI gate that passes on an
    empty or unrelated run."""
    from clitools import assert_user_error, run

    base = _write_run(tmp_path / "base", ["p0", "p1"])
    for new in (_write_run(tmp_path / "other", ["q0"]), _write_run(tmp_path / "empty", [])):
        code, _, err = run(capsys, "compare", base, new)
        assert_user_error(code, err, f"{base} (2 cases) and {new}", "no case", "in common")


def test_compare_lists_the_cases_only_in_one_run(tmp_path, capsys):
    """The cases in only one run were only counted ("3 only in base"), not listed as documented."""
    from clitools import run

    base = _write_run(tmp_path / "base", ["p0", "p1", "p2", "p3"])
    new = _write_run(tmp_path / "new", ["p0", "p4"])
    code, out, _ = run(capsys, "compare", base, new)
    assert code == 0
    listed = [line.split() for line in out.splitlines() if line.startswith("only in")]
    assert [(words[2], words[-1]) for words in listed] == [
        ("base", "p1"), ("base", "p2"), ("base", "p3"), ("new", "p4")]


def test_a_header_cut_off_by_a_kill_is_written_again(tmp_path):
    """A run killed while writing the header left a partial line; it was cut off, and the rows
    were then appended to the empty file without a header (the first row read as the header)."""
    from hikbench.bench.harness.columns import names
    from hikbench.bench.harness.results import RESULTS, ResultsWriter, read_results

    out = tmp_path / "out"
    out.mkdir()
    (out / RESULTS).write_text(",".join(names())[:25])  # no newline: the header was not finished
    with ResultsWriter(out) as w:
        w.write({"problem": "p0", "solver": "s", "settings": "default", "mode": "cold", "status": "optimal"})
    df = read_results(out)
    assert list(df.columns) == names() and list(df["problem"]) == ["p0"]



def test_a_row_still_being_written_is_not_read(tmp_path):
    """report / claims on a run in progress read the half-written last row as a row with
    status, mode and verified all NaN (charged as a failure in the report)."""
    from hikbench.bench.harness.results import RESULTS, read_results

    out = tmp_path / "out"
    _write_run(out, ["p0", "p1"])
    path = out / RESULTS
    text = path.read_text()
    path.write_text(text[:text.rstrip("\n").rfind("\n") + 12])  # the second row cut after 11 characters
    df = read_results(out)
    assert list(df["problem"]) == ["p0"] and list(df["status"]) == ["optimal"]

@pytest.mark.parametrize("text, message", [('{"suite": ', "not valid JSON"), ("[1, 2]", "got a list")],
                         ids=["truncated", "not-an-object"])
def test_a_damaged_run_json_is_a_one_line_error(tmp_path, capsys, text, message):
    """A truncated or hand-damaged run.json gave a JSONDecodeError traceback (compare, run)."""
    from clitools import assert_user_error, run

    base = _write_run(tmp_path / "base", ["p0"])
    new = _write_run(tmp_path / "new", ["p0"])
    (tmp_path / "new" / "run.json").write_text(text)
    code, _, err = run(capsys, "compare", base, new)
    assert_user_error(code, err, f"{new}/run.json", message, "expected")


def test_a_relative_solver_file_is_found_by_workers_running_elsewhere(tmp_path, monkeypatch):
    """--solvers mysolver.py:Class was passed as is to the workers: a Dask worker started in
    another directory found no such file, and every row was an `error` (finished: never run
    again on resume)."""
    from distributed import LocalCluster
    from doubles import write_suite

    from hikbench.bench.cli import main
    from hikbench.bench.harness.results import read_results

    (tmp_path / "workers").mkdir()
    (tmp_path / "user").mkdir()
    (tmp_path / "user" / "mysolver.py").write_text(
        "from hikbench.solvers.base import OPTIMAL, Solver, SolveResult\n"
        "from hikbench.solvers.yardstick import nullspace_yardstick\n"
        "class Mine(Solver):\n"
        "    name = 'mine'\n"
        "    def solve(self, h):\n"
        "        return SolveResult(nullspace_yardstick(h), OPTIMAL)\n")
    suite = write_suite(tmp_path / "s.toml", ["yardstick"], grid={"n": [4], "depth": [1]}, modes=("cold",))
    monkeypatch.chdir(tmp_path / "workers")
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, **NO_DASHBOARD) as c:
        monkeypatch.chdir(tmp_path / "user")
        assert main(["run", "--quiet", "--suite", str(suite), "--out", str(tmp_path / "out"),
                     "--scheduler", c.scheduler_address, "--solvers", "mysolver.py:Mine"]) == 0
    row = read_results(tmp_path / "out").iloc[0]
    assert (row["solver"], row["status"], row["verified"]) == ("mine", "optimal", True), row["reason"]


def test_a_lost_scheduler_is_an_error_that_says_how_to_resume(cluster, tmp_path):
    """A scheduler that went away mid-run (its futures cancelled) ended the run with a
    FutureCancelledError traceback."""
    import threading

    from distributed import Future

    from hikbench.problems.errors import HikbenchError

    ex = DaskExecutor(scheduler=cluster.scheduler_address)
    items = [(0, _solve_job(spec("SleepSolver")), 10.0),
             (1, {**_solve_job(spec("SleepSolver")), "options": {"delay": 1.0}}, 10.0)]
    got = []
    try:
        def cancel_all():  # what the client does to every future when it loses its scheduler
            ex.client.cancel([Future(k, ex.client) for k in list(ex.client.futures)])

        with pytest.raises(HikbenchError, match="a job was cancelled .*run the same command again to resume"):
            for tag, res in ex.map(items):
                got.append(tag)
                threading.Timer(0.2, cancel_all).start()
    finally:
        ex.close()
    assert got == [0]


@pytest.mark.parametrize("first_timeout", [None, 1.0], ids=["no-allowance", "allowance-not-larger"])
def test_the_job_timeout_includes_the_first_solve_when_there_is_no_larger_allowance(first_timeout):
    """The deadline was restarted after the job's first (untimed) solve even when no larger
    first-solve allowance applied: a job of 2 x 0.6 s passed a 1 s hard limit as `optimal`."""
    from hikbench.bench.harness.isolation import IsolatedWorker

    job = {**_solve_job(spec("SleepSolver")), "options": {"delay": 0.6}}  # first solve + 1 repetition
    with IsolatedWorker() as w:
        res = w.run(job, timeout=1.0, first_timeout=first_timeout)
    assert res["status"] == "timeout", res
    assert "1 s timeout" in res["reason"]


def test_a_dask_worker_with_several_threads_keeps_each_result_with_its_job():
    """Every thread of a Dask worker shared one isolated process: with `dask worker ADDR`
    (one thread per core by default) two jobs wrote to the same channel at once and read
    each other's answers (KeyError 'status' traceback, or a row given another job's x)."""
    from distributed import LocalCluster

    sizes = [4, 5, 6, 7, 8, 9]
    items = [(n, {**_solve_job(spec("SleepSolver")), "hierarchy": tiny(n=n), "options": {"delay": 0.02}}, 20.0)
             for n in sizes]
    with LocalCluster(n_workers=1, threads_per_worker=2, processes=False, **NO_DASHBOARD) as c:
        got = dict(_run_on(c, items))
    assert sorted(got) == sizes
    assert {n: (res["status"], len(res["x"])) for n, res in got.items()} == {n: ("optimal", n) for n in sizes}
    assert len({res["pid"] for res in got.values()}) == 2  # one isolated process per thread


class ReadsStdinSolver:
    """Reads its standard input (a prompt, a library probing stdin), then solves."""

    def solve(self, h):
        import sys

        from hikbench.solvers.base import OPTIMAL, SolveResult
        from hikbench.solvers.yardstick import nullspace_yardstick

        data = sys.stdin.buffer.read(4)
        return SolveResult(nullspace_yardstick(h), OPTIMAL, reason=f"stdin gave {data!r}")


def test_a_solver_reading_stdin_reads_nothing_instead_of_the_job_channel():
    """The worker's stdin was the job channel: a solver reading it waited there until the
    job timeout (a `timeout` row whose reason blamed the solver's speed)."""
    from hikbench.bench.harness.isolation import IsolatedWorker

    with IsolatedWorker() as w:
        res = w.run(_solve_job(f"{__file__}:ReadsStdinSolver"), timeout=3.0)
        again = w.run(_solve_job(spec("SleepSolver")), timeout=3.0)  # the channel still works
    assert (res["status"], res["reason"]) == ("optimal", "stdin gave b''"), res
    assert again["status"] == "optimal", again


@pytest.mark.parametrize("kind, message", [("directory", "not a file"), ("binary", "not a text file")],
                         ids=["directory", "binary"])
def test_a_suite_path_that_is_no_toml_text_is_a_one_line_error(tmp_path, capsys, kind, message):
    """--suite DIR gave an IsADirectoryError traceback; a binary file a UnicodeDecodeError one."""
    from clitools import assert_user_error, run

    path = tmp_path / "suite"
    if kind == "directory":
        path.mkdir()
    else:
        path.write_bytes(b"\xff\xfe\x00binary")
    code, _, err = run(capsys, "run", "--quiet", "--suite", path, "--out", tmp_path / "out")
    assert_user_error(code, err, str(path), message)


@pytest.mark.parametrize("content, message", [
    (b"problem,solver,settings,mode,status\np,s,default,cold,optimal\n", "columns differ from this version's"),
    (b"\xff\xfe\x00\x01", "not a text file"),
    (b"", "no case (problem, solver, settings, mode) in common"),  # no header: no rows
], ids=["other-columns", "binary", "empty"])
def test_compare_on_a_foreign_or_damaged_results_csv_is_a_one_line_error(tmp_path, capsys, content, message):
    """read_results trusted any results.csv: KeyError 'reason', UnicodeDecodeError or
    EmptyDataError tracebacks."""
    from clitools import assert_user_error, run

    base = tmp_path / "base"
    base.mkdir()
    (base / "results.csv").write_bytes(content)
    new = _write_run(tmp_path / "new", ["p0"])
    code, _, err = run(capsys, "compare", base, new)
    assert_user_error(code, err, str(base), message)


def test_a_solver_that_hangs_on_every_problem_gets_the_first_solve_allowance_once():
    """Each timeout restarted the process, and the next job of the solver got the full
    first-solve allowance again (300 s by default): a backend hanging on every problem cost
    the allowance per row, not the job timeout."""
    import time

    from hikbench.bench.harness.isolation import IsolatedWorker

    job = _solve_job(spec("HangSolver"))
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
    """A solver that completed its first solve, then hung on a later problem: the restarted
    process gave its next job the full allowance again. Now it gets the job timeout plus twice
    the first solve it took (its caches are on disk), and a slow first solve still fits."""
    import time

    from hikbench.bench.harness.isolation import IsolatedWorker

    narrow = {**_solve_job(spec("HangOnWideSolver")), "hierarchy": tiny(n=4)}
    wide = {**narrow, "hierarchy": tiny(n=8)}
    with IsolatedWorker() as w:
        assert w.run(narrow, timeout=0.3, first_timeout=20.0)["status"] == "optimal"
        hung = w.run(wide, timeout=0.3, first_timeout=20.0)  # warmed in this process: the job timeout
        t0 = time.monotonic()
        again = w.run(wide, timeout=0.3, first_timeout=20.0)  # a fresh process
        took = time.monotonic() - t0
        slow = _solve_job(spec("FirstSlowSolver"))  # 1 s first solve in every process
        assert w.run(slow, timeout=0.3, first_timeout=20.0)["status"] == "optimal"
        w.kill()
        assert w.run(slow, timeout=0.3, first_timeout=20.0)["status"] == "optimal"  # 0.3 + 2 x ~1 s
    assert hung["status"] == "timeout" and hung["reason"] == "no answer within the 0.3 s timeout; worker killed"
    assert again["status"] == "timeout", again
    assert "allowed for the first solve (after a restart: the job timeout plus twice this solver's first solve " \
           "before," in again["reason"], again
    assert took < 5  # not the 20 s allowance


@pytest.mark.parametrize("greeting, fragment", [
    (None, "sent nothing within 0.5 s"),
    (b"SSH-2.0-OpenSSH_9.2\r\n", "does not speak Dask's protocol (it sent b'SSH-2.0-')"),
    (b"", "closed the connection at once"),
], ids=["silent-http-port", "banner", "closes"])
def test_a_scheduler_address_that_is_not_a_dask_scheduler_is_a_one_line_error(tmp_path, capsys, monkeypatch,
                                                                               greeting, fragment):
    """--scheduler at the dashboard's HTTP port (which waits for a request) hung the run for good:
    Client waits for the scheduler's handshake without a time limit. A port that sent a banner
    made Client read its first 8 bytes as a message length and allocate exabytes (a traceback)."""
    import socket

    from clitools import assert_user_error, run
    from doubles import write_suite

    import hikbench.bench.harness.executors

    monkeypatch.setattr(hikbench.bench.harness.executors, "_CONNECT_TIMEOUT", 0.5)
    server = socket.create_server(("127.0.0.1", 0))
    port = server.getsockname()[1]

    def serve():
        conn, _ = server.accept()
        with conn:
            if greeting is None:
                time.sleep(2.0)  # an HTTP server: silent until it gets a request
            else:
                conn.sendall(greeting)

    t = threading.Thread(target=serve, daemon=True)
    t.start()
    suite = write_suite(tmp_path / "s.toml", [spec("SleepSolver")], grid={"n": [4], "depth": [1]})
    try:
        code, _, err = run(capsys, "run", "--quiet", "--suite", suite, "--out", tmp_path / "out",
                           "--scheduler", f"tcp://127.0.0.1:{port}")
    finally:
        t.join(5)
        server.close()
    assert_user_error(code, err, f"--scheduler tcp://127.0.0.1:{port}: {fragment}; expected a Dask scheduler's "
                                 "address (not its dashboard's HTTP port")
    assert not (tmp_path / "out" / "results.csv").exists()


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
