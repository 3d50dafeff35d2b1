"""hikbench run end to end on the tiny generator with test doubles: rows,
statuses, verification, isolation, resume without duplicates or losses."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest
from doubles import spec, tiny, write_suite

from hikbench.bench.cli import main
from hikbench.bench.harness.columns import KEY, names
from hikbench.bench.harness.results import finished_keys, finished_rows, read_results

ROOT = Path(__file__).resolve().parents[2]


def _run(*argv):
    return main(["run", "--quiet", *map(str, argv)])


def _keys(df):
    return list(map(tuple, df[list(KEY)].to_numpy()))


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    d = tmp_path_factory.mktemp("tiny")
    suite = write_suite(d / "s.toml", ["yardstick", spec("SleepSolver"), spec("WrongSolver"),
                                       spec("RaisingSolver"),
                                       "not-a-solver-*"])
    assert _run("--suite", suite, "--out", d / "out") == 0
    return d / "out"


def test_rows_statuses_and_verification(tiny_run):
    df = read_results(tiny_run)
    assert list(df.columns) == names()
    # 4 problems x (reference cold, sleep cold+warm, wrong cold, raising cold)
    assert len(df) == 4 * 5
    assert len(set(_keys(df))) == len(df)
    by = df.groupby("solver")
    assert set(by.get_group("yardstick")["verified"]) == {True}
    assert set(by.get_group("sleep")["verified"]) == {True}
    assert set(by.get_group("sleep")["mode"]) == {"cold", "warm"}
    wrong = by.get_group("wrong")
    assert set(wrong["status"]) == {"optimal"} and set(wrong["verified"]) == {False}
    assert set(wrong["verdict_side"]) == {"worse"} and set(wrong["verdict_level"]) == {0}
    raising = by.get_group("raising")
    assert set(raising["status"]) == {"error"}
    assert raising["reason"].str.contains("backend exploded").all()
    ok = df[df["solver"] == "sleep"].iloc[0]
    assert len(json.loads(ok["samples_ns"])) == 3 and ok["repeat"] == 3
    assert ok["time_min_s"] <= ok["time_median_s"] <= ok["time_p90_s"] <= ok["time_p99_s"] <= ok["time_max_s"]
    assert json.loads(ok["level_norms"]) == pytest.approx(json.loads(ok["ref_level_norms"]), abs=1e-9)


def test_outputs_beside_results(tiny_run):
    meta = json.loads((tiny_run / "run.json").read_text())
    assert meta["suite"]["name"] == "s"
    assert meta["calibration_ns"] > 0
    assert meta["skipped_solvers"] == {"not-a-solver-*": "pattern matches no installed solver"}
    df = read_results(tiny_run)
    assert meta["selected_solvers"] == sorted({*df["solver"], "not-a-solver-*"})  # (compare's MISSING)
    env = meta["environment"]
    assert env["versions"]["numpy"] and env["cpu"] and "threadpools" in env["blas"]
    assert len(list((tiny_run / "problems").glob("*.npz"))) == 4
    assert len(list((tiny_run / "yardstick").glob("*.npz"))) == 4


def test_second_run_skips_finished_rows(tiny_run, capsys):
    before = (tiny_run / "results.csv").read_text()
    suite = Path(tiny_run).parent / "s.toml"
    assert _run("--suite", suite, "--out", tiny_run) == 0
    assert "20 already done, 0 written" in capsys.readouterr().out
    assert (tiny_run / "results.csv").read_text() == before


def test_hang_and_segfault_become_rows(tmp_path):
    suite = write_suite(tmp_path / "s.toml", [spec("HangSolver"), spec("SegfaultSolver"),
                                              spec("SleepSolver")],
                        grid={"n": [4]}, modes=("cold",), timeout=1.5)
    assert _run("--suite", suite, "--out", tmp_path / "out") == 0
    df = read_results(tmp_path / "out").set_index("solver")
    assert df.loc["hang", "status"] == "timeout"
    assert df.loc["segfault", "status"] == "crashed"
    assert "SIGSEGV" in df.loc["segfault", "reason"]
    assert df.loc["sleep", "status"] == "optimal" and df.loc["sleep", "verified"]


def test_a_crashed_worker_leaves_no_open_pipe():
    """The crash path closes the dead worker's pipes (not left to the garbage
    collector, which warns about unclosed files)."""
    from hikbench.bench.harness.isolation import IsolatedWorker

    w = IsolatedWorker()
    try:
        w.start()
        proc = w.proc
        res = w.run({"kind": "solve", "hierarchy": tiny(), "solver": spec("SegfaultSolver"), "options": {},
                     "mode": "cold", "repeat": 1, "warmup": 1}, timeout=30)
        assert res["status"] == "crashed"
        assert w.proc is None and proc.stdin.closed and proc.stdout.closed
    finally:
        w.close()


def test_limit_then_resume_no_duplicate_no_loss(tmp_path):
    suite = write_suite(tmp_path / "s.toml", ["yardstick", spec("SleepSolver")])
    out = tmp_path / "out"
    assert _run("--suite", suite, "--out", out, "--limit", 5) == 0
    assert len(read_results(out)) == 5
    first = (out / "results.csv").read_text()
    assert _run("--suite", suite, "--out", out) == 0
    df = read_results(out)
    assert len(df) == 12 and len(set(_keys(df))) == 12
    assert (out / "results.csv").read_text().startswith(first)  # finished rows never rewritten


def test_partial_last_line_is_dropped_and_rerun(tmp_path):
    suite = write_suite(tmp_path / "s.toml", [spec("SleepSolver")], modes=("cold",))
    out = tmp_path / "out"
    assert _run("--suite", suite, "--out", out, "--limit", 2) == 0
    with open(out / "results.csv", "a") as f:
        f.write("half,a,row")  # what a kill during a write leaves
    assert len(finished_keys(out)) == 2
    assert _run("--suite", suite, "--out", out) == 0
    df = read_results(out)
    assert len(df) == 4 and len(set(_keys(df))) == 4


def test_rerun_replaces_rows_and_keeps_backup(tmp_path):
    suite = write_suite(tmp_path / "s.toml", [spec("SleepSolver")], modes=("cold",))
    out = tmp_path / "out"
    assert _run("--suite", suite, "--out", out) == 0
    assert _run("--suite", suite, "--out", out, "--rerun") == 0
    assert len(read_results(out)) == 4
    assert (out / "results.csv.bak").exists()
    assert len((out / "results.csv").read_text().splitlines()) == 5  # the old rows are gone


def test_killed_run_restarts_and_finishes(tmp_path):
    """SIGKILL a real `hikbench run` mid-way; the restarted run completes the
    suite with every key exactly once."""
    suite = write_suite(tmp_path / "s.toml", [spec("SleepSolver")], grid={"n": [4, 5, 6, 7, 8, 9]},
                        modes=("cold",))
    # make each solve slow enough to kill in the middle
    text = suite.read_text() + '\n[[settings]]\nsolver = "sleep"\nname = "slow"\noptions = { delay = 0.05 }\n'
    suite.write_text(text)
    out = tmp_path / "out"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), str(Path(__file__).parent)])}
    proc = subprocess.Popen([sys.executable, "-m", "hikbench", "run", "--quiet", "--suite", str(suite), "--out",
                             str(out)],
                            env=env, cwd=tmp_path, start_new_session=True)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        if len(finished_keys(out)) >= 3:
            break
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    done_before = len(finished_keys(out))
    assert 3 <= done_before < 12
    assert _run("--suite", suite, "--out", out) == 0
    df = read_results(out)
    assert len(df) == 12 and len(set(_keys(df))) == 12
    assert set(df["status"]) == {"optimal"}


def test_unknown_suite_is_a_user_error(tmp_path, capsys):
    assert _run("--suite", "no-such-suite", "--out", tmp_path) == 2
    assert "unknown suite" in capsys.readouterr().err


def test_columns_command_documents_every_column(capsys):
    assert main(["columns"]) == 0
    out = capsys.readouterr().out
    for c in names():
        assert c in out


def test_first_solve_allowance(tmp_path):
    """A solver whose first solve in a process is slow (JIT) gets the
    first-solve allowance; a hang after it gets only the job timeout."""
    from hikbench.bench.harness.isolation import IsolatedWorker

    h = tiny()
    job = {"kind": "solve", "hierarchy": h, "solver": spec("FirstSlowSolver"), "options": {}, "mode": "cold",
           "repeat": 2, "warmup": 1}
    with IsolatedWorker() as w:
        assert w.run(job, timeout=0.5, first_timeout=5.0)["status"] == "optimal"
        w.start()  # fresh process: compiles again
        assert w.run(job, timeout=0.5)["status"] == "timeout"
        hang = {**job, "solver": spec("HangSolver")}
        t0 = time.monotonic()
        res = w.run(hang, timeout=0.5, first_timeout=1.0)
        assert res["status"] == "timeout" and "first solve" in res["reason"]
        assert time.monotonic() - t0 < 4


def test_worker_dies_with_a_killed_run(tmp_path):
    """SIGKILL of the parent during a hanging solve leaves no orphan worker."""
    code = (f"import sys, time; sys.path.insert(0, {str(Path(__file__).parent)!r})\n"
            "from hikbench.bench.harness.isolation import IsolatedWorker\nfrom doubles import tiny, spec\n"
            "w = IsolatedWorker(); w.start(); print(w.proc.pid, flush=True)\n"
            "w.run({'kind': 'solve', 'hierarchy': tiny(), 'solver': spec('HangSolver'), 'options': {},"
            " 'mode': 'cold', 'repeat': 1, 'warmup': 1}, timeout=60)\n")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    with subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True, env=env) as proc:
        child = int(proc.stdout.readline())
        time.sleep(0.5)
        proc.kill()
    for _ in range(50):
        try:
            os.kill(child, 0)
        except ProcessLookupError:
            return
        time.sleep(0.1)
    os.kill(child, signal.SIGKILL)
    pytest.fail("the worker outlived its parent")


@pytest.mark.parametrize("solver", ["nullspace-svd", spec("SleepSolver")], ids=["registered", "module-class"])
def test_worker_names_an_unknown_option(solver):
    """A job's options go through registry.build for registered and module:Class
    solvers alike: an unknown name is the job's error, naming it."""
    from hikbench.bench.harness.worker import execute

    res = execute({"kind": "solve", "hierarchy": tiny(), "solver": solver, "options": {"bogus": 1},
                   "mode": "cold", "repeat": 1, "warmup": 1})
    assert res["status"] == "error"
    assert "unknown option(s) 'bogus'" in res["reason"]


