"""What run.json records about the machine and the software: package
versions, CPU model, BLAS (threadpoolctl + numpy's build config), git commit."""

from __future__ import annotations

import datetime as _dt
import json
import os
import platform
import socket
import subprocess
import sys
from importlib import metadata
from pathlib import Path

__all__ = ["PACKAGES", "environment", "machine_class", "numba_target", "openblas_kernels",
           "read_run_json", "utc_now", "write_run_json"]

PACKAGES = ("hikbench", "numpy", "scipy", "pandas", "numba", "llvmlite", "threadpoolctl", "qpsolvers", "osqp",
            "proxsuite", "clarabel", "daqp", "quadprog", "piqp", "highspy", "cvxpy", "pin",
            "example-robot-data-loaders", "matplotlib", "rich", "dask", "distributed")
RUN_JSON = "run.json"


def utc_now() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")


def _versions() -> dict:
    out = {"python": platform.python_version()}
    for p in PACKAGES:
        try:
            out[p] = metadata.version(p)
        except metadata.PackageNotFoundError:
            out[p] = None
    return out


def cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass  # not Linux: fall back to platform
    return platform.processor() or platform.machine()


def _blas() -> dict:
    import numpy as np
    from threadpoolctl import threadpool_info

    info = {"threadpools": [{k: v for k, v in d.items() if k in ("user_api", "internal_api", "version",
                                                                  "num_threads", "threading_layer",
                                                                  "architecture", "filepath")}
                            for d in threadpool_info()]}
    try:
        cfg = np.show_config(mode="dicts")
        info["numpy_build"] = cfg.get("Build Dependencies", cfg)
    except TypeError:  # numpy < 1.25 has no mode argument
        info["numpy_build"] = None
    return info


def _git() -> dict:
    root = Path(__file__).resolve().parents[2]  # the checkout (bench/harness/../..)
    def git(*args):  # its output, None when git failed (no repository, no git, timeout)
        try:
            # (--no-optional-locks: `status` would refresh the index under index.lock, and a git killed
            # at the timeout, or stopped by a full disk, would leave that lock to block the user's next commit)
            done = subprocess.run(["git", "--no-optional-locks", "-C", str(root), *args], capture_output=True, text=True,
                                  timeout=10, check=False)  # (the return code is read below)
        except (OSError, subprocess.TimeoutExpired):
            return None
        return done.stdout.strip() if done.returncode == 0 else None
    commit = git("rev-parse", "HEAD")
    status = git("status", "--porcelain", "--untracked-files=no") if commit else None
    return {"commit": commit or None, "branch": git("rev-parse", "--abbrev-ref", "HEAD") or None,
            "dirty": None if status is None else bool(status)}  # (unknown, never a claimed clean tree)


def numba_target() -> str:
    """The CPU numba compiles the solvers' kernels for: ``NUMBA_CPU_NAME``
    when set, else LLVM's name of this CPU (e.g. "znver4", "znver5")."""
    from llvmlite import binding

    return os.environ.get("NUMBA_CPU_NAME") or binding.get_host_cpu_name()


def environment() -> dict:
    return {
        "host": socket.gethostname(),
        "platform": platform.platform(),
        "cpu": cpu_model(),
        "numba_target": numba_target(),
        "cpu_count": os.cpu_count(),
        "versions": _versions(),
        "blas": _blas(),
        "git": _git(),
        "peers": _peers(),
        "argv": sys.argv,
    }


def _peers() -> dict | None:
    """How the C++ peers soth, lexls and nipm-hlsp were built (``make peers``: commits,
    compiler, flags, ``march_native``), None when they are not built."""
    from hikbench.solvers.peers import build_info

    return build_info()


def openblas_kernels(threadpools: list[dict]) -> str | None:
    """The kernels (threadpoolctl's ``architecture``) of numpy's OpenBLAS
    among ``threadpools`` (threadpoolctl's ``threadpool_info()``, or as
    run.json records it), else of another OpenBLAS; None without one."""
    pools = [t for t in threadpools if t.get("internal_api") == "openblas"]
    numpy_pools = [t for t in pools if "numpy" in str(t.get("filepath", ""))]
    return next((t.get("architecture") for t in numpy_pools + pools if t.get("architecture")), None)


