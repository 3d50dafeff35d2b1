"""A persistent worker process with a hard timeout per job.

:class:`IsolatedWorker` starts ``python -m hikbench.bench.harness.isolation`` and talks to it
over its stdin / stdout with length-prefixed pickles. The child moves the
channel off fd 1 (fd 1 then goes to stderr, the worker log) before any solver
code runs; every frame starts with a random token of the worker, given to the
child on its stdin, and carries a CRC32 of its pickle, so that bytes a solver
writes into the channel anyway are skipped (the row is still the solver's
answer); a result that cannot be pickled is status ``error`` with the cause. A job
that does not answer within its timeout gets the process killed (status
``timeout``); a process that dies (segfault, abort, ``os._exit``) gives status
``crashed`` with the signal or exit code. Either way the next job starts a
fresh process, so one bad backend costs one row, not the run.

The first solve of a solver in a worker process may compile (numba) or fill
caches; until the worker reports that first untimed solve done, a job of a
solver that this process has not run yet is allowed ``first_timeout``
seconds (if larger than the job timeout); after it, and for every later job
of that solver, the job timeout applies. The allowance is given in full once
per solver and :class:`IsolatedWorker` (not per process: a solver that hangs
on every problem would cost ``first_timeout`` per row, each timeout
restarting the process). After a restart, a solver whose first solve
completed before gets the job timeout plus twice the longest first solve it
took (its caches are on disk now), capped by ``first_timeout``; a solver
whose first solve ran past the allowance gets the job timeout only. The
``timeout`` row's reason says which limit applied.

A ``scenario`` job (a suite's ``[[scenarios]]``: hikbench.bench.scenarios.job) runs in
the same process, under the same timeouts, through the same channel.

Plain subprocesses (not ``multiprocessing``) so that this also works inside
daemonic Dask worker processes.
"""

from __future__ import annotations

import os
import pickle
import select
import signal
import socket
import struct
import subprocess
import sys
import threading
import time
import zlib

from hikbench.bench.harness.streams import HeadTail, become_subreaper, kill_descendants, kill_session, reap_children
from hikbench.problems.errors import HikbenchError
from hikbench.bench.harness.statuses import CRASHED, TIMEOUT
from hikbench.solvers.base import ERROR

__all__ = ["CappedLog", "HeadTail", "IsolatedWorker", "kill_session"]

_HEADER = struct.Struct("<QI")  # pickle size, its CRC32; after the channel's token
_TOKEN_BYTES = 16
_CHANNEL_FD_MIN = 100  # the child's channel descriptors: away from the low numbers a solver may use
_READ_CHUNK = 1 << 20
_THREAD_ENV = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS",
               "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS", "NUMBA_NUM_THREADS")


_FIRST_SOLVE_DONE = "first-solve-done"  # frame sent by the child after a job's first untimed solve


class _Timeout(Exception):
    pass


class _Closed(Exception):
    pass


class _Corrupt(Exception):
    """A frame whose pickle does not match its CRC32 (bytes written into it meanwhile)."""


def _write_frame(f, obj, token: bytes) -> None:
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    f.write(token + _HEADER.pack(len(data), zlib.crc32(data)) + data)
    f.flush()


class _Reader:
    """The frames read from the pipe ``fd``: each one starts with ``token``; the bytes
    before it (a solver that wrote into the channel) are skipped, in bounded memory,
    and counted in :attr:`skipped`."""

    def __init__(self, fd: int, token: bytes):
        self.fd, self.token = fd, token
        self.buf = bytearray()
        self.skipped = 0

    def _fill(self, deadline: float | None) -> None:
        if deadline is not None:
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([self.fd], [], [], left)[0]:
                raise _Timeout
        chunk = os.read(self.fd, _READ_CHUNK)
        if not chunk:
            raise _Closed
        self.buf += chunk

    def _exact(self, n: int, deadline: float | None) -> bytes:
        while len(self.buf) < n:
            self._fill(deadline)
        out = bytes(self.buf[:n])
        del self.buf[:n]
        return out

    def _sync(self, deadline: float | None) -> None:
        """Drop every byte up to and including the next token."""
        while (i := self.buf.find(self.token)) < 0:
            drop = max(len(self.buf) - len(self.token) + 1, 0)
            self.skipped += drop
            del self.buf[:drop]
            self._fill(deadline)
        self.skipped += i
        del self.buf[: i + len(self.token)]

    def frame(self, deadline: float | None):
        self._sync(deadline)
        size, crc = _HEADER.unpack(self._exact(_HEADER.size, deadline))
        data = self._exact(size, deadline)
        if zlib.crc32(data) != crc:
            raise _Corrupt(f"a frame of {size} bytes failed its CRC32 check")
        return pickle.loads(data)


