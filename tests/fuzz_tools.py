"""Tools of the fuzz tests: mutations of valid files (bytes, TOML structure) and a
forked, bounded run of one reader or command line.

:func:`bounded` runs ``work()`` in a forked child (everything the test process has
loaded stays loaded: no start-up cost) under an address-space limit
(``RLIMIT_AS``: the child's size at the fork plus ``memory`` bytes) and a wall-time
limit; the child's outcome is one of ``"result"`` (work returned; for a command
line its exit code is in ``code``), ``"error"`` (a HikbenchError), ``"exception"``
(anything else: the property fails, the traceback is kept), ``"timeout"`` or
``"killed"``.
"""

from __future__ import annotations

import copy
import math
import os
import resource
import signal
import sys
import tempfile
import time
import tomllib
import traceback
from dataclasses import dataclass

from hypothesis import strategies as st

MEMORY = 1 << 30  # bytes a child may map beyond its size at the fork


@dataclass
class Outcome:
    kind: str       # result, error, exception, timeout, killed
    code: int = 0   # the command's exit code (kind "result" of a command line)
    detail: str = ""
    seconds: float = 0.0
    stderr: str = ""  # what the child wrote to fd 2 (its first MiB)


def _vm_size() -> int:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmSize:"):
                return int(line.split()[1]) * 1024
    raise RuntimeError("no VmSize in /proc/self/status")


def _child(work, report, memory: int, stderr) -> None:
    from hikbench.problems.errors import HikbenchError

    limit = _vm_size() + memory
    resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)  # (a command's own output: not the test's)
    os.dup2(stderr.fileno(), 2)
    sys.stdout = open(1, "w", closefd=False)  # (pytest's capture objects: not file descriptors)
    sys.stderr = open(2, "w", buffering=1, closefd=False)
    try:
        value = work()
        kind, code, detail = "result", int(value) if isinstance(value, int) else 0, ""
    except HikbenchError as err:
        kind, code, detail = "error", 2, " ".join(str(err).split())[:300]
    except BaseException:  # noqa: BLE001 - the property: nothing else escapes; kept for the report
        kind, code, detail = "exception", 99, traceback.format_exc()[-3000:]
    sys.stdout.flush()
    sys.stderr.flush()
    report.write(f"{kind}\n{code}\n{detail}".encode())
    report.flush()
    os._exit(0)


def bounded(work, seconds: float = 20.0, memory: int = MEMORY) -> Outcome:
    """``work()`` in a forked child bounded in memory and time (see the module docstring);
    what it wrote to stderr is in the outcome's ``stderr``."""
    with tempfile.TemporaryFile() as report, tempfile.TemporaryFile() as stderr:
        t0 = time.monotonic()
        pid = os.fork()
        if pid == 0:  # pragma: no cover - the child
            try:
                _child(work, report, memory, stderr)
            finally:
                os._exit(98)
        while True:
            done, status = os.waitpid(pid, os.WNOHANG)
            if done:
                break
            if time.monotonic() - t0 > seconds:
                os.kill(pid, signal.SIGKILL)
                os.waitpid(pid, 0)
                return Outcome("timeout", detail=f"no end within {seconds:g} s", seconds=seconds)
            time.sleep(0.01)
        elapsed = time.monotonic() - t0
        report.seek(0)
        text = report.read().decode(errors="replace")
        stderr.seek(0)
        err = stderr.read(1 << 20).decode(errors="replace")
    if not text:
        return Outcome("killed", detail=f"child ended with status {os.waitstatus_to_exitcode(status)}",
                       seconds=elapsed, stderr=err)
    kind, code, detail = text.split("\n", 2)
    return Outcome(kind, int(code), detail, elapsed, err)


# --- mutations ------------------------------------------------------------------------------------

def byte_mutations(data: bytes):
    """Bytes of ``data`` with 1-4 flips, truncations, insertions or deletions."""
    @st.composite
    def mutated(draw):
        out = bytearray(data)
        for _ in range(draw(st.integers(1, 4))):
            op = draw(st.sampled_from(["flip", "truncate", "insert", "delete"]))
            i = draw(st.integers(0, max(len(out) - 1, 0)))
            if op == "flip" and out:
                out[i] ^= draw(st.integers(1, 255))
            elif op == "truncate":
                del out[i:]
            elif op == "insert":
                out[i:i] = draw(st.binary(min_size=1, max_size=16))
            elif out:
                del out[i:i + draw(st.integers(1, 16))]
        return bytes(out)
    return mutated()


BAD_VALUES = ["x", "", "now", math.nan, math.inf, -math.inf, -1, 0, 1.5, 10**18, -(10**18), 1e308, 1e-308, True,
              [], [1], ["a"], [math.nan, 1, 2], {}, {"a": 1}, "a" * 10_000, [[1, 2], [3]]]


def _paths(value, prefix=()):
    """Every key path of a parsed TOML document (dict keys and list indices)."""
    if isinstance(value, dict):
        for k, v in value.items():
            yield (*prefix, k)
            yield from _paths(v, (*prefix, k))
    elif isinstance(value, list):
        for i, v in enumerate(value):
            yield (*prefix, i)
            yield from _paths(v, (*prefix, i))


def _typo(key: str, draw) -> str:
    if not key:
        return "x"
    i = draw(st.integers(0, len(key) - 1))
    op = draw(st.sampled_from(["drop", "double", "swap", "other"]))
    if op == "drop":
        return key[:i] + key[i + 1:] or "x"
    if op == "double":
        return key[:i] + key[i] + key[i:]
    if op == "swap" and len(key) > 1:
        j = min(i + 1, len(key) - 1)
        return key[:i] + key[j] + key[i] + key[j + 1:] if i != j else key + "s"
    return draw(st.text(alphabet="abcdefghijklmnopqrstuvwxyz_", min_size=1, max_size=12))


def toml_mutations(text: str):
    """TOML documents made from ``text`` by 1-3 key renames (typos), value swaps (to
    another type, NaN, inf, huge numbers, long strings) or deletions; sometimes then
    byte-mutated as well."""
    import tomli_w

    base = tomllib.loads(text)

    @st.composite
    def mutated(draw):
        doc = tomllib.loads(text)
        for _ in range(draw(st.integers(1, 3))):
            paths = list(_paths(doc))
            if not paths:
                break
            path = draw(st.sampled_from(paths))
            parent = doc
            for p in path[:-1]:
                parent = parent[p]
            last = path[-1]
            op = draw(st.sampled_from(["rename", "value", "value", "delete"]))
            if op == "rename" and isinstance(parent, dict):
                parent[_typo(last, draw)] = parent.pop(last)
            elif op == "delete":
                del parent[last]
            else:
                parent[last] = copy.deepcopy(draw(st.sampled_from(BAD_VALUES)))  # (mutated later on)
        out = tomli_w.dumps(doc).encode()
        if draw(st.booleans()) and draw(st.booleans()):  # one in four: bytes too
            out = draw(byte_mutations(out))
        return out

    assert base  # (a valid document to start from)
    return mutated()
