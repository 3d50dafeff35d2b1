"""External solvers: ``--solvers external:NAME=CMD`` (strict) or
``external:NAME[strict=false]=CMD``.

The declaration in brackets is the program's claim (parsed with the spelling by
:func:`hikbench.bench.specs.parse_spec`):
``strict=true`` (the default) says it returns the lexicographic optimum (its
rows are judged by ``verified``); ``strict=false`` says it solves another
problem (weighted, damped): it is reported like ``weighted``, with its real
times and its per-level gap to the yardstick, not as failing it.

Protocol (docs/adding-a-solver.md, "An external program"): for every solve, the harness writes the
problem to a temporary directory and runs CMD (split like a shell command line,
no shell) after replacing the placeholders (checked before the first job, with
the program's existence: an unbalanced quote, a word in braces that is none of
them, such as ``{problm}``, or a program that is neither a path nor found on
PATH is one error at start-up)

* ``{problem}``       path of the problem as ``.npz`` (problems/files.py layout),
* ``{problem_soth}``  path of the problem in SOTH text format (needs hikbench.problems.soth),
* ``{out}``           path where the program must write its answer,

and reads ``{out}``: a JSON object ``{"x": [...], "solve_time_s": t,
"status": "optimal", "iterations": k}`` where only ``x`` is required (it may
be ``null`` with a status other than ``optimal``). The row's
time samples are the ``solve_time_s`` the program reports when every
repetition reports one (its own timer, without process start-up), else the wall
time of the program's process (bench/harness/launcher.py measures it). The
program runs in a session of its own under a small launcher that kills every
process it leaves behind when it exits, and the whole tree at the job
timeout (on Linux as a subreaper: a grandchild that called ``setsid`` too);
the timeout is wall time, whatever holds the program's output open. Its
stdout and stderr are read as they come, keeping only their first and last
4 KiB. A non-zero exit code gives status ``error`` with the head and tail of
stderr; exceeding the job timeout gives ``timeout``; an answer file larger
than an answer can be (64 bytes a number, plus 1 MiB), or that is no regular file
(a FIFO, a link to /dev/zero, a directory), is refused unread, and one nested
deeper than 8 or holding an integer of more than 20 digits unparsed; all of it
runs in the isolated worker (bench/harness/worker.py), so that whatever the
answer holds costs its row at most. An output that
breaks the protocol (no ``x`` or a wrong shape, ``solve_time_s`` not a finite
number >= 0, ``iterations`` not an integer >= 0, an unknown ``status``) gives
``error`` with a reason naming the field; an ``x`` holding NaN or inf that
the program calls optimal gives ``numerical_failure``. Each repetition is a fresh process,
so external solvers run in ``cold`` mode only.
"""

from __future__ import annotations

import difflib
import json
import math
import os
import re
import select
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass

import numpy as np

from hikbench.bench.harness.regular import NotRegular, TooLarge, bounded_bytes
from hikbench.bench.harness.streams import HeadTail, kill_session
from hikbench.bench.harness.statuses import TIMEOUT
from hikbench.bench.specs import SPEC_KEYS, ExternalSpec, command_argv, external_command, parse_spec
from hikbench.solvers.base import ERROR, OPTIMAL, STATUSES, SolveResult

__all__ = ["SPEC_KEYS", "ExternalSpec", "parse_spec", "run_external"]  # (the spelling: hikbench.bench.specs)


_LAUNCHER = os.path.join(os.path.dirname(os.path.abspath(__file__)), "launcher.py")
KEEP_BYTES = 4096  # of the head and of the tail of the program's stdout and of its stderr
_GRACE_S = 1.0  # past the timeout, for the launcher to kill the tree and report
_DRAIN_BYTES = 1 << 20  # read from a pipe after the launcher exited (its writers are dead)


@dataclass
class Ran:
    """One run of the program: ``returncode`` (negative: the signal), its wall
    time, whether it timed out, ``error`` (it could not be started) and the
    head and tail of its stdout and stderr (:class:`HeadTail`)."""

    returncode: int | None
    elapsed_ns: int
    timed_out: bool
    error: str
    stdout: HeadTail
    stderr: HeadTail

    def output(self) -> str:
        """The head and tail of stderr (of stdout when stderr is empty), stripped."""
        text = self.stderr.text().strip()
        return text or self.stdout.text().strip()


