"""``hikbench run --rounds``: a row's repetitions split over rounds, each round
running every job once; a harness failure ends a job's rounds."""

import json

import pandas as pd
import pytest
from doubles import spec, write_suite

from hikbench.bench.cli import main
from hikbench.bench.harness.columns import KEY
from hikbench.bench.harness.results import read_results
from hikbench.bench.harness.runner import _merge_rounds


def _run(*argv):
    return main(["run", "--quiet", *map(str, argv)])


def test_rounds_interleave_the_jobs_and_pool_their_samples(tmp_path, monkeypatch):
    log = tmp_path / "solves.log"
    monkeypatch.setenv("HIKBENCH_TEST_LOG", str(log))
    suite = write_suite(tmp_path / "s.toml", [spec("LogSolver")], grid={"n": [4, 6]}, modes=("cold",), repeat=5)
    assert _run("--suite", suite, "--out", tmp_path / "out", "--rounds", "2") == 0
    df = read_results(tmp_path / "out")
    assert len(df) == 2
    for _, row in df.iterrows():
        assert row["status"] == "optimal" and row["verified"]
        assert row["repeat"] == 5 and len(json.loads(row["samples_ns"])) == 5
    # per job and round: one untimed first solve, the warm-up solve, then its share of the
    # repetitions: 3 then 2. Round 1 runs both problems, then round 2 both again.
    ns = [int(line.split()[1]) for line in log.read_text().splitlines()]
    first, second = ns[:10], ns[10:]
    assert len(ns) == 10 + 8
    assert sorted(set(first)) == [4, 6] and first[:5] == [first[0]] * 5 and first[5:] == [first[5]] * 5
    assert second == [first[0]] * 4 + [first[5]] * 4
    session = json.loads((tmp_path / "out" / "run.json").read_text())["sessions"][-1]
    assert session["rounds"] == 2 and session["repeat"] == 5


@pytest.mark.parametrize("executor", [[], ["--workers", "1"]], ids=["serial", "dask"])
def test_each_round_solves_in_fresh_worker_processes(tmp_path, monkeypatch, executor):
    """A process's memory layout holds a solve's speed for its life: round r of a job runs in
    another process than round r-1, so a row's samples come from as many layouts as rounds."""
    log = tmp_path / "solves.log"
    monkeypatch.setenv("HIKBENCH_TEST_LOG", str(log))
    suite = write_suite(tmp_path / "s.toml", [spec("PidLogSolver")], grid={"n": [4, 6]}, modes=("cold",), repeat=3)
    assert _run("--suite", suite, "--out", tmp_path / "out", "--rounds", "3", *executor) == 0
    lines = [line.split() for line in log.read_text().splitlines()]
    # per job and round: the first solve, the warm-up and one timed solve; the jobs in suite order
    pids = [[int(pid) for _, n, pid in lines[r * 6:(r + 1) * 6]] for r in range(3)]
    assert len(lines) == 3 * 6 and all(len(set(p)) == 1 for p in pids)
    assert len({p[0] for p in pids}) == 3
    assert all(row["repeat"] == 3 for _, row in read_results(tmp_path / "out").iterrows())


def test_a_crash_ends_the_rounds_of_its_job_only(tmp_path, monkeypatch):
    log = tmp_path / "solves.log"
    monkeypatch.setenv("HIKBENCH_TEST_LOG", str(log))
    suite = write_suite(tmp_path / "s.toml", [spec("LogSegfaultSolver"), spec("LogSolver")], grid={"n": [4]},
                        modes=("cold",), repeat=3)
    assert _run("--suite", suite, "--out", tmp_path / "out", "--rounds", "3") == 0
    df = read_results(tmp_path / "out").set_index("solver")
    assert df.loc["log-segfault", "status"] == "crashed"
    assert df.loc["log-segfault", "reason"].endswith("(in round 1 of 3)")
    assert df.loc["log", "status"] == "optimal" and df.loc["log", "repeat"] == 3
    lines = log.read_text().splitlines()
    assert lines.count("log-segfault 4") == 1  # not run again in rounds 2 and 3
    assert lines.count("log 4") == 3 * 3  # per round: the first solve, the warm-up and one timed solve


def test_a_timeout_in_a_later_round_is_the_row(tmp_path, monkeypatch):
    log = tmp_path / "solves.log"
    monkeypatch.setenv("HIKBENCH_TEST_LOG", str(log))
    suite = write_suite(tmp_path / "s.toml", [spec("LogHangLaterSolver"), spec("LogSolver")], grid={"n": [4]},
                        modes=("cold",), repeat=3, timeout=1.5)
    # not --quiet: the progress bar counts each job's rounds (a row written early advances by the rest)
    assert main(["run", "--suite", str(suite), "--out", str(tmp_path / "out"), "--rounds", "3"]) == 0
    df = read_results(tmp_path / "out").set_index("solver")
    assert df.loc["log-hang-later", "status"] == "timeout"
    assert df.loc["log-hang-later", "reason"].endswith("(in round 2 of 3; the earlier rounds ended optimal)")
    assert df.loc["log-hang-later", "repeat"] == 0  # (a timeout row has no timing, as without rounds)
    assert df.loc["log", "status"] == "optimal" and df.loc["log", "repeat"] == 3
    assert log.read_text().splitlines().count("log-hang-later 4") == 3 + 1  # round 3 did not run it


def _res(status="optimal", samples=(10, 20), wall=1.0, reason="", **kw):
    return {"status": status, "reason": reason, "x": None, "samples_ns": list(samples), "wall_s": wall, **kw}


