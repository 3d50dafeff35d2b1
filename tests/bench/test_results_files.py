"""A run directory's results.csv and run.json (hikbench.bench.harness.results, docs/running.md
"Resuming"): what a kill leaves (a header cut off, a row half-written, a row written twice by a
re-run) is mended or skipped when read; what a person leaves (two files concatenated, a word in
a number column, a damaged run.json, a results.csv of another tool) is a one-line error of
``report``, ``compare`` and ``run``, never a traceback."""

import csv

import pytest
from doubles import spec, verified_run, write_suite

from hikbench.bench.cli import main
from hikbench.bench.harness.results import compact, read_results

SLEEP = spec("SleepSolver")


def _run(*argv):
    return main(["run", "--quiet", *map(str, argv)])


def test_rows_left_twice_by_a_killed_rerun_resolve_to_the_new_row(tmp_path):
    suite = write_suite(tmp_path / "s.toml", [SLEEP], modes=("cold",))
    out = tmp_path / "out"
    assert _run("--suite", suite, "--out", out) == 0
    path = out / "results.csv"
    lines = path.read_text().splitlines(keepends=True)
    newer = lines[1].replace(lines[1].rsplit(",", 1)[1].strip(), "2099-01-01T00:00:00Z")
    path.write_text("".join(lines) + newer)  # what a kill between append and compaction leaves
    df = read_results(out)
    assert len(df) == 4 and "2099-01-01T00:00:00Z" in set(df["finished_at"])
    assert compact(out) == 1
    assert compact(out) == 0
    assert len(path.read_text().splitlines()) == 5
    assert "2099-01-01T00:00:00Z" in path.read_text()


@pytest.fixture(scope="module")
def two_runs_concatenated(tmp_path_factory):
    """A results.csv made by `cat a/results.csv b/results.csv`: header, rows, header, rows."""
    d = tmp_path_factory.mktemp("cat")
    suite = write_suite(d / "s.toml", [SLEEP], modes=("cold",), repeat=1)
    assert _run("--suite", suite, "--out", d / "a") == 0
    text = (d / "a" / "results.csv").read_text()
    (d / "a" / "run.json").rename(d / "run.json")
    (d / "a" / "results.csv").write_text(text + text)
    (d / "run.json").rename(d / "a" / "run.json")
    return d / "a", suite


