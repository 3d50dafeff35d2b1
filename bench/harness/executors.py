"""Where jobs run: serially through one isolated worker process (default), or
on a Dask cluster (``--workers N``: a LocalCluster of N single-threaded worker
processes; ``--scheduler tcp://HOST:PORT``: an existing cluster). On Dask each
worker thread keeps its own isolated solve process (a fresh one for every
run), so hard timeouts and crash isolation hold there too.

An executor maps ``(tag, job, timeout)`` items to ``(tag, result)`` in the
order they finish; ``result`` carries ``worker`` and ``wall_s``.

On Dask, a job that takes its worker process down (the Dask worker itself
killed, not the isolated solve process) costs its row only: a job whose worker
died runs once more at the end, with no other job of the run beside it, and
its row is ``crashed`` when the worker dies again (a job assigned to the same
worker, or one whose finished result was still on it and was computed again,
can die with it the first time). On the local cluster Dask does not retry a
job on another worker (``allowed-failures`` 0: the retry above is hikbench's),
queues the jobs of a large run rather than assigning two to a worker ahead
(``worker-saturation`` 1.0), and never drops a worker's nanny
(``lost-worker-timeout``); a future is released once its result is taken. A
cluster left without any worker for
:data:`NO_WORKER_GRACE` seconds while jobs wait ends the run with an error on
the local cluster (its nannies gave up) and prints a warning on an external one
(workers may come back).
"""

from __future__ import annotations

import contextlib
import os
import socket
import sys
import threading
import time
import uuid
from concurrent.futures import CancelledError

from hikbench.bench.harness.isolation import IsolatedWorker
from hikbench.problems.errors import HikbenchError
from hikbench.bench.harness.statuses import CRASHED

__all__ = ["NO_WORKER_GRACE", "DaskExecutor", "SerialExecutor", "dask_setup", "run_job"]

NO_WORKER_GRACE = 60.0  # seconds a Dask cluster may have no worker while jobs wait (see DaskExecutor)


#: seconds an isolated worker running an external program has past the program's timeout (to write the
#: problem's files, have the launcher end the program's tree, read and check its answer)
EXTERNAL_MARGIN_S = 15.0


def run_job(worker: IsolatedWorker, job: dict, timeout: float) -> dict:
    """Run ``job`` in ``worker``'s isolated process, a solve's under the job timeout
    (and its first-solve allowance); an external program's too (it starts it, reads
    and checks its answer there: an answer that breaks the parser costs its row, never
    this process), the program killed at ``timeout``."""
    t0 = time.perf_counter()
    if job["kind"] == "external":
        res = worker.run({**job, "program_timeout": timeout}, timeout + EXTERNAL_MARGIN_S)
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

    def renew(self) -> None:
        """The next job starts a fresh worker process (see
        :func:`hikbench.bench.harness.runner.run_suite`'s rounds)."""
        self.worker.close()

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

    dask_worker = get_worker()
    current = getattr(_DASK_LOCAL, "worker", None)
    if current is None or current[0] != session:
        if current is not None:
            current[1].close()
        # the isolated process's stderr, capped as OUT/worker.log is, in the Dask worker's own folder
        log = os.path.join(dask_worker.local_directory, "hikbench-worker.log")
        current = _DASK_LOCAL.worker = (session, IsolatedWorker(log=log))
    res = run_job(current[1], job, timeout)
    res["worker"] = dask_worker.address
    return res


def _died(err) -> dict:
    """The row of a job whose Dask worker died under it twice, the second time alone (KilledWorker)."""
    worker = getattr(err.last_worker, "address", None)
    return {"status": CRASHED, "x": None, "samples_ns": [], "worker": worker,
            "reason": f"the Dask worker process died while this job was running on it, also when it ran again "
                      f"alone on the cluster (KilledWorker; last on {worker}: see that worker's log)"}


_CONNECT_TIMEOUT = 10.0  # seconds to reach a --scheduler
# the local cluster, for the executor's life: Dask retries no job whose worker died (map does, alone);
# a large run's jobs wait in the scheduler, not two per worker; a nanny is never dropped (by default
# it is when its worker is still down 15 s after a death: under repeated deaths no worker was left)
# Ctrl-C reaches the worker processes too (the terminal's process group): dask_setup below, run in each
# at its start (a preload), has them ignore it, so that only hikbench stops and closes the cluster
_LOCAL_CLUSTER = {"distributed.scheduler.worker-saturation": 1.0, "distributed.scheduler.allowed-failures": 0,
                  "distributed.deploy.lost-worker-timeout": "1 day", "distributed.worker.preload": [__name__]}