def _run(argv: list[str], timeout: float, tmp: str) -> Ran:
    """Run ``argv`` through the launcher (bench/harness/launcher.py: its own session,
    every process it leaves killed when it ends or at ``timeout``), reading its
    stdout and stderr as they come into bounded :class:`HeadTail` buffers; the
    launcher itself is killed ``_GRACE_S`` past the timeout if it has not exited."""
    status = os.path.join(tmp, "launch.json")
    if os.path.exists(status):
        os.remove(status)
    cmd = [sys.executable, "-I", "-S", _LAUNCHER, status, repr(float(timeout)), str(os.getpid()), *argv]
    out, err = HeadTail(KEEP_BYTES, KEEP_BYTES), HeadTail(KEEP_BYTES, KEEP_BYTES)
    with subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                          start_new_session=True) as proc:
        streams = {proc.stdout.fileno(): out, proc.stderr.fileno(): err}
        try:
            exited = _pump(proc, streams, time.monotonic() + timeout + _GRACE_S)
        finally:
            _stop_launcher(proc)
        _drain(streams)
    return _ran(status, exited, out, err)


def _pump(proc: subprocess.Popen, streams: dict, deadline: float) -> bool:
    """Read the launcher's pipes into their buffers until it exits (True) or
    ``deadline`` passes (False). Never waits on a pipe: a process holding it
    open does not hold this up."""
    pidfd = os.pidfd_open(proc.pid) if hasattr(os, "pidfd_open") else None
    try:
        open_fds = list(streams)
        while proc.poll() is None:
            left = deadline - time.monotonic()
            if left <= 0:
                return False
            waits = open_fds + ([pidfd] if pidfd is not None else [])
            ready = select.select(waits, [], [], left if pidfd is not None else min(left, 0.02))[0]
            for fd in ready:
                if fd == pidfd:
                    continue
                chunk = os.read(fd, 1 << 16)
                if chunk:
                    streams[fd].add(chunk)
                else:
                    open_fds.remove(fd)
        return True
    finally:
        if pidfd is not None:
            os.close(pidfd)


def _drain(streams: dict) -> None:
    """What is left in the pipes once the launcher has exited, without blocking
    (at most ``_DRAIN_BYTES`` each)."""
    for fd, buf in streams.items():
        os.set_blocking(fd, False)
        for _ in range(_DRAIN_BYTES >> 16):
            try:
                chunk = os.read(fd, 1 << 16)
            except BlockingIOError:  # nothing more now; whoever holds the pipe is not waited for
                break
            if not chunk:
                break
            buf.add(chunk)


def _stop_launcher(proc: subprocess.Popen) -> None:
    """End a launcher still running past its deadline: SIGTERM (it kills its tree), then
    SIGKILL of its group if it has not exited within ``_GRACE_S``."""
    if proc.poll() is not None:
        return
    proc.terminate()
    try:
        proc.wait(_GRACE_S)
    except subprocess.TimeoutExpired:
        kill_session(proc.pid)
        proc.wait()


def _ran(status: str, exited: bool, out: HeadTail, err: HeadTail) -> Ran:
    """The :class:`Ran` of the launcher's STATUS file (a launcher that wrote none
    failed: its error is on its stderr)."""
    try:
        with open(status) as f:
            st = json.load(f)
    except (OSError, ValueError) as exc:
        if not exited:
            return Ran(None, 0, True, "", out, err)
        return Ran(None, 0, False, f"the launcher wrote no status ({exc}): {err.text().strip()[-300:]}", out, err)
    if "error" in st:
        return Ran(None, 0, False, st["error"], out, err)
    return Ran(int(st["returncode"]), int(st["elapsed_ns"]), bool(st["timed_out"]) or not exited, "", out, err)


def _describe_code(code: int) -> str:
    """``exit code 3`` or ``killed by signal SIGSEGV``."""
    if code >= 0:
        return f"exit code {code}"
    try:
        return f"killed by signal {signal.Signals(-code).name}"
    except ValueError:
        return f"killed by signal {-code}"


def _read_answer(path: str, n: int):
    """The JSON object the program wrote to ``{out}``, read within bounds: opened
    without blocking and refused unless it is a regular file (a FIFO, a link to
    /dev/zero or a directory is named, never waited on or read), refused unread
    when larger than an answer of ``n`` numbers can be, and parsed only when
    its nesting is at most :data:`_ANSWER_DEPTH` deep and none of its integers
    has more than :data:`_ANSWER_INT_DIGITS` digits; ValueError / OSError naming
    what is wrong otherwise."""
    limit = _ANSWER_BYTES_PER_NUMBER * n + _ANSWER_BYTES_EXTRA
    try:
        data = bounded_bytes(path, limit)
    except NotRegular as err:
        raise ValueError(f"it is {err.what}: expected a regular file holding a JSON object") from None
    except TooLarge as err:
        raise ValueError(f"it is {err.size} bytes: expected at most {limit} for an answer of {n} numbers" if err.size
                         else f"it holds more than {limit} bytes: expected at most {limit} for an answer of {n} "
                              f"numbers") from None
    text = data.decode("utf-8", errors="strict")
    depth = _nesting(text)
    if depth > _ANSWER_DEPTH:
        raise ValueError(f"its JSON is nested {depth} deep: expected at most {_ANSWER_DEPTH} "
                         f"(an object holding a list x)")
    return json.loads(text, parse_int=_bounded_int)


