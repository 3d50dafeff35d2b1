"""hikbench run: user-audit defects. --rerun keeps the rows it does not re-run
and never overwrites a backup; bad suite values, bad settings options, unknown
solvers, empty suites and bad command-line values are one-line errors (exit
2) before anything runs; a changed [[settings]] runs its rows again."""

import csv
import json
import socket
import textwrap

import pytest
from doubles import spec, write_suite

from hikbench.bench.cli import main
from hikbench.bench.harness.columns import KEY
from hikbench.bench.harness.results import compact, finished_rows, read_results

SLEEP = spec("SleepSolver")
GROUP = '[[problems]]\nfamily = "equality"\ngrid = { n = [6] }\n'


def _run(*argv):
    return main(["run", "--quiet", *map(str, argv)])


def _one_error_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    errors = [line for line in err if line.startswith("hikbench run: error: ")]
    assert len(errors) == 1, err
    assert not any("Traceback" in line for line in err), err
    return errors[0]


def _rows(out) -> dict:
    """key -> (wall_s, samples_ns) of the row: different at every write."""
    df = read_results(out)
    return {tuple(r[k] for k in KEY): (r["wall_s"], r["samples_ns"]) for _, r in df.iterrows()}


# --- 1. --rerun ------------------------------------------------------------------------------------


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


# --- 2. bad suite values ---------------------------------------------------------------------------

BAD_SUITES = [
    ('repeat = "abc"\n' + GROUP, "repeat = 'abc': expected an integer >= 1"),
    ('repeat = 0\n' + GROUP, "repeat = 0: expected an integer >= 1"),
    ('repeat = true\n' + GROUP, "repeat = True: expected an integer >= 1"),
    ('timeout = "abc"\n' + GROUP, "timeout = 'abc': expected a number of seconds > 0"),
    ('timeout = 0\n' + GROUP, "timeout = 0: expected a number of seconds > 0"),
    ('timeout = -1.5\n' + GROUP, "timeout = -1.5: expected a number of seconds > 0"),
    ('first_solve_timeout = 0\n' + GROUP, "first_solve_timeout = 0: expected a number of seconds > 0"),
    ('warmup = -1\n' + GROUP, "warmup = -1: expected an integer >= 0"),
    ('modes = "cold"\n' + GROUP, "modes = 'cold': expected a non-empty list of strings"),
    ('modes = []\n' + GROUP, "modes = []: expected a non-empty list of strings"),
    ('solvers = "hcod"\n' + GROUP, "solvers = 'hcod': expected a non-empty list of strings"),
    ('export = ["pdf"]\n' + GROUP, "export 'pdf': expected 'npz' or 'soth'"),
    ('calibrate_each_job = "yes"\n' + GROUP, "calibrate_each_job = 'yes': expected true or false"),
    ('settings = 3\n' + GROUP, "settings = 3: expected [[settings]] tables"),
    ('problems = "abc"\n', "problems = 'abc': expected [[problems]] tables"),
    (GROUP + "seeds = 3\n", "problems group 0: seeds = 3: expected a non-empty list of integers"),
    (GROUP + 'seeds = "abc"\n', "problems group 0: seeds = 'abc': expected a non-empty list of integers"),
    (GROUP + "seeds = []\n", "problems group 0: seeds = []: expected a non-empty list of integers"),
    (GROUP + 'params = "abc"\n', "problems group 0: params = 'abc': expected a table"),
    (GROUP + 'solvers = "hcod"\n', "problems group 0: solvers = 'hcod': expected a non-empty list"),
    ('[[problems]]\nfamily = "equality"\ngrid = { n = [] }\n',
     "problems group 0: grid key 'n' is an empty list: expected at least one value"),
    ('[[problems]]\nfamily = 3\n', "problems group 0: family = 3: expected a non-empty string"),
    ('[[problems]]\nfamily = "equality"\ngrid = { n = ["abc"] }\n',
     "problem equality/n=abc/seed=0: n must be an integer; got 'abc'"),
    ('[[settings]]\nsolver = "hcod"\noptions = {}\n' + GROUP, "settings 0: missing key 'name'"),
    ('[[settings]]\nname = "x"\n' + GROUP, "settings 0: missing key 'solver'"),
    ('[[settings]]\nsolver = "hcod"\nname = "x"\noptions = 3\n' + GROUP,
     "settings 0: options = 3: expected a table"),
    ('[[settings]]\nsolver = "hcod"\nname = "default"\n' + GROUP, "name 'default' is reserved"),
    ('[[settings]]\nsolver = "hcod"\nname = "x"\nopts = {}\n' + GROUP, "settings 0: unknown key(s) ['opts']"),
]
BAD_SUITE_IDS = ["repeat-str", "repeat-0", "repeat-bool", "timeout-str", "timeout-0", "timeout-neg",
                 "first-timeout-0", "warmup-neg", "modes-str", "modes-empty", "solvers-str", "export",
                 "calibrate-str", "settings-int", "problems-str", "seeds-int", "seeds-str", "seeds-empty",
                 "params-str", "group-solvers-str", "grid-empty", "family-int", "param-value", "settings-no-name",
                 "settings-no-solver", "settings-options-int", "settings-default-name", "settings-key"]


