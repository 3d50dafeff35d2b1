"""External programs that break the output protocol cost one error row (with
a reason naming the field), never the run (bench/harness/external.py)."""

import json
import sys

import numpy as np
import pytest
from doubles import tiny, write_suite

from hikbench.bench.cli import main
from hikbench.bench.harness.external import run_external
from hikbench.bench.harness.results import read_results

# writes argv[3] (a JSON object; "X" stands for a correct-length zero x) to {out}
PROG = """
import json, sys
import numpy as np
n = int(np.load(sys.argv[1])["n"])
out = json.loads(sys.argv[3])
if out.get("x") == "X":
    out["x"] = [0.0] * n
elif out.get("x") == "NaN":
    out["x"] = [0.0] * (n - 1) + [float("nan")]
with open(sys.argv[2], "w") as f:
    f.write(json.dumps(out))
"""


@pytest.fixture(scope="module")
def prog(tmp_path_factory):
    p = tmp_path_factory.mktemp("ext") / "prog.py"
    p.write_text(PROG)
    return p


def _job(prog, payload: dict) -> dict:
    arg = json.dumps(payload).replace("'", "")
    return {"solver": f"external:p={sys.executable} {prog} {{problem}} {{out}} '{arg}'",
            "hierarchy": tiny(n=4), "repeat": 1, "warmup": 0}


@pytest.mark.parametrize("payload, fragment", [
    ({"x": "X", "iterations": "many"}, '"iterations" must be an integer >= 0 or absent; got \'many\''),
    ({"x": "X", "iterations": -2}, '"iterations" must be an integer >= 0'),
    ({"x": "X", "iterations": 2.5}, '"iterations" must be an integer >= 0'),
    ({"x": "X", "solve_time_s": -1}, '"solve_time_s" must be a finite number >= 0 (seconds) or absent; got -1'),
    ({"x": "X", "solve_time_s": "fast"}, '"solve_time_s" must be a finite number >= 0'),
    ({"x": "X", "status": "great"}, '"status" must be one of optimal'),
    ({"x": "X", "status": "timeout"}, '"status" must be one of'),
    ({"x": [1, 2]}, '"x" has shape (2,): expected (4,)'),
    ({"x": ["a", "b", "c", "d"]}, '"x" must be a list of 4 numbers'),
    ({"y": 1}, '"x" is missing'),
    ({"x": None}, '"x" is null with status optimal: expected a list of 4 numbers'),
    ({"x": "X", "solve_time": 1e-4}, "unknown field 'solve_time' (did you mean 'solve_time_s'?); expected some of x, "
                                     "status, solve_time_s, iterations, reason"),
    ({"x": "X", "flops": 12}, "unknown field 'flops'; expected some of"),
], ids=["iterations string", "iterations negative", "iterations fraction", "time negative", "time string",
        "status unknown", "status harness", "x short", "x strings", "x missing", "x null optimal",
        "field misspelt", "field unknown"])
def test_bad_output_is_an_error_row(prog, payload, fragment):
    res = run_external(_job(prog, payload), timeout=30)
    assert res["status"] == "error" and res["x"] is None and res["samples_ns"] == []
    assert res["reason"].startswith("bad output of the external program: ")
    assert fragment in res["reason"], res["reason"]


@pytest.mark.parametrize("payload, status, iterations, reported", [
    ({"x": "X", "iterations": 3, "solve_time_s": 2e-4}, "optimal", 3, 2e-4),
    ({"x": "X", "iterations": 3.0, "solve_time_s": 0}, "optimal", 3, 0.0),
    ({"x": "X", "iterations": None, "solve_time_s": None}, "optimal", 0, None),
    ({"x": None, "status": "unsupported", "reason": "no inequalities"}, "unsupported", 0, None),
    ({"x": "NaN", "iterations": 2}, "numerical_failure", 2, None),
], ids=["full", "integral float, zero time", "nulls", "no x with a status", "x with NaN called optimal"])
def test_good_output(prog, payload, status, iterations, reported):
    res = run_external(_job(prog, payload), timeout=30)
    assert res["status"] == status and res["iterations"] == iterations
    assert res["reason"] == {"unsupported": "no inequalities", "numerical_failure": "x holds NaN or inf"}.get(status, "")
    if reported is None:
        assert np.isnan(res["solve_time_s"])
    else:
        assert res["solve_time_s"] == reported and res["samples_ns"] == [int(reported * 1e9)]


def test_run_goes_on_after_a_bad_output(prog, tmp_path, capsys):
    """A bad output ("iterations": "many") costs its own row only: the run goes on to the end,
    no traceback."""
    suite = write_suite(tmp_path / "s.toml", ["yardstick"], grid={"n": [4, 6], "depth": [2]}, repeat=1,
                        modes=("cold",))
    bad = f"external:bad={sys.executable} {prog} {{problem}} {{out}} '{{\"x\": \"X\", \"iterations\": \"many\"}}'"
    assert main(["run", "--quiet", "--suite", str(suite), "--out", str(tmp_path / "o"),
                 "--solvers", "yardstick", bad]) == 0
    assert "Traceback" not in capsys.readouterr().err
    df = read_results(tmp_path / "o")
    rows = df[df["solver"] == "external:bad"]
    assert len(rows) == 2 and set(rows["status"]) == {"error"}
    assert rows["reason"].str.contains('"iterations" must be an integer').all()
    assert set(df[df["solver"] == "yardstick"]["status"]) == {"optimal"}


def test_a_timed_out_program_leaves_no_background_child(tmp_path):
    """On a timeout only the direct child was killed: a shell's background child kept running
    (and burning CPU through the timings of later jobs)."""
    import os
    import time

    pidfile = tmp_path / "bg.pid"
    job = {"solver": f"external:p=sh -c 'sleep 30 & echo $! > {pidfile}; wait'", "hierarchy": tiny(n=4),
           "repeat": 1, "warmup": 0}
    t0 = time.monotonic()
    res = run_external(job, timeout=0.5)
    assert res["status"] == "timeout" and "0.5 s timeout" in res["reason"]
    assert time.monotonic() - t0 < 10
    pid = int(pidfile.read_text())
    for _ in range(100):  # SIGKILL is delivered at once; the orphan is reaped by init soon after
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            break
        time.sleep(0.05)
    else:
        raise AssertionError(f"background child {pid} still running after the timeout")
