"""An external program cannot take the run down: its output is read in bounded
memory, the timeout is wall time whatever it leaves running, and every process
it started is gone when its job ends (bench/harness/external.py, launcher.py)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
from doubles import tiny, write_suite

from hikbench.bench.harness.external import run_external
from hikbench.bench.harness.results import read_results

HERE = Path(__file__).parent
MB = 1 << 20

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="process containment is Linux's")


def _job(cmd: str, n: int = 4) -> dict:
    return {"solver": f"external:p={cmd}", "hierarchy": tiny(n=n), "repeat": 1, "warmup": 0}


def _gone(pid: int, within: float = 2.0) -> bool:
    """Whether process ``pid`` no longer exists (not even as a zombie) within ``within`` s."""
    deadline = time.monotonic() + within
    while time.monotonic() < deadline:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return True
        time.sleep(0.02)
    return False


def _pids(path: Path) -> list[int]:
    deadline = time.monotonic() + 5
    while not path.exists() and time.monotonic() < deadline:
        time.sleep(0.02)
    return [int(p) for p in path.read_text().split()]


# runs argv[1] (python code) in a fresh interpreter with hikbench imported; prints its peak
# resident memory (KiB) before and after the code, and the code's wall time
_MEASURE = """
import json, resource, sys, time
sys.path.insert(0, sys.argv[2])
import numpy as np
import hikbench.bench.cli, hikbench.bench.harness.external
from doubles import tiny
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
t0 = time.monotonic()
exec(sys.argv[1])
wall = time.monotonic() - t0
print(json.dumps({"before_kib": before, "after_kib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss,
                  "wall_s": wall, "result": RESULT}))
"""


def _measured(code: str, cwd) -> dict:
    """Run ``code`` (it sets RESULT) under _MEASURE; returns its JSON report."""
    out = subprocess.run([sys.executable, "-c", _MEASURE, code, str(HERE)], capture_output=True, text=True,
                         cwd=cwd, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    return {**json.loads(out.stdout.strip().splitlines()[-1]), "stderr": out.stderr[-2000:]}


def test_a_program_flooding_stdout_is_read_in_bounded_memory(tmp_path):
    code = ("from hikbench.bench.harness.external import run_external\n"
            "r = run_external({'solver': 'external:p=sh -c \"yes garbage\"', 'hierarchy': tiny(n=4), "
            "'repeat': 1, 'warmup': 0}, timeout=1.5)\n"
            "RESULT = {'status': r['status'], 'reason': r['reason']}")
    rep = _measured(code, tmp_path)
    assert rep["result"]["status"] == "timeout", rep
    assert rep["wall_s"] < 1.5 + 2, rep
    assert (rep["after_kib"] - rep["before_kib"]) * 1024 < 200 * MB, rep


def test_the_timeout_is_wall_time_when_a_background_process_holds_the_output(tmp_path):
    """communicate() waited for the pipes to close: for the sleep left in the background."""
    pids = tmp_path / "bg.pid"
    t0 = time.monotonic()
    res = run_external(_job(f"sh -c 'setsid sleep 40 & echo $! > {pids}; sleep 40'"), timeout=1.0)
    assert res["status"] == "timeout" and "1 s timeout" in res["reason"]
    assert time.monotonic() - t0 < 1.0 + 2
    assert all(_gone(p) for p in _pids(pids))


def test_a_background_process_left_by_a_program_that_answered_is_killed_at_once(tmp_path):
    pids = tmp_path / "bg.pid"
    cmd = f"""sh -c 'setsid sleep 40 & echo $! >> {pids}; printf "{{\\"x\\": [0, 0, 0, 0]}}" > {{out}}'"""
    job = {**_job(cmd), "warmup": 1}
    t0 = time.monotonic()
    res = run_external(job, timeout=5.0)
    assert res["status"] == "optimal", res["reason"]
    assert time.monotonic() - t0 < 5.0
    found = _pids(pids)
    assert len(found) == 2 and all(_gone(p) for p in found)


def test_a_grandchild_in_a_session_of_its_own_dies_at_the_timeout(tmp_path):
    """Only the program's process group was killed: a grandchild that called setsid
    (and whose parent had exited: an orphan) survived, though the docs say every
    process a solver started is killed."""
    pids = tmp_path / "gc.pid"
    cmd = f"sh -c '(setsid sleep 30 < /dev/null > /dev/null 2>&1 & echo $! > {pids}); sleep 30'"
    res = run_external(_job(cmd), timeout=1.0)
    assert res["status"] == "timeout"
    [pid] = _pids(pids)
    assert _gone(pid), f"grandchild {pid} in its own session survived the timeout"


def test_an_error_reason_keeps_the_head_and_tail_of_a_long_stderr(tmp_path):
    prog = tmp_path / "noisy.py"
    prog.write_text("import sys\nsys.stderr.write('FIRST LINE\\n' + 'x' * 3000000 + '\\nLAST LINE')\nsys.exit(3)\n")
    res = run_external(_job(f"{sys.executable} {prog}"), timeout=30)
    assert res["status"] == "error" and res["reason"].startswith("exit code 3: FIRST LINE")
    assert res["reason"].endswith("LAST LINE") and len(res["reason"]) < 600, res["reason"][:300]


def test_a_program_killed_by_a_signal_is_an_error_naming_it(tmp_path):
    res = run_external(_job("sh -c 'kill -SEGV $$'"), timeout=30)
    assert res["status"] == "error" and res["reason"].startswith("killed by signal SIGSEGV"), res["reason"]


def test_an_answer_file_larger_than_an_answer_is_refused_unread(tmp_path):
    cmd = "sh -c 'head -c 3000000 /dev/zero | tr \"\\0\" \" \" > {out}'"
    res = run_external(_job(cmd), timeout=30)
    assert res["status"] == "error" and "3000000 bytes: expected at most" in res["reason"], res["reason"]


def test_a_run_with_a_flooding_and_a_lingering_program_finishes_in_time_and_writes_its_rows(tmp_path):
    """Within timeout + 2 s per row, memory under 200 MB above
    the run's own, every row written."""
    suite = write_suite(tmp_path / "s.toml", ["yardstick"], grid={"n": [4], "depth": [1]}, repeat=1,
                        timeout=2.0, modes=("cold",))
    pids = tmp_path / "bg.pid"
    flood = 'external:flood=sh -c "yes garbage" {out}'  # (the answer never written)
    linger = (f"""external:linger=sh -c 'setsid sleep 40 & echo $! >> {pids}; """
              f"""printf "{{\\"x\\": [0, 0, 0, 0]}}" > {{out}}'""")
    argv = ["run", "--quiet", "--suite", str(suite), "--out", str(tmp_path / "o"), "--solvers", flood, linger]
    code = f"from hikbench.bench.cli import main\nRESULT = main({argv!r})"
    rep = _measured(code, tmp_path)
    assert rep["result"] == 0, rep
    assert (rep["after_kib"] - rep["before_kib"]) * 1024 < 200 * MB, rep
    df = read_results(tmp_path / "o").set_index("solver")
    assert df.loc["external:flood", "status"] == "timeout"
    assert df.loc["external:linger", "status"] == "optimal"
    assert (df["wall_s"] < 2.0 + 2).all(), df["wall_s"]
    assert all(_gone(p) for p in _pids(pids))