@pytest.mark.parametrize("status_rc, dirty", [(0, False), (128, None)], ids=["clean", "status-failed"])
def test_git_state_unknown_when_git_status_fails(monkeypatch, status_rc, dirty):
    """run.json's git.dirty: False only when `git status` said so; None when it failed."""
    import subprocess as sp

    from hikbench.bench.harness import environment

    def fake_run(cmd, **kw):
        rc = status_rc if "status" in cmd else 0
        return sp.CompletedProcess(cmd, rc, stdout="abc123\n" if "rev-parse" in cmd else "", stderr="")

    monkeypatch.setattr(environment.subprocess, "run", fake_run)
    assert environment._git() == {"commit": "abc123", "branch": "abc123", "dirty": dirty}


# -- later runs of one --out: --rerun, changed [[settings]], a failed yardstick --------------------

SLEEP = spec("SleepSolver")


def _rows(out) -> dict:
    """key -> (wall_s, samples_ns) of the row: different at every write."""
    df = read_results(out)
    return {tuple(r[k] for k in KEY): (r["wall_s"], r["samples_ns"]) for _, r in df.iterrows()}


def test_rerun_with_limit_keeps_the_other_rows_and_every_backup(tmp_path):
    suite = write_suite(tmp_path / "s.toml", [SLEEP], modes=("cold",))  # 4 problems
    out = tmp_path / "out"
    assert _run("--suite", suite, "--out", out) == 0
    first = _rows(out)
    first_text = (out / "results.csv").read_text()
    assert len(first) == 4

    assert _run("--suite", suite, "--out", out, "--rerun", "--limit", 1) == 0
    second = _rows(out)
    assert set(second) == set(first)  # nothing lost
    changed = [k for k in first if first[k] != second[k]]
    assert len(changed) == 1  # exactly the re-run row was replaced, in place of the old one
    assert len(read_results(out)) == 4 and len(finished_rows(out)) == 4
    assert (out / "results.csv.bak").read_text() == first_text
    second_text = (out / "results.csv").read_text()

    assert _run("--suite", suite, "--out", out, "--rerun", "--limit", 2) == 0
    assert set(_rows(out)) == set(first)
    assert (out / "results.csv.bak").read_text() == first_text  # the first backup is not overwritten
    assert (out / "results.csv.bak.1").read_text() == second_text