@pytest.mark.parametrize("text, message", BAD_SUITES, ids=BAD_SUITE_IDS)
def test_bad_suite_values_are_one_line_errors(tmp_path, capsys, text, message):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    out = tmp_path / "out"
    assert _run("--suite", path, "--solvers", "yardstick", "--out", out) == 2
    line = _one_error_line(capsys)
    assert f"suite {path}: " in line  # names the suite file
    assert message in line
    assert not out.exists()  # nothing ran, nothing was written


# --- 3. settings options ---------------------------------------------------------------------------


@pytest.mark.parametrize("solvers, settings, message", [
    (["cascade-osqp"], {"solver": "cascade-osqp", "name": "tight", "options": {"eps_abs": 1e-9}},
     "[[settings]] 'tight': solver 'cascade-osqp': unknown option(s) 'eps_abs'; allowed options: freeze"),
    (["hcod"], {"solver": "hcod", "name": "x", "options": {"rank_rtol": "abc"}},
     "[[settings]] 'x': hcod: option rank_rtol='abc'"),
    ([SLEEP], {"solver": "sleep", "name": "slow", "options": {"dleay": 0.1}},
     "[[settings]] 'slow': solver 'sleep': unknown option(s) 'dleay'; allowed options: delay"),
    ([SLEEP], {"solver": "sleep", "name": "slow", "options": {"delay": "abc"}},
     ("[[settings]] 'slow': solver 'sleep' rejected its options {'delay': 'abc'}: ValueError: could not "
      "convert string to float: 'abc'")),
    (["hcod"], {"solver": "hcdo", "name": "x", "options": {}},
     "[[settings]] 'x': solver 'hcdo' is not one of the suite's solvers (hcod)"),
], ids=["registry-unknown-name", "registry-bad-value", "class-unknown-name", "class-bad-value",
        "settings-solver-typo"])
def test_bad_settings_options_fail_before_running(tmp_path, capsys, solvers, settings, message):
    path = write_suite(tmp_path / "s.toml", solvers, grid={"n": [4]}, modes=("cold",))
    options = ", ".join(f"{k} = {json.dumps(v)}" for k, v in settings["options"].items())
    path.write_text(path.read_text() + f'\n[[settings]]\nsolver = "{settings["solver"]}"\n'
                    f'name = "{settings["name"]}"\noptions = {{ {options} }}\n')
    out = tmp_path / "out"
    assert _run("--suite", path, "--out", out) == 2
    line = _one_error_line(capsys)
    assert f"suite {path}: " in line and message in line
    assert not (out / "results.csv").exists()


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


def test_the_schema_example_of_the_suites_docstring_is_valid():
    from hikbench.bench import suites

    doc = suites.__doc__
    block = textwrap.dedent(doc[doc.index("Schema"):doc.index("Decisions")].split("::", 1)[1])
    import tomllib
    data = tomllib.loads(block)
    suite = suites.suite_from_dict(data, "doc")
    assert suite.settings == [{"solver": "cascade-osqp", "name": "low", "options": {"accuracy": "low"}}]
    suites.expand(suite)
    if "cascade-osqp" in _available():  # its [[settings]] options are checked against the solver
        tasks, _ = suites.expand(suite, ["cascade-osqp"])
        assert {(t.entry.settings, t.entry.options_json()) for t in tasks} == {
            ("default", "{}"), ("low", '{"accuracy": "low"}')}


def _available():
    from hikbench.solvers import registry
    return registry.available()


# --- 4. unknown solver, empty selection -------------------------------------------------------------


def test_unknown_solver_lists_the_known_ones(tmp_path, capsys):
    assert _run("--suite", "quick", "--solvers", "nosuch", "--out", tmp_path / "out") == 2
    line = _one_error_line(capsys)
    assert "unknown solver 'nosuch' (in --solvers); known solvers: " in line
    assert "hcod" in line and "yardstick" in line
    assert not (tmp_path / "out").exists()