_ANSWER_BYTES_PER_NUMBER = 64  # bytes per number of x in the answer file, at most
_ANSWER_BYTES_EXTRA = 1 << 20  # and for the other fields (a reason)
_ANSWER_DEPTH = 8  # nesting of arrays and objects in an answer (it needs 2)
_ANSWER_INT_DIGITS = 20  # digits of an integer in an answer (an iteration count; 2**64 has 20)
_STRING = re.compile(r'"(?:[^"\\]|\\.)*"', re.DOTALL)


def _nesting(text: str) -> int:
    """The deepest nesting of ``[`` and ``{`` in the JSON ``text`` (strings left out),
    counted without recursion: json's own parser recurses and would exhaust the stack."""
    code = np.frombuffer(_STRING.sub("", text).encode("utf-8", errors="replace"), dtype=np.uint8)
    step = np.zeros(code.size, dtype=np.int64)
    step[(code == ord("[")) | (code == ord("{"))] = 1
    step[(code == ord("]")) | (code == ord("}"))] = -1
    return int(np.cumsum(step).max(initial=0))


def _bounded_int(digits: str) -> int:
    """A JSON integer of at most :data:`_ANSWER_INT_DIGITS` digits (a longer one is no
    iteration count, and as x or a time it is no float64)."""
    if len(digits.lstrip("-")) > _ANSWER_INT_DIGITS:
        raise ValueError(f"it holds an integer of {len(digits.lstrip('-'))} digits ({digits[:12]}...): "
                         f"expected at most {_ANSWER_INT_DIGITS} (write x and times as floats)")
    return int(digits)


def run_external(job: dict, timeout: float) -> dict:
    """Run the external program ``warmup + repeat`` times on job['hierarchy']."""
    from hikbench.problems.files import save_npz

    base = {"host": socket.gethostname(), "pid": os.getpid(), "calib_ns": None}
    cmd = external_command(job["solver"])
    h = job["hierarchy"]
    deadline = time.monotonic() + timeout
    wall, reported, last = [], [], {}
    with tempfile.TemporaryDirectory(prefix="hikbench-ext-") as tmp:
        paths = {"{problem}": os.path.join(tmp, "problem.npz"), "{out}": os.path.join(tmp, "out.json"),
                 "{problem_soth}": os.path.join(tmp, "problem.soth.txt")}
        save_npz(h, paths["{problem}"])
        if "{problem_soth}" in cmd:
            from hikbench.problems.soth import save_soth
            save_soth(h, paths["{problem_soth}"])
        try:
            argv = command_argv(cmd)
        except ValueError as err:
            return {**base, "status": ERROR, "x": None, "samples_ns": [], "reason": str(err)}
        for ph, p in paths.items():
            argv = [a.replace(ph, p) for a in argv]
        total = int(job.get("warmup", 0)) + int(job["repeat"])
        for i in range(total):
            _remove(paths["{out}"])
            ran = _run(argv, max(deadline - time.monotonic(), 0.001), tmp)
            if ran.timed_out:
                return {**base, "status": TIMEOUT, "x": None, "samples_ns": [],
                        "reason": f"external program exceeded the {timeout:g} s timeout"}
            if ran.error:
                return {**base, "status": ERROR, "x": None, "samples_ns": [], "reason": ran.error}
            if ran.returncode != 0:
                return {**base, "status": ERROR, "x": None, "samples_ns": [],
                        "reason": f"{_describe_code(ran.returncode)}: {_shorten(ran.output())}"}
            try:
                last = _read_answer(paths["{out}"], h.n)
            except (OSError, ValueError) as err:
                return {**base, "status": ERROR, "x": None, "samples_ns": [],
                        "reason": f"cannot read the program's output file: {err}"}
            parsed, problem = _check_output(last, h.n)
            if problem:
                return {**base, "status": ERROR, "x": None, "samples_ns": [],
                        "reason": f"bad output of the external program: {problem}"}
            if i >= total - int(job["repeat"]):
                wall.append(ran.elapsed_ns)
                reported.append(parsed["solve_time_s"])
    use_reported = all(r is not None for r in reported)
    samples = [int(r * 1e9) for r in reported] if use_reported else wall
    return {**base, "status": parsed["status"], "reason": parsed["reason"], "x": parsed["x"],
            "samples_ns": samples, "iterations": parsed["iterations"], "iterations_per_level": [],
            "activations": 0, "deactivations": 0, "flops": None, "build_time_s": float("nan"),
            "solve_time_s": float(np.median(reported)) if use_reported else float("nan")}


