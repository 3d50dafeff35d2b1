"""Where jobs run: serially through one isolated worker process (default), or
on a Dask cluster (``--workers N``: a LocalCluster of N single-threaded worker
processes; ``--scheduler tcp://HOST:PORT``: an existing cluster). On Dask each
worker thread keeps its own isolated solve process (a fresh one for every
run), so hard timeouts and crash isolation hold there too.

An executor maps ``(tag, job, timeout)`` items to ``(tag, result)`` in the
order they finish; ``result`` carries ``worker`` and ``wall_s``.
"""

from __future__ import annotations

import os
import socket
import threading
import time
import uuid
from concurrent.futures import CancelledError

from bench.isolation import IsolatedWorker
from problems.errors import HikbenchError
from solvers.base import CRASHED

__all__ = ["SerialExecutor", "DaskExecutor", "run_job"]


def run_job(worker: IsolatedWorker, job: dict, timeout: float) -> dict:
    t0 = time.perf_counter()
    if job["kind"] == "external":
        from bench.external import run_external
        res = run_external(job, timeout)
    else:
        res = worker.run(job, timeout, job.get("first_timeout"))
    res["wall_s"] = time.perf_counter() - t0
    res.setdefault("worker", f"{res.get('pid', os.getpid())}@{res.get('host', socket.gethostname())}")
    return res


class SerialExecutor:
    name = "serial"

    def __init__(self, log=None):
        self.worker = IsolatedWorker(log=log)

    def map(self, items):
        for tag, job, timeout in items:
            yield tag, run_job(self.worker, job, timeout)

    def close(self) -> None:
        self.worker.close()


_DASK_LOCAL = threading.local()  # .worker: (session, isolated worker) of this Dask worker thread


def _dask_task(job: dict, timeout: float, session: str) -> dict:
    """Run one job in an isolated process of this Dask worker thread (a worker with several
    threads runs several jobs at once: one process each, never a shared channel). A new
    ``session`` (one per DaskExecutor, i.e. per run) starts a fresh process: a long-lived
    cluster must not solve with the modules (a user's ``file.py:Class``, an edited solver)
    imported for an earlier run."""
    from distributed import get_worker

    current = getattr(_DASK_LOCAL, "worker", None)
    if current is None or current[0] != session:
        if current is not None:
            current[1].close()
        current = _DASK_LOCAL.worker = (session, IsolatedWorker())
    res = run_job(current[1], job, timeout)
    res["worker"] = get_worker().address
    return res


_CONNECT_TIMEOUT = 10.0  # seconds to reach a --scheduler


def _check_scheduler_address(address: str) -> tuple[str, int] | None:
    """Reject a malformed --scheduler address (HikbenchError naming the
    option); returns (host, port) for a tcp/tls address, else None."""
    from distributed.comm import parse_address
    from distributed.comm.addressing import parse_host_port
    from distributed.comm.registry import get_backend

    try:
        scheme, loc = parse_address(address)
        get_backend(scheme)
        if scheme not in ("tcp", "tls"):
            return None
        host, port = parse_host_port(loc)
    except ValueError as err:
        raise HikbenchError(f"--scheduler {address!r}: expected a Dask scheduler address like "
                            f"tcp://HOST:PORT ({err})") from err
    if not host or not 0 < int(port) < 65536:
        raise HikbenchError(f"--scheduler {address!r}: expected a Dask scheduler address like tcp://HOST:PORT "
                            f"with a host and a port in 1..65535")
    return host, int(port)


class DaskExecutor:
    def __init__(self, workers: int | None = None, scheduler: str | None = None):
        from distributed import Client, LocalCluster

        self.cluster = None
        self.session = uuid.uuid4().hex  # fresh isolated processes on the Dask workers (see _dask_task)
        if scheduler:
            host_port = _check_scheduler_address(scheduler)
            try:
                if host_port is not None:  # fail at once on a refused connection (Client retries for 30 s)
                    socket.create_connection(host_port, timeout=_CONNECT_TIMEOUT).close()
                self.client = Client(scheduler, timeout=_CONNECT_TIMEOUT)
            except OSError as err:  # refused, unreachable, unknown host, timed out
                raise HikbenchError(f"could not connect to scheduler {scheduler}: "
                                    f"{err.strerror or err or type(err).__name__}") from err
            try:  # a cluster without workers would queue the jobs forever, silently
                self.client.wait_for_workers(1, timeout=_CONNECT_TIMEOUT)
            except TimeoutError as err:
                self.client.close()
                raise HikbenchError(f"scheduler {scheduler} has no worker (waited {_CONNECT_TIMEOUT:g} s); "
                                    f"expected at least one, e.g. `dask worker {scheduler}`") from err
            self.name = f"dask:{scheduler}"
        else:
            # no dashboard; the scheduler's HTTP server on a free local port, not on 8787 (taken by
            # any other cluster: a "Port 8787 is already in use" warning on every run)
            self.cluster = LocalCluster(n_workers=int(workers), threads_per_worker=1, processes=True,
                                        dashboard_address="127.0.0.1:0", scheduler_kwargs={"dashboard": False})
            self.client = Client(self.cluster)
            self.name = f"dask-local:{workers}"

    def map(self, items):
        from distributed import KilledWorker, as_completed

        futures = {}
        for tag, job, timeout in items:
            futures[self.client.submit(_dask_task, job, timeout, self.session, pure=False)] = tag
        for fut in as_completed(futures):
            try:
                res = fut.result()
            except KilledWorker as err:  # every Dask worker holding the job died: its row only, the run goes on
                worker = getattr(err.last_worker, "address", None)
                res = {"status": CRASHED, "x": None, "samples_ns": [], "worker": worker,
                       "reason": f"the Dask worker process died while this job was running or queued on it, "
                                 f"on each of its {err.allowed_failures + 1} attempts (KilledWorker; last on "
                                 f"{worker}: see that worker's log)"}
            except CancelledError as err:  # hikbench cancels nothing: the scheduler went away
                raise HikbenchError(f"{self.name}: a job was cancelled ({err}); expected the Dask scheduler "
                                    f"to stay up for the whole run. The rows written so far are kept: run "
                                    f"the same command again to resume") from err
            yield futures.pop(fut), res

    def close(self) -> None:
        self.client.close()
        if self.cluster is not None:
            self.cluster.close()
