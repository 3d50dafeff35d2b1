"""Runs on Dask (hikbench.bench.harness.executors.DaskExecutor, docs/running.md "Scale-out on
Dask"): a long-lived cluster runs the solver file as edited now; a job that kills its Dask worker
costs its own row only; a cluster left without workers, a failing watchdog poll, a lost
scheduler or an address that is not a Dask scheduler end the run with one line that says how to
resume; several threads per worker keep each result with its job; a relative solver file is
found by workers started elsewhere."""

from __future__ import annotations

import threading
import time

import pytest
from doubles import solve_job, spec, tiny

from hikbench.bench.harness.executors import DaskExecutor

NO_DASHBOARD = {"dashboard_address": "127.0.0.1:0", "scheduler_kwargs": {"dashboard": False}}  # no port warning


@pytest.fixture(scope="module")
def cluster():
    """A long-lived Dask cluster (in-process, one single-threaded worker) that several runs share."""
    from distributed import LocalCluster

    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, **NO_DASHBOARD) as c:
        yield c


def _run_on(cluster, items) -> list:
    """(tag, result) of each item, run on ``cluster`` by a DaskExecutor."""
    ex = DaskExecutor(scheduler=cluster.scheduler_address)
    try:
        return list(ex.map(items))
    finally:
        ex.close()


def test_a_second_run_on_the_same_cluster_solves_with_the_edited_solver_file(cluster, tmp_path):
    """A second run on a long-lived cluster solves with the solver file as the user edited it
    after the first run, not with the module the worker's isolated process loaded then."""
    path = tmp_path / "mysolver.py"
    text = ("from hikbench.solvers.base import Solver, SolveResult\n"
            "class Versioned(Solver):\n"
            "    name = 'versioned'\n"
            "    def solve(self, h):\n"
            "        return SolveResult(None, 'numerical_failure', reason='version {v}')\n")
    reasons = []
    for version in (1, 2):
        path.write_text(text.format(v=version))
        ((_, res),) = _run_on(cluster, [(0, solve_job(f"{path}:Versioned"), 10.0)])
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
    """Jobs that kill their Dask worker are `crashed` rows, and nothing else is lost: no
    KilledWorker escapes DaskExecutor.map; a finished result still on the dying worker or a job
    queued on it is not lost with it (Dask's defaults would compute it again there and give a
    healthy row `crashed`); under repeated deaths the local cluster keeps its nannies (Dask's
    defaults drop them: no worker left, the run would hang)."""
    killer, healthy = solve_job(f"{__file__}:KillParentSolver"), solve_job("hcod")
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
    """A local cluster that has lost every worker (here: scaled to 0) ends the run after the
    grace with an error that says how to resume, instead of waiting for workers forever."""
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
            list(ex.map([(0, solve_job("hcod"), 10.0)]))
    finally:
        ex.close()


@pytest.mark.parametrize("error, message", [
    (ValueError("no answer"), r"the watchdog could not ask the cluster for its workers \(ValueError: no answer\)"),
    (ConnectionResetError("reset by peer"), (r"the local Dask cluster has had no worker for 1 s \(it could not "
                                             r"be asked: ConnectionResetError: reset by peer\)")),
], ids=["unexpected-error", "connection-error"])
def test_a_watchdog_whose_polls_fail_ends_the_run_with_an_error(monkeypatch, error, message):
    """An error in the watchdog's poll ends the run with an error, not only the watchdog's
    thread (an unexpected error) or the watchdog without a word (a connection error while the
    client still runs): an unguarded run would hang when a local cluster loses its workers. A
    connection error counts as no worker, for the grace."""
    import hikbench.bench.harness.executors
    from hikbench.problems.errors import HikbenchError

    monkeypatch.setattr(hikbench.bench.harness.executors, "NO_WORKER_GRACE", 1.0)
    ex = DaskExecutor(workers=1)
    try:
        def broken():
            raise error
        monkeypatch.setattr(ex.client, "nthreads", broken)
        with pytest.raises(HikbenchError, match=message + r".*run the same command again"):
            list(ex.map([(0, {**solve_job(spec("SleepSolver")), "options": {"delay": 5.0}}, 30.0)]))
    finally:
        monkeypatch.undo()
        ex.close()


