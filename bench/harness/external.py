"""External solvers: ``--solvers external:NAME=CMD``.

Protocol (docs/adding-a-solver.md, "An external program"): for every solve, the harness writes the
problem to a temporary directory and runs CMD (split like a shell command line,
no shell) after replacing the placeholders

* ``{problem}``       path of the problem as ``.npz`` (problems/files.py layout),
* ``{problem_soth}``  path of the problem in SOTH text format (needs hikbench.problems.soth),
* ``{out}``           path where the program must write its answer,

and reads ``{out}``: a JSON object ``{"x": [...], "solve_time_s": t,
"status": "optimal", "iterations": k}`` where only ``x`` is required (it may
be ``null`` with a status other than ``optimal``). The row's
time samples are the ``solve_time_s`` the program reports when every
repetition reports one (its own timer, without process start-up), else the wall
time of the whole process. A non-zero exit code gives status ``error`` with the
end of stderr; exceeding the job timeout gives ``timeout``; an output that
breaks the protocol (no ``x`` or a wrong shape, ``solve_time_s`` not a finite
number >= 0, ``iterations`` not an integer >= 0, an unknown ``status``) gives
``error`` with a reason naming the field; an ``x`` holding NaN or inf that
the program calls optimal gives ``numerical_failure``. Each repetition is a fresh process,
so external solvers run in ``cold`` mode only.
"""

from __future__ import annotations

import json
import math
import os
import shlex
import socket
import subprocess
import tempfile
import time

import numpy as np

from hikbench.bench.harness.isolation import kill_session
from hikbench.problems.errors import HikbenchError
from hikbench.bench.harness.statuses import CRASHED, TIMEOUT
from hikbench.solvers.base import ERROR, OPTIMAL, STATUSES, SolveResult

__all__ = ["run_external"]


def _command(spec: str) -> str:
    return spec[len("external:"):].partition("=")[2]


def _run(argv: list[str], timeout: float) -> subprocess.CompletedProcess:
    """subprocess.run(argv) in a session of its own; past ``timeout`` the whole
    session is killed (a shell's background children too, not only the direct
    child: orphans would burn CPU through later timings) and TimeoutExpired raised."""
    with subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                          start_new_session=True) as proc:
        try:
            out, err = proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            kill_session(proc.pid)
            proc.communicate()
            raise
    return subprocess.CompletedProcess(argv, proc.returncode, out, err)


def run_external(job: dict, timeout: float) -> dict:
    """Run the external program ``warmup + repeat`` times on job['hierarchy']."""
    from hikbench.problems.files import save_npz

    base = {"host": socket.gethostname(), "pid": os.getpid(), "calib_ns": None}
    cmd = _command(job["solver"])
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
        argv = [a for a in shlex.split(cmd)]
        for ph, p in paths.items():
            argv = [a.replace(ph, p) for a in argv]
        total = int(job.get("warmup", 0)) + int(job["repeat"])
        for i in range(total):
            if os.path.exists(paths["{out}"]):
                os.remove(paths["{out}"])
            t0 = time.perf_counter_ns()
            try:
                proc = _run(argv, max(deadline - time.monotonic(), 0.001))
            except subprocess.TimeoutExpired:
                return {**base, "status": TIMEOUT, "x": None, "samples_ns": [],
                        "reason": f"external program exceeded the {timeout:g} s timeout"}
            except OSError as err:
                return {**base, "status": ERROR, "x": None, "samples_ns": [],
                        "reason": f"cannot run {argv[0]!r}: {err}"}
            dt = time.perf_counter_ns() - t0
            if proc.returncode != 0:
                return {**base, "status": ERROR, "x": None, "samples_ns": [],
                        "reason": f"exit code {proc.returncode}: {proc.stderr.strip()[-300:]}"}
            try:
                with open(paths["{out}"]) as f:
                    last = json.load(f)
            except (OSError, ValueError) as err:
                return {**base, "status": ERROR, "x": None, "samples_ns": [],
                        "reason": f"cannot read the program's output file: {err}"}
            parsed, problem = _check_output(last, h.n)
            if problem:
                return {**base, "status": ERROR, "x": None, "samples_ns": [],
                        "reason": f"bad output of the external program: {problem}"}
            if i >= total - int(job["repeat"]):
                wall.append(dt)
                reported.append(parsed["solve_time_s"])
    use_reported = all(r is not None for r in reported)
    samples = [int(r * 1e9) for r in reported] if use_reported else wall
    return {**base, "status": parsed["status"], "reason": parsed["reason"], "x": parsed["x"],
            "samples_ns": samples, "iterations": parsed["iterations"], "iterations_per_level": [],
            "activations": 0, "deactivations": 0, "flops": None, "build_time_s": float("nan"),
            "solve_time_s": float(np.median(reported)) if use_reported else float("nan")}


# statuses a program may report; timeout and crashed are the harness's own
_PROGRAM_STATUSES = STATUSES


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
    if out["x"] is None and status != OPTIMAL:
        x = None  # no solution, and the program says why
    elif out["x"] is None:
        return {}, f'"x" is null with status optimal: expected a list of {n} numbers'
    else:
        try:
            x = np.asarray(out["x"], dtype=float)
        except (ValueError, TypeError):
            return {}, f'"x" must be a list of {n} numbers'
        if x.shape != (n,):
            return {}, f'"x" has shape {x.shape}: expected ({n},)'
    t = out.get("solve_time_s")
    if t is not None and (isinstance(t, bool) or not isinstance(t, (int, float))
                          or not math.isfinite(t) or t < 0):
        return {}, f'"solve_time_s" must be a finite number >= 0 (seconds) or absent; got {t!r}'
    it = out.get("iterations")
    if it is None:
        it = 0
    elif (isinstance(it, bool) or not isinstance(it, (int, float)) or not math.isfinite(it)
          or it != int(it) or it < 0):
        return {}, f'"iterations" must be an integer >= 0 or absent; got {it!r}'
    reason = "" if out.get("reason") is None else str(out["reason"])
    res = SolveResult(x, status, reason)  # its rule: an optimal x holding NaN or inf is a numerical_failure
    return {"x": x, "solve_time_s": None if t is None else float(t), "iterations": int(it),
            "status": res.status, "reason": res.reason}, ""
