"""hikbench run: user mistakes are one-line errors (exit 2) before anything runs: bad suite
values, a suite path that is no TOML text, bad [[settings]] options, unknown solvers, a
selection of no job, bad command-line values. A known solver whose backend is missing is
skipped with the hint that installs it."""

import json
import socket

import pytest
from doubles import spec, write_suite

from hikbench.bench.cli import main
from hikbench.bench.harness.results import read_results

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


# --- bad suite values -------------------------------------------------------------------------------

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
    ('export = ["pdf"]\n' + GROUP, "export[0] = 'pdf': expected one of 'npz', 'soth'"),
    ('calibrate_each_job = "yes"\n' + GROUP, "calibrate_each_job = 'yes': expected true or false"),
    ('settings = 3\n' + GROUP, "settings = 3: expected [[settings]] tables"),
    ('problems = "abc"\n', "problems = 'abc': expected [[problems]] tables"),
    (GROUP + "seeds = 3\n", "problems[0].seeds = 3: expected a non-empty list of integers"),
    (GROUP + 'seeds = "abc"\n', "problems[0].seeds = 'abc': expected a non-empty list of integers"),
    (GROUP + "seeds = []\n", "problems[0].seeds = []: expected a non-empty list of integers"),
    (GROUP + 'params = "abc"\n', "problems[0].params = 'abc': expected a table"),
    (GROUP + 'solvers = "hcod"\n', "problems[0].solvers = 'hcod': expected a non-empty list"),
    ('[[problems]]\nfamily = "equality"\ngrid = { n = [] }\n',
     "problems[0].grid.n = []: expected at least one value"),
    ('[[problems]]\nfamily = 3\n', "problems[0].family = 3: expected a non-empty string"),
    ('[[problems]]\nfamily = "equality"\ngrid = { n = ["abc"] }\n',
     "problem equality/n=abc/seed=0: n must be an integer; got 'abc'"),
    ('[[settings]]\nsolver = "hcod"\noptions = {}\n' + GROUP, "settings[0]: missing key 'name'"),
    ('[[settings]]\nname = "x"\n' + GROUP, "settings[0]: missing key 'solver'"),
    ('[[settings]]\nsolver = "hcod"\nname = "x"\noptions = 3\n' + GROUP,
     "settings[0].options = 3: expected a table"),
    ('[[settings]]\nsolver = "hcod"\nname = "default"\n' + GROUP, "name 'default' is reserved"),
    ('[[settings]]\nsolver = "hcod"\nname = "x"\nopts = {}\n' + GROUP, "unknown key settings[0].opts (did you mean 'options'?)"),
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


# --- settings options -------------------------------------------------------------------------------


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


# --- unknown solver, empty selection ----------------------------------------------------------------


def test_unknown_solver_lists_the_known_ones(tmp_path, capsys):
    assert _run("--suite", "quick", "--solvers", "nosuch", "--out", tmp_path / "out") == 2
    line = _one_error_line(capsys)
    assert "unknown solver 'nosuch' (in --solvers); known solvers: " in line
    assert "hcod" in line and "yardstick" in line
    assert not (tmp_path / "out").exists()


def test_a_misspelt_solver_gets_its_close_match(tmp_path, capsys):
    assert _run("--suite", "quick", "--solvers", "hcdo", "--out", tmp_path / "out") == 2
    assert "unknown solver 'hcdo' (in --solvers); did you mean 'hcod'?; known solvers: " in _one_error_line(capsys)


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


# --- command-line values ------------------------------------------------------------------------------


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


# --- a suite path that is no TOML text ------------------------------------------------------------

@pytest.mark.parametrize("kind, message", [("directory", "not a file"), ("binary", "not UTF-8 text")],
                         ids=["directory", "binary"])
def test_a_suite_path_that_is_no_toml_text_is_a_one_line_error(tmp_path, capsys, kind, message):
    """--suite DIR gave an IsADirectoryError traceback; a binary file a UnicodeDecodeError one."""
    from clitools import assert_user_error, run

    path = tmp_path / "suite"
    if kind == "directory":
        path.mkdir()
    else:
        path.write_bytes(b"\xff\xfe\x00binary")
    code, _, err = run(capsys, "run", "--quiet", "--suite", path, "--out", tmp_path / "out")
    assert_user_error(code, err, str(path), message)


def test_a_grid_too_large_for_a_run_is_refused_before_any_problem_is_made(tmp_path, capsys):
    """Ten grid keys of 100 values are 1e20 problems in a few lines of TOML: refused in one line."""
    import tomli_w
    from clitools import assert_user_error, run

    grid = {f"k{i}": list(range(100)) for i in range(10)}
    suite = tmp_path / "s.toml"
    suite.write_text(tomli_w.dumps({"solvers": ["hcod"], "problems": [{"family": "equality", "grid": grid}]}))
    code, _, err = run(capsys, "run", "--suite", suite, "--out", tmp_path / "out")
    assert_user_error(code, err, "problems[0]: its grid and seeds make 1e+20 problems: expected at most 100000 per group")
