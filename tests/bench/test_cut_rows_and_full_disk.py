"""results.csv is written so that a row cut anywhere is detected (one line a
row; a cut inside a quoted multi-line field of an earlier version's file
too), a damaged row is one line naming it, and a full disk stops the run
with one line, nothing half-written, the finished rows kept
(bench/harness/results.py, environment.py, runner.py)."""

import csv
import errno
import io
import os
import resource
import signal
import subprocess
import sys

import pytest
from clitools import ROOT, run
from doubles import spec, write_suite

from hikbench.bench.harness import environment, results
from hikbench.bench.harness.columns import KEY, names
from hikbench.bench.harness.results import ResultsWriter, finished_keys, read_results
from hikbench.problems.errors import HikbenchError

SLEEP = spec("SleepSolver")


def _row(i: int, reason: str) -> dict:
    row = dict.fromkeys(names(), "")
    row.update(problem=f"p{i}", solver="s", settings="default", mode="cold", status="optimal", reason=reason)
    return row


def test_a_reason_with_line_breaks_is_written_on_one_line(tmp_path):
    with ResultsWriter(tmp_path) as w:
        w.write(_row(0, "first\nsecond\r\nthird\rfourth"))
        w.write(_row(1, "plain"))
    assert len((tmp_path / "results.csv").read_bytes().splitlines()) == 3
    assert list(read_results(tmp_path)["reason"]) == ["first\\nsecond\\nthird\\nfourth", "plain"]


@pytest.fixture(scope="module")
def multi_line_file(tmp_path_factory):
    """A results.csv as earlier versions wrote it: reasons holding raw line breaks inside quotes,
    and the byte offset where each row ends."""
    buf = io.StringIO(newline="")
    w = csv.DictWriter(buf, fieldnames=names())
    w.writeheader()
    ends = []
    for i, reason in enumerate(["one\ntwo", "", "a \"quoted\" word\nand, a comma\n", "last\nline"]):
        w.writerow(_row(i, reason))
        ends.append(len(buf.getvalue().encode()))
    return buf.getvalue().encode(), ends


def test_no_cut_of_a_file_with_multi_line_fields_counts_its_cut_row_as_finished(tmp_path, multi_line_file):
    """Every cut position: the finished keys are exactly the rows wholly before the cut (a
    cut just after a line break inside a quoted reason counted that row as finished)."""
    data, ends = multi_line_file
    path = tmp_path / "results.csv"
    for cut in range(ends[0] - 10, len(data) + 1):
        path.write_bytes(data[:cut])
        want = {(f"p{i}", "s", "default", "cold") for i, end in enumerate(ends) if end <= cut}
        assert finished_keys(tmp_path) == want, cut
        if cut % 23 == 0 or cut in ends:
            assert set(read_results(tmp_path)["problem"]) == {k[0] for k in want}, cut


def test_a_run_resumes_a_row_cut_inside_a_multi_line_reason(tmp_path, capsys):
    suite = write_suite(tmp_path / "s.toml", [SLEEP], modes=("cold",), repeat=1)
    out = tmp_path / "o"
    assert run(capsys, "run", "--quiet", "--suite", suite, "--out", out)[0] == 0
    path = out / "results.csv"
    header, *rows = list(csv.reader(io.StringIO(path.read_text(), newline="")))
    rows[-1][header.index("reason")] = "a reason\nover two lines"
    buf = io.StringIO(newline="")
    csv.writer(buf).writerows([header, *rows])
    text = buf.getvalue()
    path.write_text(text[: text.index("a reason\n") + len("a reason\n")], newline="")  # cut after the break
    code, _, err = run(capsys, "run", "--quiet", "--suite", suite, "--out", out)
    assert code == 0 and "Traceback" not in err, err
    df = read_results(out)
    assert len(df) == len(rows) and (df["reason"] == "").all()
    assert run(capsys, "report", out)[0] == 0


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory):
    d = tmp_path_factory.mktemp("finished")
    suite = write_suite(d / "s.toml", [SLEEP], modes=("cold",), repeat=1)
    from hikbench.bench.cli import main
    assert main(["run", "--quiet", "--suite", str(suite), "--out", str(d / "o")]) == 0
    return d / "o", suite, (d / "o" / "results.csv").read_text()


def _damage(text: str, how: str) -> str:
    lines = text.splitlines(keepends=True)
    if how == "extra field":
        lines[2] = lines[2].rstrip("\r\n") + ",surplus\r\n"
    elif how == "short row":
        buf = io.StringIO(newline="")
        csv.writer(buf).writerow(next(csv.reader([lines[2]]))[:5])
        lines[2] = buf.getvalue()
    elif how == "broken quote":
        lines[1] = lines[1].replace(",cold,", ',"cold,', 1)
    return "".join(lines)


@pytest.mark.parametrize("how, says", [
    ("extra field", "line 3 holds {w1} fields, expected {w}: a damaged row"),
    ("short row", "line 3 holds 5 fields, expected {w}: a damaged row"),
    ("broken quote", "line 2 opens a quoted field that is never closed"),
], ids=["extra field", "short row", "broken quote"])
@pytest.mark.parametrize("command", ["report", "compare", "run"])
def test_a_damaged_row_is_one_line_naming_it(tmp_path, capsys, finished_run, how, says, command):
    out, suite, text = finished_run
    damaged = tmp_path / "o"
    damaged.mkdir()
    (damaged / "run.json").write_bytes((out / "run.json").read_bytes())
    (damaged / "results.csv").write_text(_damage(text, how), newline="")
    argv = {"report": ["report", damaged], "compare": ["compare", out, damaged],
            "run": ["run", "--quiet", "--suite", suite, "--out", damaged]}[command]
    code, _, err = run(capsys, *argv)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert says.format(w=len(names()), w1=len(names()) + 1) in err, err
    assert str(damaged / "results.csv") in err