@pytest.mark.parametrize("earlier, last, expected", [
    ([], _res(), _res()),
    ([_res(samples=(5,))], _res(samples=(7, 9), wall=2.0), _res(samples=(5, 7, 9), wall=3.0)),
    ([_res(), _res(status="max_iterations")], _res(samples=(1,)),
     _res(samples=(10, 20, 10, 20, 1), wall=3.0,
          reason="statuses differ across the rounds: optimal, max_iterations, optimal")),
    ([_res(), _res()], _res(status="timeout", samples=(), reason="killed after 5 s"),
     _res(status="timeout", samples=(), reason="killed after 5 s (in round 3 of 3; the earlier rounds ended "
                                               "optimal, optimal)")),
    ([], _res(status="error", samples=(), reason="boom"), _res(status="error", samples=(),
                                                               reason="boom (in round 1 of 3)")),
    ([_res(status="error", reason="qp failed")], _res(status="error", reason="qp failed"),
     _res(status="error", samples=(10, 20, 10, 20), wall=2.0, reason="qp failed")),
    ([_res(calib_ns=100, host="a"), _res(calib_ns=300, host="a")], _res(calib_ns=110, host="a", wall=None),
     _res(samples=(10, 20) * 3, wall=None, calib_ns=110, host="a")),
    ([_res(host="a"), _res(host="b")], _res(host="a"),
     _res(samples=(10, 20) * 3, wall=3.0, host="a", reason="rounds ran on hosts a, b (calib_ns: their median)")),
], ids=["one-round", "samples-pooled", "statuses-differ", "timeout-in-round-3", "error-in-round-1",
        "solver-reported-error-goes-on", "calib-median-wall-unknown", "hosts-differ"])
def test_merge_rounds(earlier, last, expected):
    assert _merge_rounds(earlier, last, 3) == expected


def test_a_suites_rounds_are_lowered_to_a_smaller_repeat(tmp_path, capsys):
    suite = write_suite(tmp_path / "s.toml", [spec("SleepSolver")], grid={"n": [4]}, modes=("cold",), repeat=5)
    suite.write_text("rounds = 4\n" + suite.read_text())
    assert _run("--suite", suite, "--out", tmp_path / "out", "--repeat", "2") == 0
    assert "the suite's rounds = 4 lowered to repeat = 2" in capsys.readouterr().err
    session = json.loads((tmp_path / "out" / "run.json").read_text())["sessions"][-1]
    assert session["rounds"] == 2
    assert read_results(tmp_path / "out")["repeat"].tolist() == [2]


# --- rounds with the other run options, end to end -------------------------------------------------


def _pooled(df):
    """Every row optimal, verified, with all 4 repetitions of its 2 rounds."""
    assert (df["status"] == "optimal").all() and df["verified"].all()
    assert (df["repeat"] == 4).all()
    assert df["samples_ns"].map(lambda s: len(json.loads(s))).eq(4).all()


def test_rounds_with_limit_then_resume(tmp_path):
    """--limit counts rows (each pooled over its rounds); the resumed run adds the rest once."""
    suite = write_suite(tmp_path / "s.toml", [spec("SleepSolver")], modes=("cold",), repeat=4)
    out = tmp_path / "out"
    assert _run("--suite", suite, "--out", out, "--rounds", 2, "--limit", 3) == 0
    first = (out / "results.csv").read_text()
    assert len(read_results(out)) == 3
    assert _run("--suite", suite, "--out", out, "--rounds", 2) == 0
    df = read_results(out)
    assert len(df) == 4 and not df.duplicated(list(KEY)).any()
    assert (out / "results.csv").read_text().startswith(first)  # finished rows never rewritten
    _pooled(df)
    sessions = json.loads((out / "run.json").read_text())["sessions"]
    assert [(s["todo"], s["written"], s["rounds"]) for s in sessions] == [(3, 3, 2), (1, 1, 2)]


def test_rerun_in_rounds_replaces_each_row_once(tmp_path):
    suite = write_suite(tmp_path / "s.toml", [spec("SleepSolver")], modes=("cold",), repeat=4)
    out = tmp_path / "out"
    assert _run("--suite", suite, "--out", out) == 0
    assert _run("--suite", suite, "--out", out, "--rerun", "--rounds", 2) == 0
    df = read_results(out)
    assert len(df) == 4 and not df.duplicated(list(KEY)).any()
    _pooled(df)
    assert len((out / "results.csv.bak").read_text().splitlines()) == 5  # the one-round rows kept


def test_rounds_on_dask_workers_give_the_rows_of_a_serial_run(tmp_path):
    suite = write_suite(tmp_path / "s.toml", ["yardstick", spec("SleepSolver"), spec("SegfaultSolver")],
                        modes=("cold",), repeat=4, timeout=60.0)  # (2 workers on 2 cores: not about timeouts)
    assert _run("--suite", suite, "--out", tmp_path / "serial", "--rounds", 2) == 0
    assert _run("--suite", suite, "--out", tmp_path / "dask", "--rounds", 2, "--workers", 2) == 0
    cols = [*KEY, "status", "verified", "repeat", "reason"]
    a, b = (read_results(tmp_path / d)[cols].sort_values(list(KEY)).reset_index(drop=True)
            for d in ("serial", "dask"))
    pd.testing.assert_frame_equal(a, b)
    assert set(b["status"]) == {"optimal", "crashed"}
    assert b.loc[b["status"] == "crashed", "reason"].str.endswith("(in round 1 of 2)").all()
    assert (b.loc[b["status"] == "optimal", "repeat"] == 4).all()