def describe_exit(code: int | None, who: str = "worker process") -> str:
    """How a process ended, from its Popen returncode (negative: the signal)."""
    if code is None:
        return f"{who} died"
    if code < 0:
        try:
            return f"{who} killed by signal {signal.Signals(-code).name}"
        except ValueError:
            return f"{who} killed by signal {-code}"
    return f"{who} exited with code {code}"


LOG_KEEP_BYTES = 1 << 20  # of the head and of the tail of a worker process's stderr, in its log


class CappedLog:
    """Copies what a process writes into a pipe to the file ``path`` (appended),
    from a thread: the first ``keep`` bytes as they come, then, when the pipe
    closes, a line saying how many bytes were left out and the last ``keep``
    bytes. A solver printing without end cannot fill the disk."""

    def __init__(self, path, fd: int, keep: int = LOG_KEEP_BYTES):
        self.path = path
        self._buf = HeadTail(keep, keep)
        self._thread = threading.Thread(target=self._pump, args=(fd,), name="worker-log", daemon=True)
        self._thread.start()

    def _pump(self, fd: int) -> None:
        with open(self.path, "ab") as f, os.fdopen(fd, "rb", buffering=0) as pipe:
            while chunk := pipe.read(1 << 16):
                head = self._buf.add(chunk)
                if head:
                    f.write(head)
                    f.flush()
            f.write(self._buf.marker() + self._buf.tail)

    def close(self, timeout: float = 2.0) -> None:
        """Wait (at most ``timeout`` s: a process the solver left may hold the pipe)
        for the pipe to close and the tail to be written."""
        self._thread.join(timeout)