class _FullDisk:
    """``os`` as seen by one module, its ``write`` (or ``fsync``) failing with ENOSPC after
    ``room`` bytes, as a full disk does (a short write first, then the error)."""

    def __init__(self, room: int, call: str = "write"):
        self.room, self.call = room, call

    def __getattr__(self, name):
        if name == self.call == "write":
            return self._write
        if name == self.call == "fsync":
            return self._fail
        return getattr(os, name)

    def _write(self, fd, data):
        if self.room <= 0:
            self._fail()
        n = os.write(fd, bytes(data[: self.room]))
        self.room -= n
        return n

    @staticmethod
    def _fail(*args):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


def test_a_row_that_finds_the_disk_full_is_cut_off_again(tmp_path, monkeypatch):
    with ResultsWriter(tmp_path) as w:
        w.write(_row(0, "kept"))
        before = (tmp_path / "results.csv").read_bytes()
        monkeypatch.setattr(results, "os", _FullDisk(room=40))
        with pytest.raises(HikbenchError, match=r"results.csv: cannot write a row \(No space left on device\); "
                                                 r"the rows finished before it are kept"):
            w.write(_row(1, "lost"))
    assert (tmp_path / "results.csv").read_bytes() == before


def test_run_json_that_finds_the_disk_full_leaves_no_temporary_file(tmp_path, monkeypatch):
    environment.write_run_json(tmp_path, {"created": "then"})
    monkeypatch.setattr(environment, "os", _FullDisk(room=0, call="fsync"))
    with pytest.raises(HikbenchError, match=r"run.json: cannot write it \(No space left on device\); the "
                                             r"previous run.json is left as it was"):
        environment.write_run_json(tmp_path, {"created": "now"})
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.json"]
    assert environment.read_run_json(tmp_path) == {"created": "then"}


def _limited(limit: int):
    def start():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # (a write past the limit fails with EFBIG instead)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    return start


@pytest.mark.skipif(not hasattr(signal, "SIGXFSZ"), reason="needs RLIMIT_FSIZE (POSIX)")
def test_a_run_that_runs_out_of_space_stops_with_one_line_and_resumes(tmp_path):
    """The run's files may not grow past a size between its run.json's and its whole
    results.csv's (both measured on a run of the same suite without a limit: run.json records
    this machine's environment): the row that finds no room is the run's one error line,
    nothing is left half-written, and the same command then finishes the rest."""
    suite = write_suite(tmp_path / "s.toml", [SLEEP], grid={"n": [4, 6, 8], "depth": [1, 2, 3]},
                        seeds=(0, 1, 2), repeat=1)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.path.dirname(__file__)])}

    def argv(out):
        return [sys.executable, "-m", "hikbench", "run", "--quiet", "--suite", str(suite), "--out", str(out)]

    probe = tmp_path / "p"  # (a name as long as the limited run's: run.json records the paths)
    assert subprocess.run(argv(probe), env=env, cwd=tmp_path, capture_output=True, timeout=300).returncode == 0
    run_json, csv = (probe / "run.json").stat().st_size, (probe / "results.csv").stat().st_size
    assert run_json + 2000 < csv, (run_json, csv)
    limit, rows = (run_json + csv) // 2, len(read_results(probe))
    out = tmp_path / "o"
    p = subprocess.run(argv(out), env=env, cwd=tmp_path, capture_output=True, text=True, timeout=300,
                       preexec_fn=_limited(limit))
    assert p.returncode == 2, p.stderr
    assert p.stderr.strip().splitlines() == [p.stderr.strip()], p.stderr
    assert "results.csv: cannot write a row (File too large); the rows finished before it are kept" in p.stderr
    data = (out / "results.csv").read_bytes()
    assert data.endswith(b"\n") and len(data) <= limit
    kept = len(read_results(out))
    assert 0 < kept < rows
    assert not (out / "run.json.tmp").exists() and environment.read_run_json(out)["sessions"]
    p = subprocess.run(argv(out), env=env, cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    df = read_results(out)
    assert len(df) == rows and len(df.drop_duplicates(list(KEY))) == rows


def test_a_scenario_row_that_finds_the_disk_full_leaves_scenarios_csv_whole(tmp_path, monkeypatch):
    import pandas as pd

    from hikbench.bench.scenarios import rows as scenario_rows

    row = {k: f"v{i}" for i, k in enumerate(scenario_rows.names())}
    scenario_rows.write_scenario_row(tmp_path, row)
    before = (tmp_path / "scenarios.csv").read_bytes()

    def full(self, path, **kw):
        with open(path, "w") as f:
            f.write("partial,")
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(pd.DataFrame, "to_csv", full)
    with pytest.raises(HikbenchError, match=r"scenarios.csv: cannot write a row \(No space left on device\)"):
        scenario_rows.write_scenario_row(tmp_path, {**row, scenario_rows.KEY[0]: "other"})
    assert (tmp_path / "scenarios.csv").read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scenarios.csv"]