def _remove(path: str) -> None:
    """Remove what the last run left at ``path`` (a file, a FIFO, a link, or a directory)."""
    if os.path.isdir(path) and not os.path.islink(path):
        shutil.rmtree(path)
    elif os.path.lexists(path):
        os.remove(path)


def _shorten(text: str, head: int = 200, tail: int = 300) -> str:
    """``text`` cut to its first ``head`` and last ``tail`` characters, on one line."""
    text = " ".join(text.split())
    return text if len(text) <= head + tail + 5 else f"{text[:head]} ... {text[-tail:]}"


def _real_x(value, n: int) -> tuple[np.ndarray | None, str]:
    """``value`` (the answer's "x") as float64 of shape (n,), or what is wrong
    with it: not a list, another length, an element that is not a JSON number
    (a string such as "(1+2j)" is named as a complex number: x must be real; a
    numeric string is not read as a number either)."""
    if not isinstance(value, list):
        return None, f'"x" must be a list of {n} numbers; got {type(value).__name__}'
    if len(value) != n:
        return None, f'"x" has shape {_shape(value)}: expected ({n},)'
    for i, v in enumerate(value):
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            return None, f'"x" must be a list of {n} numbers: element {i} is {_describe_element(v)}'
    return np.asarray(value, dtype=float), ""


def _shape(value: list) -> tuple:
    """The shape of the nested lists ``value`` (of its first axis only when they are ragged)."""
    try:
        return np.shape(value) if all(isinstance(v, list) for v in value) else (len(value),)
    except ValueError:  # (ragged: numpy refuses an inhomogeneous shape)
        return (len(value),)


def _describe_element(v) -> str:
    """How :func:`_real_x` names an element of x that is not a real number."""
    if isinstance(v, str):
        try:
            complex(v.replace(" ", ""))
        except ValueError:
            return f"the string {v[:40]!r}"
        return f"the string {v[:40]!r}, a complex number: x must be real" if "j" in v.lower() else \
            f"the string {v[:40]!r}: expected a JSON number, not a string"
    return f"{type(v).__name__} {str(v)[:40]}"


# statuses a program may report; timeout and crashed are the harness's own
_PROGRAM_STATUSES = STATUSES


#: the fields of a program's answer (docs/adding-a-solver.md, "An external program")
_ANSWER_KEYS = ("x", "status", "solve_time_s", "iterations", "reason")


def _check_output(out, n: int) -> tuple[dict, str]:
    """Validate the JSON object a program wrote: ``(fields, "")`` or
    ``({}, what is wrong)``, naming the field and what was expected."""
    if not isinstance(out, dict):
        return {}, f"expected a JSON object, got {type(out).__name__}"
    status = out.get("status", OPTIMAL)
    if not isinstance(status, str) or status not in _PROGRAM_STATUSES:
        return {}, f'"status" must be one of {", ".join(_PROGRAM_STATUSES)}; got {status!r}'
    if "x" not in out:
        return {}, f'"x" is missing (a list of {n} numbers is required)'
    for key in out:
        if key not in _ANSWER_KEYS:
            close = difflib.get_close_matches(str(key), _ANSWER_KEYS, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            return {}, f"unknown field {key!r}{hint}; expected some of {', '.join(_ANSWER_KEYS)}"
    if out["x"] is None and status != OPTIMAL:
        x = None  # no solution, and the program says why
    elif out["x"] is None:
        return {}, f'"x" is null with status optimal: expected a list of {n} numbers'
    else:
        x, problem = _real_x(out["x"], n)
        if problem:
            return {}, problem
    t = out.get("solve_time_s")
    if t is not None and (isinstance(t, bool) or not isinstance(t, (int, float))
                          or not math.isfinite(t) or t < 0):
        return {}, f'"solve_time_s" must be a finite number >= 0 (seconds) or absent; got {t!r}'
    it = out.get("iterations")
    if it is None:
        it = 0
    elif (isinstance(it, bool) or not isinstance(it, (int, float)) or not math.isfinite(it)
          or it != int(it) or not 0 <= it < 2 ** 63):
        return {}, f'"iterations" must be an integer >= 0 or absent; got {it!r}'
    reason = "" if out.get("reason") is None else str(out["reason"])
    res = SolveResult(x, status, reason)  # its rule: an optimal x holding NaN or inf is a numerical_failure
    return {"x": x, "solve_time_s": None if t is None else float(t), "iterations": int(it),
            "status": res.status, "reason": res.reason}, ""