class IsolatedWorker:
    """One worker process, restarted after a timeout or a crash.

    Parameters
    ----------
    log : path or None
        File that receives the worker's stderr (appended; per process, its first
        and last ``LOG_KEEP_BYTES`` only: :class:`CappedLog`); None inherits it.
    startup_timeout : float
        Seconds allowed for the process to start and calibrate.
    path_first : sequence of str
        Folders put first on the child's ``PYTHONPATH`` (another install of hikbench:
        ``hikbench regress``'s base revision), with ``cwd`` its working directory.
    """

    def __init__(self, log=None, startup_timeout: float = 120.0, path_first=(), cwd=None):
        self.log = log
        self.startup_timeout = startup_timeout
        self.path_first, self.cwd = tuple(map(str, path_first)), cwd
        self.proc: subprocess.Popen | None = None
        self._log_pump: CappedLog | None = None
        self.info: dict = {}
        self.restarts = 0
        self._warmed: set = set()  # solver specs whose first solve this process has done
        # across restarts: the longest completed first solve (s) of each spec, and the specs whose
        # first solve ran past the full allowance (see the module docstring)
        self._first_s: dict = {}
        self._first_hung: set = set()

    def _env(self) -> dict:
        env = dict(os.environ)
        paths = [p for p in sys.path if p and os.path.isdir(p)]
        env["PYTHONPATH"] = os.pathsep.join(dict.fromkeys([*self.path_first, os.getcwd(), *paths]))
        for var in _THREAD_ENV:
            env[var] = "1"
        return env

    def start(self) -> None:
        self.close()
        self._warmed = set()
        # the log gets what the child writes to its stderr through a pipe, capped (CappedLog)
        err = os.pipe() if self.log else None
        try:
            # own session: a Ctrl-C in the terminal interrupts the run, not the solve (no bogus
            # `crashed` row); the child dies with its parent through PR_SET_PDEATHSIG (Linux)
            self.proc = subprocess.Popen([sys.executable, "-m", "hikbench.bench.harness.isolation"], stdin=subprocess.PIPE,
                                         stdout=subprocess.PIPE, stderr=err[1] if err else None, env=self._env(),
                                         start_new_session=True, cwd=self.cwd)
        except BaseException:
            if err:
                os.close(err[0])
            raise
        finally:
            if err:
                os.close(err[1])  # the child has its own copy
        self._log_pump = CappedLog(self.log, err[0]) if err else None
        self._token = os.urandom(_TOKEN_BYTES)
        self._reader = _Reader(self.proc.stdout.fileno(), self._token)
        try:
            self.proc.stdin.write(self._token)  # (raw, first: the child reads it before any frame)
            self.proc.stdin.flush()
            self.info = self._reader.frame(time.monotonic() + self.startup_timeout)
        except (_Timeout, _Closed, _Corrupt, BrokenPipeError) as exc:
            code = self.proc.poll()
            self.close()
            raise HikbenchError(f"the isolated worker did not start ({describe_exit(code)}); "
                                f"see {self.log or 'stderr'}") from exc

    @property
    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def run(self, job: dict, timeout: float, first_timeout: float | None = None, on_first_solve=None) -> dict:
        """Run ``job`` (see hikbench.bench.harness.worker); returns its result dict, or a
        ``timeout`` / ``crashed`` result. Adds ``calib_ns``, ``host``, ``pid``.
        ``first_timeout``: allowance for the first solve of a solver new to
        this process (see the module docstring); ``on_first_solve()``, if given, is
        called when the job's untimed first solve is done."""
        if not self.alive:
            if self.proc is not None:
                self.restarts += 1
            self.start()
        proc = self.proc
        meta = {"host": self.info.get("host", socket.gethostname()), "pid": proc.pid,
                "calib_ns": self.info.get("calib_ns")}
        spec = job.get("solver")
        allowance, why = self._allowance(spec, timeout, first_timeout)
        first = allowance > timeout
        try:
            t0 = time.monotonic()
            _write_frame(proc.stdin, job, self._token)
            deadline = t0 + allowance  # (= timeout when this is not a first solve)
            while True:
                out = self._reader.frame(deadline)
                if not (isinstance(out, str) and out == _FIRST_SOLVE_DONE):
                    break
                if on_first_solve is not None:
                    on_first_solve()
                if spec not in self._warmed:
                    self._warmed.add(spec)
                    self._first_s[spec] = max(self._first_s.get(spec, 0.0), time.monotonic() - t0)
                if first:  # the allowance covered the first solve; the job timeout applies after it
                    first = False
                    deadline = time.monotonic() + timeout
        except _Timeout:
            self.kill()
            if first:
                limit = f"{allowance:g} s allowed for the first solve{why}"
                if spec not in self._first_s:
                    self._first_hung.add(spec)
            else:
                limit = f"{timeout:g} s timeout{why}"
            return {**meta, "status": TIMEOUT, "x": None, "samples_ns": [],
                    "reason": f"no answer within the {limit}; worker killed"}
        except _Corrupt as err:  # a solver writing into the channel while its frame was written
            self.kill()
            return {**meta, "status": CRASHED, "x": None, "samples_ns": [],
                    "reason": f"the job channel was corrupted ({err}); worker killed"}
        except (_Closed, BrokenPipeError, OSError):
            try:
                code = proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                code = None
            self.kill()  # (closes its pipes, and ends it if it still runs)
            return {**meta, "status": CRASHED, "x": None, "samples_ns": [], "reason": describe_exit(code)}
        out.setdefault("calib_ns", meta["calib_ns"])
        return out

    def _allowance(self, spec, timeout: float, first_timeout: float | None) -> tuple[float, str]:
        """Seconds allowed for the first solve of ``spec`` in the current process, and
        the words a timeout reason adds when that is not the full ``first_timeout``
        (see the module docstring)."""
        if not first_timeout or first_timeout <= timeout or spec in self._warmed:
            return timeout, ""
        if spec in self._first_hung:
            return timeout, (f" (no first-solve allowance: this solver's first solve ran past the "
                             f"{first_timeout:g} s allowance earlier in this worker)")
        done = self._first_s.get(spec)
        if done is None:
            return first_timeout, ""
        allowance = min(first_timeout, timeout + 2.0 * done)
        return allowance, (f" (after a restart: the job timeout plus twice this solver's first solve "
                           f"before, {done:.3g} s)")

    def kill(self) -> None:
        """End the worker and every process a solver started in its session (a helper
        left running would burn CPU through the timings of every later job)."""
        if self.proc is not None:
            kill_descendants(self.proc.pid)  # (those that left its session too: the worker is their subreaper)
            kill_session(self.proc.pid)
            self.proc.wait()
            if self._log_pump is not None:
                self._log_pump.close()
                self._log_pump = None
            for f in (self.proc.stdin, self.proc.stdout):
                try:
                    f.close()
                except OSError:
                    pass  # the pipe is already broken; the process is gone either way
            self.proc = None

    def close(self) -> None:
        """Ask the worker to exit; kill it if it does not."""
        if self.proc is None:
            return
        if self.proc.poll() is None:
            try:
                _write_frame(self.proc.stdin, None, self._token)
                self.proc.wait(timeout=5)
            except (OSError, subprocess.TimeoutExpired):
                pass  # kill() below ends it
        self.kill()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def die_with_parent() -> None:
    """Linux: SIGKILL this process when its parent dies (a killed run must not
    leave a hanging solve behind). Elsewhere the closed stdin ends an idle worker."""
    if sys.platform.startswith("linux"):
        import ctypes

        try:
            rc = ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
            why = f"prctl failed, errno {ctypes.get_errno()}" if rc != 0 else ""
        except (OSError, AttributeError) as err:  # no glibc
            why = f"{type(err).__name__}: {err}"
        if why:  # (stderr: OUT/worker.log under `hikbench run`)
            print(f"hikbench worker: not killed with its parent ({why}); an orphaned worker ends when "
                  "it next reads its closed stdin, one in a hanging solve does not", file=sys.stderr)