def test_unknown_solver_in_the_suite_file(tmp_path, capsys):
    path = write_suite(tmp_path / "s.toml", ["yardstick", "no-such-solver"], grid={"n": [4]})
    assert _run("--suite", path, "--out", tmp_path / "out") == 2
    assert f"unknown solver 'no-such-solver' (in suite {path}); known solvers:" in _one_error_line(capsys)


def test_a_known_solver_whose_backend_is_missing_is_skipped_with_its_hint(tmp_path, capsys, monkeypatch):
    from hikbench.solvers import registry

    registry.available()
    monkeypatch.setitem(registry._missing, "cascade-fake", "install it with: pip install fake")
    path = write_suite(tmp_path / "s.toml", ["yardstick", "cascade-fake"], grid={"n": [4]}, modes=("cold",))
    assert _run("--suite", path, "--out", tmp_path / "out") == 0
    assert "skipping solver cascade-fake: not installed: install it with: pip install fake" in \
        capsys.readouterr().err
    assert set(read_results(tmp_path / "out")["solver"]) == {"yardstick"}


@pytest.mark.parametrize("solvers, modes, message", [
    (["nomatch-*"], ("cold",), ("selects no job to run (skipped solver nomatch-*: pattern matches no "
                                "installed solver)")),
    (["yardstick"], ("warm",), "selects no job to run (none of its solvers runs in its modes ['warm']"),
], ids=["glob-matches-nothing", "warm-only-without-warm-solver"])
def test_a_run_selecting_no_job_fails(tmp_path, capsys, solvers, modes, message):
    path = write_suite(tmp_path / "s.toml", solvers, grid={"n": [4]}, modes=modes)
    out = tmp_path / "out"
    assert _run("--suite", path, "--out", out) == 2
    assert message in _one_error_line(capsys)
    assert not (out / "results.csv").exists()
    assert list((out / "problems").glob("*.npz"))  # the problems are still exported


# --- 5. command-line values --------------------------------------------------------------------------


def _refused_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]  # closed again: nothing listens there


@pytest.mark.parametrize("argv, message", [
    (["--limit", "-1"], "--limit must be >= 0"),
    (["--repeat", "0"], "--repeat must be >= 1; got 0"),
    (["--rounds", "0"], "--rounds must be >= 1; got 0"),
    (["--rounds", "4"], ("rounds = 4 (--rounds or the suite's): expected at most repeat = 3 (--repeat or the "
                         "suite's): each round times at least one solve of every row")),
    (["--timeout", "nan"], "--timeout must be a number of seconds > 0; got nan"),
    (["--workers", "0"], "--workers must be >= 1; got 0"),
    (["--scheduler", "nonsense"], ("--scheduler 'nonsense': expected a Dask scheduler address like "
                                   "tcp://HOST:PORT (missing port number")),
    (["--scheduler", "tcp://127.0.0.1:0"], "--scheduler 'tcp://127.0.0.1:0': expected a Dask scheduler"),
    (["--scheduler", "foo://h:1"], "unknown address scheme 'foo'"),
    (["--out", "{file}"], "--out {file}: exists and is not a directory; expected an output directory"),
    (["--out", "{file}/sub"], "--out {file}/sub: is under {file}, which exists and is not a directory"),
    (["--scheduler", "tcp://127.0.0.1:{port}"], "could not connect to scheduler tcp://127.0.0.1:{port}: "),
], ids=["limit-neg", "repeat-0", "rounds-0", "rounds-over-repeat", "timeout-nan", "workers-0", "scheduler-garbage", "scheduler-port-0",
        "scheduler-scheme", "out-file", "out-under-file", "scheduler-unreachable"])
def test_bad_command_line_values(tmp_path, capsys, argv, message):
    file = tmp_path / "a-file"
    file.write_text("x")
    port = _refused_port()
    argv = [a.format(file=file, port=port) for a in argv]
    if "--out" not in argv:
        argv += ["--out", str(tmp_path / "out")]
    suite = write_suite(tmp_path / "s.toml", ["yardstick"], grid={"n": [4]}, modes=("cold",))
    assert _run("--suite", suite, *argv) == 2
    assert message.format(file=file, port=port) in _one_error_line(capsys)
    assert not (tmp_path / "out" / "results.csv").exists()
    assert file.read_text() == "x"


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