def test_changed_settings_options_run_again_and_replace_their_rows(tmp_path, capsys):
    path = write_suite(tmp_path / "s.toml", [SLEEP], grid={"n": [4, 5]}, modes=("cold",))
    base = path.read_text()
    path.write_text(base + '\n[[settings]]\nsolver = "sleep"\nname = "slow"\noptions = { delay = 0.0 }\n')
    out = tmp_path / "out"
    assert _run("--suite", path, "--out", out) == 0
    assert len(read_results(out)) == 4
    capsys.readouterr()

    path.write_text(base + '\n[[settings]]\nsolver = "sleep"\nname = "slow"\noptions = { delay = 0.001 }\n')
    assert _run("--suite", path, "--out", out) == 0
    cap = capsys.readouterr()
    assert "4 rows in the suite, 2 already done, 2 written" in cap.out
    assert "2 finished row(s) run again: their settings' options changed" in cap.err
    df = read_results(out)
    assert len(df) == 4 and len(df.drop_duplicates(list(KEY))) == 4
    slow = df[df["settings"] == "slow"]
    assert [json.loads(o) for o in slow["options"]] == [{"delay": 0.001}] * 2
    assert len((out / "results.csv").read_text().splitlines()) == 5  # old rows gone from the file too
    assert (out / "results.csv.bak").exists()

    assert _run("--suite", path, "--out", out) == 0  # and now it resumes as usual
    assert "4 already done, 0 written" in capsys.readouterr().out