@pytest.mark.parametrize("command", ["report", "compare", "run"])
def test_a_second_header_line_is_a_one_line_error(capsys, two_runs_concatenated, command):
    out, suite = two_runs_concatenated
    rows = len((out / "results.csv").read_text().splitlines())
    argv = {"report": ["report", out], "compare": ["compare", out, out],
            "run": ["run", "--quiet", "--suite", suite, "--out", out]}[command]
    assert main([str(a) for a in argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"hikbench {command}: error: "), err
    assert "second header line (two files concatenated?)" in err[0], err
    assert len((out / "results.csv").read_text().splitlines()) == rows  # nothing appended


def test_a_word_in_a_number_column_is_a_one_line_error(tmp_path, capsys):
    suite = write_suite(tmp_path / "s.toml", [SLEEP], modes=("cold",), repeat=1)
    assert _run("--suite", suite, "--out", tmp_path / "a") == 0
    df = read_results(tmp_path / "a")
    path = tmp_path / "a" / "results.csv"
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    col = rows[0].index("time_median_s")
    assert float(rows[2][col]) == df["time_median_s"].iloc[1]
    rows[2][col] = "fast"
    with open(path, "w", newline="") as f:
        csv.writer(f).writerows(rows)
    assert main(["report", str(tmp_path / "a")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"hikbench report: error: {path}: data row 2: column 'time_median_s' holds 'fast', not a number"]


def test_a_header_cut_off_by_a_kill_is_written_again(tmp_path):
    """A run killed while writing the header leaves a partial line: the next writer writes the
    header again (cut off and followed by rows alone, the first row would read as the header)."""
    from hikbench.bench.harness.columns import names
    from hikbench.bench.harness.results import RESULTS, ResultsWriter, read_results

    out = tmp_path / "out"
    out.mkdir()
    (out / RESULTS).write_text(",".join(names())[:25])  # no newline: the header was not finished
    with ResultsWriter(out) as w:
        w.write({"problem": "p0", "solver": "s", "settings": "default", "mode": "cold", "status": "optimal"})
    df = read_results(out)
    assert list(df.columns) == names() and list(df["problem"]) == ["p0"]


def test_a_row_still_being_written_is_not_read(tmp_path):
    """report / claims on a run in progress skip its half-written last row (read as a row, its
    status, mode and verified would be NaN, charged as a failure in the report)."""
    from hikbench.bench.harness.results import RESULTS, read_results

    out = tmp_path / "out"
    verified_run(out, ["p0", "p1"])
    path = out / RESULTS
    text = path.read_text()
    path.write_text(text[:text.rstrip("\n").rfind("\n") + 12])  # the second row cut after 11 characters
    df = read_results(out)
    assert list(df["problem"]) == ["p0"] and list(df["status"]) == ["optimal"]


@pytest.mark.parametrize("text, message", [('{"suite": ', "not valid JSON"), ("[1, 2]", "got a list")],
                         ids=["truncated", "not-an-object"])
def test_a_damaged_run_json_is_a_one_line_error(tmp_path, capsys, text, message):
    """A truncated or hand-damaged run.json is a one-line error of compare, not a JSONDecodeError
    traceback."""
    from clitools import assert_user_error, run

    base = verified_run(tmp_path / "base", ["p0"])
    new = verified_run(tmp_path / "new", ["p0"])
    (tmp_path / "new" / "run.json").write_text(text)
    code, _, err = run(capsys, "compare", base, new)
    assert_user_error(code, err, f"{new}/run.json", message, "expected")


@pytest.mark.parametrize("content, message", [
    (b"problem,solver,settings,mode,status\np,s,default,cold,optimal\n", "columns differ from this version's"),
    (b"\xff\xfe\x00\x01", "not a text file"),
    (b"", "no case (problem, solver, settings, mode) in common"),  # no header: no rows
], ids=["other-columns", "binary", "empty"])
def test_compare_on_a_foreign_or_damaged_results_csv_is_a_one_line_error(tmp_path, capsys, content, message):
    """read_results checks a results.csv before trusting it: a file of other columns, a binary
    one or an empty one is a one-line error, not a KeyError, UnicodeDecodeError or EmptyDataError
    traceback."""
    from clitools import assert_user_error, run

    base = tmp_path / "base"
    base.mkdir()
    (base / "results.csv").write_bytes(content)
    new = verified_run(tmp_path / "new", ["p0"])
    code, _, err = run(capsys, "compare", base, new)
    assert_user_error(code, err, str(base), message)


@pytest.mark.parametrize("new", [["solver_settings"],
                                 ["solver_settings", "level_gaps", "verified_high", "verified_default",
                                  "verified_low"]], ids=["without-solver-settings", "without-verdicts"])
def test_a_run_of_an_earlier_version_is_reported_with_its_new_columns_empty_and_never_resumed(tmp_path, capsys,
                                                                                              new):
    """An earlier version's results.csv (without the solver's resolved settings, or also without
    the per-profile verdicts and level gaps) is read by ``report`` and ``compare`` with those
    columns empty; ``run`` refuses to append to it (one line: a new --out)."""
    suite = write_suite(tmp_path / "s.toml", [SLEEP], modes=("cold",))
    out = tmp_path / "out"
    assert _run("--suite", suite, "--out", out) == 0
    path = out / "results.csv"
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    kept = [c for c in rows[0] if c not in new]
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=kept, extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    df = read_results(out)
    assert len(df) == len(rows) and (df["solver_settings"] == "").all()
    if "level_gaps" in new:
        assert (df["level_gaps"] == "").all() and df[new[2:]].isna().all().all()
    assert list(df["verified"]) == [r["verified"] == "True" for r in rows]
    assert main(["report", str(out)]) == 0
    capsys.readouterr()
    assert _run("--suite", suite, "--out", out, "--rerun") == 2
    assert "its columns differ from this version's" in capsys.readouterr().err


def test_each_row_holds_the_settings_the_solver_ran_with(tmp_path):
    """Column solver_settings: a cascade's settings with its swept defaults resolved (the row of
    ``hikbench list solvers --settings`` at its accuracy), an option given by the suite in
    place of its default; a solver reporting none leaves it empty."""
    import json

    import tomli_w

    from hikbench.solvers import _qp_backends as tables

    suite = tmp_path / "s.toml"
    suite.write_bytes(tomli_w.dumps({
        "repeat": 1, "warmup": 0, "timeout": 30.0, "modes": ["cold"], "solvers": ["cascade-daqp", SLEEP],
        "problems": [{"family": "equality", "params": {"n": 6, "depth": 2, "rows": 2}, "seeds": [0]}],
        "settings": [{"solver": "cascade-daqp", "name": "shift", "options": {"freeze": "shift"}}]}).encode())
    out = tmp_path / "out"
    assert _run("--suite", suite, "--out", out) == 0
    df = read_results(out)
    got = {(r.solver, r.settings): json.loads(r.solver_settings) if r.solver_settings else None
           for r in df.itertuples()}
    chosen = tables.SETTINGS["daqp"]["high"]
    default = got[("cascade-daqp", "default")]
    assert {k: default[k] for k in chosen} == chosen
    assert default["backend"] == "daqp" and default["accuracy"] == "high"
    assert got[("cascade-daqp", "shift")] == {**default, "freeze": "shift"}
    assert [v for (solver, _), v in got.items() if solver != "cascade-daqp"] == [None]