def dask_setup(worker) -> None:
    """Dask's preload hook, run in every worker process of the local cluster
    as it starts (and restarts): SIGINT ignored. A Ctrl-C in the terminal
    reaches every process of its group; each worker printed a
    KeyboardInterrupt traceback (~70 lines for two) before hikbench's
    ``interrupted``, and died under its nanny. hikbench itself stops on it and
    closes the cluster, which ends the workers. (The isolated solve processes
    run in sessions of their own and never see it.)

    Closing a worker while a job runs on it cancels the job's coroutine, which
    Dask logs as a warning ("Async instruction for <Task ...> ended with
    CancelledError"; in Dask's words, this happens exclusively in
    ``Worker.close()``): that message is dropped. So are a worker's heartbeat
    racing the closing scheduler ("Failed to communicate with scheduler
    during heartbeat", an ERROR with a 30-line traceback, and "Scheduler was
    unaware of this worker"): the local cluster's scheduler runs in
    hikbench's own process, which is closing it (1 in ~10 runs stopped by
    SIGTERM under load printed the traceback after hikbench's one line). A
    job that such a worker loses is still reported (KilledWorker: a
    ``crashed`` row)."""
    import logging
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    logging.getLogger("distributed.worker.state_machine").addFilter(_drop_close_races)
    logging.getLogger("distributed.worker").addFilter(_drop_close_races)


_CLOSE_RACES = ("Failed to communicate with scheduler during heartbeat", "Scheduler was unaware of this worker")


def _drop_close_races(record) -> bool:
    """False for the log records of a closing local cluster (see :func:`dask_setup`)."""
    msg = record.getMessage()
    if msg.startswith("Async instruction for") and msg.endswith("ended with CancelledError"):
        return False
    return not msg.startswith(_CLOSE_RACES)


def _drop_unbound_cancel(record) -> bool:
    """False for the error that Dask's ``distributed.utils.sync`` logs (through
    tornado) when Ctrl-C lands before its call has started: its ``cancel``
    callback reads ``future`` before it is bound (a NameError; there is nothing
    to cancel). hikbench stops on the interrupt as on any other; the record
    only put a 10-line traceback before its one line ``interrupted``."""
    exc = record.exc_info[1] if record.exc_info else None
    if not isinstance(exc, NameError) or exc.__traceback__ is None:
        return True
    tb = exc.__traceback__
    while tb.tb_next is not None:
        tb = tb.tb_next
    code = tb.tb_frame.f_code
    return not (code.co_name == "cancel" and code.co_filename.replace("\\", "/").endswith("distributed/utils.py"))


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


def _probe_scheduler(address: str, host_port: tuple[str, int]) -> None:
    """Connect to a tcp:// --scheduler and read what it sends first.

    Fails at once on a refused connection (OSError; Client retries for 30 s).
    A Dask server writes its handshake as soon as it accepts (a message of a
    few dozen bytes, led by its length as a little-endian 64-bit integer);
    Client waits for it without a time limit, and reads any 8 bytes as that
    length. A port that sends nothing within ``_CONNECT_TIMEOUT`` (an HTTP
    server, such as the scheduler's dashboard) left the run hanging, and one
    that sent a banner made Client allocate exabytes: both are a
    HikbenchError naming the address."""
    with socket.create_connection(host_port, timeout=_CONNECT_TIMEOUT) as sock:
        try:
            first = sock.recv(8)
        except TimeoutError:
            first = None
    hint = "expected a Dask scheduler's address (not its dashboard's HTTP port, by default 8787)"
    if first is None:
        raise HikbenchError(f"--scheduler {address}: sent nothing within {_CONNECT_TIMEOUT:g} s; {hint}")
    if not first:
        raise HikbenchError(f"--scheduler {address}: closed the connection at once; {hint}")
    if len(first) == 8 and int.from_bytes(first, "little") > 2 ** 26:
        raise HikbenchError(f"--scheduler {address}: does not speak Dask's protocol (it sent {first!r}); {hint}")