class _ReferenceCrashes:
    """An executor whose yardstick jobs (the independent point and hcod's candidate) come back
    ``crashed`` (a killed worker, a lost Dask worker); the solves run for real."""

    name = "reference-crashes"

    def __init__(self, log):
        from hikbench.bench.harness.executors import SerialExecutor

        self.inner = SerialExecutor(log=log)

    def map(self, items):
        for tag, job, timeout in items:
            if job["kind"] in ("yardstick", "candidate"):
                yield tag, {"status": "crashed", "reason": "worker process killed by signal SIGKILL",
                            "x": None, "samples_ns": []}
            else:
                yield from self.inner.map([(tag, job, timeout)])

    def close(self):
        self.inner.close()


def test_a_crashed_reference_is_computed_again_by_the_next_run(tmp_path):
    """A yardstick solution that timed out or crashed is not cached in OUT/reference/: the next
    run of that --out computes it again and verifies its rows (docs/running.md, "Resuming")."""
    from doubles import write_suite

    from hikbench.bench.harness.results import read_results
    from hikbench.bench.harness.runner import run_suite
    from hikbench.bench.suites import load_suite

    suite = load_suite(str(write_suite(tmp_path / "s.toml", [spec("SleepSolver")],
                                       grid={"n": [4], "depth": [1]})))
    out = tmp_path / "out"
    first = _ReferenceCrashes(out / "worker.log")
    try:
        run_suite(suite, out, executor=first, quiet=True, limit=1)  # the cold row; its yardstick crashed
    finally:
        first.close()
    run_suite(suite, out, quiet=True)  # the warm row
    df = read_results(out).set_index("mode")
    assert "yardstick crashed" in df.loc["cold", "reason"] and pd.isna(df.loc["cold", "verified"])
    assert df.loc["warm", "verified"] is True, df.loc["warm", "reason"]
