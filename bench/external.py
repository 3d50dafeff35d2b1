"""External solvers: ``--solvers external:NAME=CMD``.

Protocol (README, "External solvers"): for every solve, the harness writes the
problem to a temporary directory and runs CMD (split like a shell command line,
no shell) after replacing the placeholders

* ``{problem}``       path of the problem as ``.npz`` (problems/files.py layout),
* ``{problem_soth}``  path of the problem in SOTH text format (needs problems.soth),
* ``{out}``           path where the program must write its answer,

and reads ``{out}``: a JSON object ``{"x": [...], "solve_time_s": t,
"status": "optimal", "iterations": k}`` where only ``x`` is required. The row's
time samples are the ``solve_time_s`` the program reports when every
repetition reports one (its own timer, without process start-up), else the wall
time of the whole process. A non-zero exit code gives status ``error`` with the
end of stderr; exceeding the job timeout gives ``timeout``. Each repetition is
a fresh process, so external solvers run in ``cold`` mode only.
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

from problems.errors import HikbenchError
from solvers.base import ERROR, OPTIMAL, STATUSES, TIMEOUT

__all__ = ["parse_external", "run_external"]


def parse_external(text: str):
    """``external:NAME=CMD`` -> SolverEntry."""
    from bench.suites import SolverEntry

    body = text[len("external:"):]
    name, sep, cmd = body.partition("=")
    if not sep or not name or not cmd.strip():
        raise HikbenchError(f"{text!r}: expected external:NAME=CMD, e.g. "
                            "external:mysolver='./mysolver {problem} {out}'")
    if "{out}" not in cmd:
        raise HikbenchError(f"{text!r}: CMD must contain the placeholder {{out}} (where x is written)")
    return SolverEntry(solver=f"external:{name}", spec=text, strict=True, warm=False)


def _command(spec: str) -> str:
    return spec[len("external:"):].partition("=")[2]


def run_external(job: dict, timeout: float) -> dict:
    """Run the external program ``warmup + repeat`` times on job['hierarchy']."""
    from problems.files import save_npz

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
            from problems.soth import save_soth
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
                proc = subprocess.run(argv, capture_output=True, text=True,
                                      timeout=max(deadline - time.monotonic(), 0.001))
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
                x = np.asarray(last["x"], dtype=float)
            except (OSError, ValueError, KeyError, TypeError) as err:
                return {**base, "status": ERROR, "x": None, "samples_ns": [],
                        "reason": f"cannot read x from the program's output file: {err}"}
            if i >= total - int(job["repeat"]):
                wall.append(dt)
                t = last.get("solve_time_s")
                reported.append(float(t) if isinstance(t, (int, float)) and math.isfinite(t) else None)
    use_reported = all(r is not None for r in reported)
    samples = [int(r * 1e9) for r in reported] if use_reported else wall
    status = last.get("status", OPTIMAL)
    if status not in STATUSES:
        status, reason = ERROR, f"unknown status {last.get('status')!r} from the external program"
    else:
        reason = str(last.get("reason", ""))
    if x.shape != (h.n,):
        return {**base, "status": ERROR, "x": None, "samples_ns": [],
                "reason": f"x has shape {x.shape}: expected ({h.n},)"}
    return {**base, "status": status, "reason": reason, "x": x, "samples_ns": samples,
            "iterations": int(last.get("iterations", 0) or 0), "iterations_per_level": [],
            "activations": 0, "deactivations": 0, "flops": None, "build_time_s": float("nan"),
            "solve_time_s": float(np.median(reported)) if use_reported else float("nan")}
