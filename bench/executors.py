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


class DaskExecutor:
    def __init__(self, workers: int | None = None, scheduler: str | None = None):
        from distributed import Client, LocalCluster

        self.cluster = None
        if scheduler:
            self.client = Client(scheduler)
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