def machine_class(env: dict) -> str | None:
    """The kind of machine a run.json's ``environment`` was recorded on: the
    CPU model, the kernels numpy's OpenBLAS chose for it (threadpoolctl's
    ``architecture``: "Haswell" on an AVX2 CPU, "SkylakeX" on an AVX-512 one,
    or what the environment's ``OPENBLAS_CORETYPE`` asks for) and, when
    recorded (run.json files from 2026-11-23 on), numba's target
    (:func:`numba_target`), e.g. ``"AMD EPYC, OpenBLAS SkylakeX, numba
    znver4"``; None when the run.json says neither CPU nor BLAS. Timing ratios
    between solvers move with it (the calibration kernel does not absorb that:
    normalised by it, 5 cases of hcod read 1.23-1.30x slower on an AMD EPYC
    Zen 5 than on a Zen 4, both "AMD EPYC" with SkylakeX kernels), so a
    timing baseline holds for one class."""
    cpu = env.get("cpu")
    arch = openblas_kernels((env.get("blas") or {}).get("threadpools", []))
    if cpu is None and arch is None:
        return None
    target = env.get("numba_target")
    return f"{cpu or 'unknown CPU'}, OpenBLAS {arch or 'unknown'}" + (f", numba {target}" if target else "")


#: the types of the fields of run.json that runs, reports and compare read (others are kept as they are)
RUN_JSON_TYPES = {"sessions": list, "selected_solvers": list, "suite": dict, "environment": dict,
                  "accuracy": dict, "skipped_solvers": dict, "export_skipped": dict, "key": list,
                  "suite_rows": int, "suite_scenario_runs": int, "calibration_ns": (int, float),
                  "created": str, "yardstick_code": str, "calibration_kernel": str}
_RUN_JSON_BYTES = 1 << 28  # a run.json larger than this is refused unread (its sessions are a few hundred bytes)


def read_run_json(run_dir) -> dict:
    """OUT/run.json as a dict ({} when there is none); HikbenchError when it is no regular file
    (a FIFO, a folder), not a JSON object, or a field of :data:`RUN_JSON_TYPES` has another type."""
    from hikbench.bench.harness.regular import read_regular, regular_or_absent
    from hikbench.problems.errors import HikbenchError

    p = Path(run_dir) / RUN_JSON
    expected = "the run.json written by hikbench run"
    if not regular_or_absent(p, expected):
        return {}
    try:
        data = json.loads(read_regular(p, _RUN_JSON_BYTES, expected).decode("utf-8"))
    except (RecursionError, ValueError) as err:  # (JSONDecodeError, UnicodeDecodeError, digits past the limit)
        why = "nested too deep" if isinstance(err, RecursionError) else str(err)
        raise HikbenchError(f"{p}: not valid JSON ({why}); expected {expected} "
                            f"(restore it, or write to a new --out directory)") from None
    if not isinstance(data, dict):
        raise HikbenchError(f"{p}: expected a JSON object (the run.json written by hikbench run); "
                            f"got a {type(data).__name__}")
    for key, types in RUN_JSON_TYPES.items():
        value = data.get(key)
        if value is not None and (not isinstance(value, types) or isinstance(value, bool)):
            want = " or ".join(t.__name__ for t in (types if isinstance(types, tuple) else (types,)))
            raise HikbenchError(f"{p}: {key} is a {type(value).__name__}: expected a {want} ({expected}; "
                                f"restore it, or write to a new --out directory)")
    bad = next((i for i, s in enumerate(data.get("sessions") or []) if not isinstance(s, dict)), None)
    if bad is not None:
        raise HikbenchError(f"{p}: sessions[{bad}] is a {type(data['sessions'][bad]).__name__}: expected an "
                            f"object ({expected}; restore it, or write to a new --out directory)")
    return data


def write_run_json(run_dir, data: dict) -> None:
    """Write OUT/run.json whole or not at all: through ``run.json.tmp``, fsynced, then
    renamed over it; a write that fails (a full disk) removes the temporary file and
    raises HikbenchError naming the cause, the previous run.json left as it was."""
    from hikbench.problems.errors import HikbenchError

    p = Path(run_dir) / RUN_JSON
    tmp = p.with_suffix(".json.tmp")
    try:
        with open(tmp, "w") as f:
            f.write(json.dumps(data, indent=1, default=str) + "\n")
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, p)
    except OSError as err:
        if not tmp.is_dir():  # (a folder in its place is not this function's to remove)
            tmp.unlink(missing_ok=True)
        raise HikbenchError(f"{p}: cannot write it ({err.strerror or err}); the previous {RUN_JSON} is left as "
                            f"it was") from None