class DaskExecutor:
    def __init__(self, workers: int | None = None, scheduler: str | None = None):
        import logging

        from distributed import Client, LocalCluster

        logging.getLogger("tornado.application").addFilter(_drop_unbound_cancel)  # (once: a set)
        self.cluster = None
        # what close undoes, last first: the client, the local cluster, its dask settings (each even
        # when one before it fails to close)
        self._closing = contextlib.ExitStack()
        self.session = uuid.uuid4().hex  # fresh isolated processes on the Dask workers (see _dask_task)
        if scheduler:
            host_port = _check_scheduler_address(scheduler)
            with contextlib.ExitStack() as starting:  # (the client closes at once if the scheduler is unusable)
                try:
                    if host_port is not None and scheduler.startswith("tcp://"):
                        _probe_scheduler(scheduler, host_port)
                    elif host_port is not None:  # fail at once on a refused connection (Client retries 30 s)
                        socket.create_connection(host_port, timeout=_CONNECT_TIMEOUT).close()
                    self.client = Client(scheduler, timeout=_CONNECT_TIMEOUT)
                except OSError as err:  # refused, unreachable, unknown host, timed out
                    raise HikbenchError(f"could not connect to scheduler {scheduler}: "
                                        f"{err.strerror or err or type(err).__name__}") from err
                starting.callback(self.client.close)
                try:  # a cluster without workers would queue the jobs forever, silently
                    self.client.wait_for_workers(1, timeout=_CONNECT_TIMEOUT)
                except TimeoutError as err:
                    raise HikbenchError(f"scheduler {scheduler} has no worker (waited {_CONNECT_TIMEOUT:g} s); "
                                        f"expected at least one, e.g. `dask worker {scheduler}`") from err
                self._closing = starting.pop_all()
            self.name = f"dask:{scheduler}"
        else:
            import dask

            with contextlib.ExitStack() as starting:  # (undone at once if the cluster does not start)
                starting.enter_context(dask.config.set(_LOCAL_CLUSTER))
                # no dashboard; the scheduler's HTTP server on a free local port, not on 8787 (taken by
                # any other cluster: a "Port 8787 is already in use" warning on every run)
                self.cluster = LocalCluster(n_workers=int(workers), threads_per_worker=1, processes=True,
                                            dashboard_address="127.0.0.1:0", scheduler_kwargs={"dashboard": False})
                starting.callback(self.cluster.close)
                self.client = Client(self.cluster)
                starting.callback(self.client.close)
                self._closing = starting.pop_all()
            self.name = f"dask-local:{workers}"

    def map(self, items):
        """Every job at once; a job whose worker process died (KilledWorker) runs once more at
        the end, with no other job of the run beside it (see the module docstring)."""
        jobs = {self._submit(job, timeout): (tag, job, timeout) for tag, job, timeout in items}
        again = []
        for (tag, job, timeout), res in self._collect(jobs):
            if isinstance(res, dict):
                yield tag, res
            else:
                again.append((tag, job, timeout))
        for tag, job, timeout in again:
            for _, res in self._collect({self._submit(job, timeout): tag}):
                yield tag, res if isinstance(res, dict) else _died(res)

    def renew(self) -> None:
        """Each Dask worker's next job starts a fresh isolated process (a new session)."""
        self.session = uuid.uuid4().hex

    def _submit(self, job: dict, timeout: float):
        return self.client.submit(_dask_task, job, timeout, self.session, pure=False)

    def _collect(self, futures: dict):
        """``(futures[fut], result)`` in the order the jobs finish; the result is the
        KilledWorker exception for a job whose worker process died."""
        from distributed import KilledWorker, as_completed

        lost = []  # the watchdog's reason when it cancelled the jobs (a local cluster left without workers)
        stop = threading.Event()
        threading.Thread(target=self._watch_workers, args=(futures, lost, stop), daemon=True).start()
        try:
            for fut in as_completed(futures):
                try:
                    res = fut.result()
                except KilledWorker as err:
                    res = err
                except CancelledError as err:  # hikbench cancels only through the watchdog
                    why = lost[0] if lost else f"a job was cancelled ({err}: the Dask scheduler went away)"
                    raise HikbenchError(f"{self.name}: {why}; expected the cluster to stay up for the whole run. "
                                        f"The rows written so far are kept: run the same command again to "
                                        f"resume") from err
                fut.release()  # (a worker that dies later holds nothing Dask would compute again)
                yield futures.pop(fut), res
        finally:
            stop.set()

    def _watch_workers(self, futures: dict, lost: list, stop: threading.Event) -> None:
        """While jobs wait, look every second whether the cluster has a worker. After
        NO_WORKER_GRACE seconds without one: cancel the jobs of a local cluster (``_collect``
        raises with the reason put in ``lost``), or warn once on an external cluster."""
        since = None
        warned = False
        while not stop.wait(1.0):
            asked = ""
            try:
                n = len(self.client.nthreads())
            except Exception as err:  # noqa: BLE001 - the watchdog never dies silently: see below
                if stop.is_set() or self.client.status != "running":
                    return  # the client closed or the scheduler went away: the run is over (_collect raises)
                if not isinstance(err, OSError):
                    # any other failure leaves the run unguarded (a silent hang if the workers go): end it
                    self._abort(futures, lost, f"the watchdog could not ask the cluster for its workers "
                                               f"({type(err).__name__}: {err})")
                    return
                # a connection error while the client runs counts as no worker: a passing one ends
                # within the grace, a lasting one is met as a cluster without workers
                n = 0
                asked = f" (it could not be asked: {type(err).__name__}: {err})"
            if n:
                since = None
                continue
            since = since or time.monotonic()
            if time.monotonic() - since < NO_WORKER_GRACE:
                continue
            if self.cluster is not None:
                self._abort(futures, lost, f"the local Dask cluster has had no worker for {NO_WORKER_GRACE:g} s"
                                           + (asked or " (its worker processes died and were not restarted)"))
                return
            if not warned:
                print(f"hikbench: {self.name} has had no worker for {NO_WORKER_GRACE:g} s{asked}; {len(futures)} "
                      f"jobs wait for one (Ctrl-C stops the run; the rows written so far are kept)",
                      file=sys.stderr, flush=True)
                warned = True

    def _abort(self, futures: dict, lost: list, why: str) -> None:
        """The watchdog ends the run: the reason for ``_collect``, then every job cancelled."""
        lost.append(why)
        self.client.cancel(list(futures.copy()))  # (a copy: _collect pops from it meanwhile)

    def close(self) -> None:
        self._closing.close()