def test_an_external_cluster_without_workers_is_waited_for_with_a_warning(monkeypatch, capsys):
    """A cluster whose workers all left mid-run: the run waits for them and says so."""
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
            res = dict(ex.map([(0, solve_job(spec("SleepSolver")), 10.0)]))
        finally:
            back.cancel()
            ex.close()
    assert res[0]["status"] == "optimal", res[0]
    assert f"hikbench: dask:{c.scheduler_address} has had no worker for 0.5 s; 1 jobs wait" in capsys.readouterr().err


def test_a_scheduler_without_workers_is_a_one_line_error(tmp_path, capsys, monkeypatch):
    """A scheduler that has no worker when the run starts: one line, not a silent wait."""
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
    """Any error while waiting for a worker closes the client, not only a timeout: no
    connection to the scheduler stays open for the rest of the process."""
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
    """DaskExecutor.close stops the local cluster's worker processes and undoes its dask
    settings even when the client's close raises."""
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
    """--workers N does not bind the scheduler's HTTP server to port 8787: next to any other
    Dask cluster a run gives no warning "Port 8787 is already in use. Perhaps you already have a
    cluster running?"."""
    import socket
    import warnings

    taken = socket.socket()
    try:
        taken.bind(("127.0.0.1", 8787))
        taken.listen()
    except OSError:  # already taken by another cluster: the case under test anyway
        taken.close()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        ex = DaskExecutor(workers=1)
        ex.close()
    taken.close()
    assert not [w for w in caught if "8787" in str(w.message)], [str(w.message) for w in caught]


def test_a_relative_solver_file_is_found_by_workers_running_elsewhere(tmp_path, monkeypatch):
    """--solvers mysolver.py:Class reaches the workers as an absolute path: a Dask worker
    started in another directory finds the file (a relative path there would make every row an
    `error`, finished: never run again on resume)."""
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
    """A scheduler that goes away mid-run (its futures cancelled) ends the run with an error
    that says how to resume, not a FutureCancelledError traceback."""
    import threading

    from distributed import Future

    from hikbench.problems.errors import HikbenchError

    ex = DaskExecutor(scheduler=cluster.scheduler_address)
    items = [(0, solve_job(spec("SleepSolver")), 10.0),
             (1, {**solve_job(spec("SleepSolver")), "options": {"delay": 1.0}}, 10.0)]
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


def test_a_dask_worker_with_several_threads_keeps_each_result_with_its_job():
    """Each thread of a Dask worker has its own isolated process: with `dask worker ADDR`
    (one thread per core by default) two jobs sharing one process would write to the same
    channel at once and read each other's answers (KeyError 'status' traceback, or a row given
    another job's x)."""
    from distributed import LocalCluster

    sizes = [4, 5, 6, 7, 8, 9]
    items = [(n, {**solve_job(spec("SleepSolver")), "hierarchy": tiny(n=n), "options": {"delay": 0.02}}, 20.0)
             for n in sizes]
    with LocalCluster(n_workers=1, threads_per_worker=2, processes=False, **NO_DASHBOARD) as c:
        got = dict(_run_on(c, items))
    assert sorted(got) == sizes
    assert {n: (res["status"], len(res["x"])) for n, res in got.items()} == {n: ("optimal", n) for n in sizes}
    assert len({res["pid"] for res in got.values()}) == 2  # one isolated process per thread


@pytest.mark.parametrize("greeting, fragment", [
    (None, "sent nothing within 0.5 s"),
    (b"SSH-2.0-OpenSSH_9.2\r\n", "does not speak Dask's protocol (it sent b'SSH-2.0-')"),
    (b"", "closed the connection at once"),
], ids=["silent-http-port", "banner", "closes"])
def test_a_scheduler_address_that_is_not_a_dask_scheduler_is_a_one_line_error(tmp_path, capsys, monkeypatch,
                                                                               greeting, fragment):
    """--scheduler at the dashboard's HTTP port (which waits for a request), at a port that
    sends a banner or at one that closes at once: a one-line error. (Client waits for the
    scheduler's handshake without a time limit, and reads a banner's first 8 bytes as a message
    length: exabytes to allocate, a traceback.)"""
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
