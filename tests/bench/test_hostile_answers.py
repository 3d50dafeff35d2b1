"""An external program's answer is read and checked within bounds (nesting,
digits, bytes, the kind of file at ``{out}``), in the isolated worker: a
hostile answer costs its row with a reason, never the run nor its resume; a
command that cannot be run is one line before the first job
(bench/harness/external.py, executors.py)."""

import os
import shlex
import sys
import time

import pytest
from clitools import assert_user_error, run
from doubles import tiny, write_suite

from hikbench.bench.harness.external import parse_spec, run_external
from hikbench.bench.harness.results import read_results

# writes sys.argv[2] (Python code giving the answer's text: `n` is the problem's size) to {out}
WRITER = """
import sys
import numpy as np
n = int(np.load(sys.argv[1])["n"])
with open(sys.argv[3], "w") as f:
    f.write(eval(sys.argv[2]))
"""


@pytest.fixture(scope="module")
def writer(tmp_path_factory):
    p = tmp_path_factory.mktemp("hostile") / "writer.py"
    p.write_text(WRITER)
    return p


def _spec(writer, text_expr: str) -> str:
    return f"external:p={sys.executable} {writer} {{problem}} {shlex.quote(text_expr)} {{out}}"


def _job(cmd_spec: str) -> dict:
    return {"solver": cmd_spec, "hierarchy": tiny(n=4), "repeat": 1, "warmup": 0}


BIG = "1" + "0" * 399  # an integer of 400 digits


@pytest.mark.parametrize("text_expr, fragment", [
    ('"[" * 200000 + "]" * 200000', "its JSON is nested 200000 deep: expected at most 8"),
    ('"{\\"x\\": " + "[" * 5000 + "]" * 5000 + "}"', "nested 5001 deep"),
    (f'"{{\\"x\\": [{BIG}, 0, 0, 0]}}"', "an integer of 400 digits"),
    (f'"{{\\"x\\": [0, 0, 0, 0], \\"iterations\\": {BIG}}}"', "an integer of 400 digits"),
    (f'"{{\\"x\\": [0, 0, 0, 0], \\"solve_time_s\\": -{BIG}}}"', "an integer of 400 digits"),
    ('"{\\"x\\": [[1], [1, 2], 0, 0]}"', '"x" must be a list of 4 numbers: element 0 is list'),
    ('"{\\"x\\": [0, 0, 0, 0], \\"iterations\\": 1e300}"', '"iterations" must be an integer >= 0'),
    ('"\\xff\\xfe"', "cannot read the program's output file"),
], ids=["nested list", "nested x", "x digits", "iterations digits", "time digits", "x ragged",
        "iterations 1e300", "not utf-8"])
def test_a_hostile_answer_is_an_error_row_naming_it(writer, text_expr, fragment):
    res = run_external(_job(_spec(writer, text_expr)), timeout=30)
    assert res["status"] == "error" and res["x"] is None and res["samples_ns"] == [], res
    assert fragment in res["reason"], res["reason"]


@pytest.mark.parametrize("make_out, fragment", [
    ("mkfifo {out}", "it is a FIFO: expected a regular file"),
    ("ln -s /dev/zero {out}", "it is a character device: expected a regular file"),
    ("mkdir {out}", "it is a directory: expected a regular file"),
], ids=["fifo", "dev zero", "directory"])
def test_an_answer_path_that_is_no_regular_file_is_refused_at_once(make_out, fragment):
    t0 = time.monotonic()
    res = run_external(_job(f"external:p=sh -c '{make_out}'"), timeout=20)
    assert time.monotonic() - t0 < 10
    assert res["status"] == "error" and fragment in res["reason"], res["reason"]


def test_a_run_with_hostile_answers_writes_their_rows_and_resumes(writer, tmp_path, capsys):
    """Deep nesting broke json's recursion and 400 digits the float conversion in the
    run's own process: the run and every resume died with a traceback."""
    suite = write_suite(tmp_path / "s.toml", ["yardstick"], grid={"n": [4], "depth": [1]}, repeat=1,
                        timeout=10.0, modes=("cold",))
    deep = _spec(writer, '"[" * 100000 + "]" * 100000').replace("external:p=", "external:deep=")
    digits = _spec(writer, f'"{{\\"x\\": [{BIG}, 0, 0, 0]}}"').replace("external:p=", "external:digits=")
    argv = ["run", "--quiet", "--suite", suite, "--out", tmp_path / "o", "--solvers", "yardstick", deep, digits]
    for _ in range(2):  # the run, then a resume that finds every row finished
        code, _, err = run(capsys, *argv)
        assert code == 0 and "Traceback" not in err, err
    df = read_results(tmp_path / "o").set_index("solver")
    assert len(df) == 3
    assert df.loc["external:deep", "status"] == "error" and "nested" in df.loc["external:deep", "reason"]
    assert df.loc["external:digits", "status"] == "error" and "400 digits" in df.loc["external:digits", "reason"]
    assert df.loc["external:deep", "worker"] != f"{os.getpid()}@{df.loc['external:deep', 'host']}"


@pytest.mark.parametrize("cmd, fragments", [
    ("sh -c 'echo {out}", ["cannot be split like a shell command line", "No closing quotation",
                           "expected its quotes closed"]),
    ("prog {problm} {out}", ["unknown placeholder {problm} (did you mean {problem}?)",
                             "expected {problem}, {problem_soth}, {out}"]),
    ("hikbench-no-such-program {problem} {out}", ["program 'hikbench-no-such-program' is not found on PATH"]),
    ("./no/such/prog {problem} {out}", ["program './no/such/prog' does not exist"]),
], ids=["unbalanced quote", "misspelt placeholder", "not on PATH", "no such path"])
def test_a_command_that_cannot_run_is_one_line_before_the_first_job(tmp_path, capsys, cmd, fragments):
    if "placeholder" in fragments[0]:
        cmd = f"{sys.executable} {cmd.split(' ', 1)[1]}"
    suite = write_suite(tmp_path / "s.toml", ["yardstick"], grid={"n": [4]}, repeat=1, modes=("cold",))
    code, _, err = run(capsys, "run", "--quiet", "--suite", suite, "--out", tmp_path / "o",
                       "--solvers", f"external:p={cmd}")
    assert_user_error(code, err, *fragments)
    assert not (tmp_path / "o" / "results.csv").exists()


@pytest.mark.parametrize("cmd", [
    "sh -c 'echo ${HOME} > /dev/null; printf \"{\\\"x\\\": [0, 0, 0, 0]}\" > {out}'",
    f"{sys.executable} -c 'import sys; open(sys.argv[1], \"w\").write(\"{{\\\"x\\\": [0, 0, 0, 0]}}\")' {{out}}",
], ids=["shell variable in braces", "json in braces"])
def test_braces_that_are_no_placeholder_are_left_alone(cmd):
    parse_spec(f"external:p={cmd}")
    res = run_external(_job(f"external:p={cmd}"), timeout=30)
    assert res["status"] == "optimal", res
