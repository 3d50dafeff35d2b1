"""Where jobs run: serially through one isolated worker process (default), or
on a Dask cluster (``--workers N``: a LocalCluster of N single-threaded worker
processes; ``--scheduler tcp://HOST:PORT``: an existing cluster). On Dask each
worker process keeps its own isolated solve process, so hard timeouts and
crash isolation hold there too.

An executor maps ``(tag, job, timeout)`` items to ``(tag, result)`` in the
order they finish; ``result`` carries ``worker`` and ``wall_s``.
"""

from __future__ import annotations

import os
import socket
import time

from bench.isolation import IsolatedWorker
from problems.errors import HikbenchError

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


_DASK_WORKER: IsolatedWorker | None = None


def _dask_task(job: dict, timeout: float) -> dict:
    global _DASK_WORKER
    from distributed import get_worker

    if _DASK_WORKER is None:
        _DASK_WORKER = IsolatedWorker()
    res = run_job(_DASK_WORKER, job, timeout)
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
        if scheduler:
            host_port = _check_scheduler_address(scheduler)
            try:
                if host_port is not None:  # fail at once on a refused connection (Client retries for 30 s)
                    socket.create_connection(host_port, timeout=_CONNECT_TIMEOUT).close()
                self.client = Client(scheduler, timeout=_CONNECT_TIMEOUT)
            except OSError as err:  # refused, unreachable, unknown host, timed out
                raise HikbenchError(f"could not connect to scheduler {scheduler}: "
                                    f"{err.strerror or err or type(err).__name__}") from err
            self.name = f"dask:{scheduler}"
        else:
            self.cluster = LocalCluster(n_workers=int(workers), threads_per_worker=1, processes=True,
                                        dashboard_address=None)
            self.client = Client(self.cluster)
            self.name = f"dask-local:{workers}"

    def map(self, items):
        from distributed import as_completed

        futures = {}
        for tag, job, timeout in items:
            futures[self.client.submit(_dask_task, job, timeout, pure=False)] = tag
        for fut in as_completed(futures):
            yield futures[fut], fut.result()

    def close(self) -> None:
        self.client.close()
        if self.cluster is not None:
            self.cluster.close()