def _high_fd(fd: int) -> int:
    """A close-on-exec copy of ``fd`` numbered at least _CHANNEL_FD_MIN; ``fd`` is left open."""
    import fcntl

    return fcntl.fcntl(fd, fcntl.F_DUPFD_CLOEXEC, _CHANNEL_FD_MIN)


def _read_token(fd: int) -> bytes:
    token = b""
    while len(token) < _TOKEN_BYTES:
        chunk = os.read(fd, _TOKEN_BYTES - len(token))
        if not chunk:
            raise _Closed
        token += chunk
    return token


def _send(channel, result: dict, token: bytes) -> None:
    """Write ``result``; one that pickle cannot send (a solver's object in its fields)
    is sent as status ``error`` with the cause instead."""
    try:
        _write_frame(channel, result, token)
    except Exception as err:  # noqa: BLE001 - pickle raises what the unpicklable object's type decides
        _write_frame(channel, {"host": result.get("host"), "pid": result.get("pid"), "status": ERROR, "x": None,
                               "samples_ns": [], "reason": f"the solver's result cannot be sent back to the "
                                                           f"harness: {type(err).__name__}: {err}"}, token)


def _child_main() -> None:
    die_with_parent()
    why = become_subreaper()  # (a solver's grandchild that called setsid comes back here: ended after its job)
    if why:
        print(f"hikbench worker: a process a solver started outside its session may outlive its job ({why})",
              file=sys.stderr)
    # the channel and the jobs on close-on-exec descriptors >= _CHANNEL_FD_MIN; fd 1 goes to stderr (what a
    # solver prints), fd 0 to /dev/null (a solver reading stdin reads nothing: not the job channel)
    channel = os.fdopen(_high_fd(1), "wb")
    os.dup2(2, 1)
    fd = _high_fd(0)
    null = os.open(os.devnull, os.O_RDONLY)
    os.dup2(null, 0)
    os.close(null)
    try:
        token = _read_token(fd)
    except _Closed:
        return
    jobs = _Reader(fd, token)
    from hikbench.bench.harness.calibration import calibrate
    from hikbench.bench.harness.worker import execute

    calib = calibrate()
    _write_frame(channel, {"host": socket.gethostname(), "pid": os.getpid(), "calib_ns": calib}, token)
    while True:
        try:
            job = jobs.frame(None)
        except _Closed:
            return
        if job is None:
            return
        run = execute
        if job.get("kind") == "scenario":  # (a suite's [[scenarios]]: pinocchio and the robots, loaded here only)
            from hikbench.bench.scenarios.job import execute_scenario as run
        _send(channel, run(job, notify=lambda: _write_frame(channel, _FIRST_SOLVE_DONE, token)), token)
        kill_descendants(os.getpid())  # every process the job left (a solver's helper would burn CPU through
        reap_children()  # the timings of every later job), then their exit statuses


if __name__ == "__main__":
    _child_main()
