"""User mistakes on the command line: one line on stderr naming the option,
file or key, exit code 2, no traceback; and what ``solve`` prints of a solver that
reports no iteration count."""

import json

import numpy as np
import pytest
from clitools import assert_user_error, run

INF = np.inf


# ---------------------------------------------------------------- scenario
def test_scenario_out_is_a_file(capsys, tmp_path):
    f = tmp_path / "afile"
    f.write_text("")
    code, _, err = run(capsys, "scenario", "reach", "--out", f)
    assert_user_error(code, err, "hikbench scenario: error:", f"--out {f}: is a file; expected a directory")


def test_scenario_list_needs_no_name(capsys):
    code, out, err = run(capsys, "scenario", "--list")
    assert code == 0, err
    assert out.startswith("scenarios: ") and "reach" in out and "stacks:" in out


def test_scenario_without_name(capsys):
    code, _, err = run(capsys, "scenario")
    assert_user_error(code, err, "give a scenario NAME", "`hikbench scenario --list`")


# ---------------------------------------------------------------- generate
@pytest.mark.parametrize("argv, fragment", [
    (["--seed", "-1"], "--seed must be an integer >= 0; got -1"),
    (["--param", "cond=1e400"], "cond must be a finite number >= 1"),
    (["--param", "cond=0.5"], "cond must be a finite number >= 1"),
    (["--param", "row_scale=NaN"], "row_scale must be a finite number >= 1"),
    (["--param", "box_bound=-1"], "box_bound must be a finite number >= 0"),
    (["--param", "equality_fraction=2"], "equality_fraction must be a finite number >= 0 and <= 1; got 2.0"),
    (["--param", "rows=-1"], "rows must be >= 0"),
    # numpy's MemoryError tracebacks before
    (["--param", "n=1000000000000"], ("family random: n = 1000000000000 variables: one n x n matrix of doubles "
                                      "needs 7.45e+15 GiB, more than this machine's ")),
    (["--param", "rows=1000000000000"], ("random_hierarchy: depth = 5 levels, 4000000000020 rows of n = 20 "
                                         "variables need 6.85e+05 GiB, more than half of this machine's")),
], ids=["negative seed", "cond overflow", "cond below 1", "row_scale nan", "box_bound negative",
        "equality_fraction", "rows negative", "n beyond the memory", "rows beyond the memory"])
def test_generate_parameter_errors(capsys, tmp_path, argv, fragment):
    code, _, err = run(capsys, "generate", "random", *argv, "--out", tmp_path / "g")
    assert_user_error(code, err, "hikbench generate: error:", fragment)


def test_inspect_of_a_problem_beyond_the_memory(capsys, tmp_path):
    """`variable size 100000` and no rows: np.eye(n) of the rank analysis gave numpy's MemoryError."""
    path = tmp_path / "big.soth"
    path.write_text("variable size 100000\nlevel\nequalities 0\ninequalities 0\nend\n")
    code, _, err = run(capsys, "inspect", path)
    assert_user_error(code, err, "hikbench inspect: error: rank analysis: n = 100000 variables: one n x n "
                                 "matrix of doubles needs 74.5 GiB")


# ------------------------------------------------------ malformed .npz files
def _bad_npz(path, problem, **changes):
    h, _ = problem
    arrays = {"A": h.A, "lower": h.lower, "upper": h.upper, "level": h.level, "n": np.int64(h.n),
                  "names": np.array(h.names, dtype=str)}
    arrays.update(changes)
    with open(path, "wb") as f:
        np.savez(f, **arrays)
    return path


@pytest.mark.parametrize("command", [["inspect"], ["solve"], ["export", "--format", "soth", "--out", "-"]],
                         ids=["inspect", "solve", "export"])
@pytest.mark.parametrize("kind, fragment", [
    ("A strings", "A must be a numeric array (float64); got dtype <U"),
    ("lower strings", "lower must be a numeric array (float64); got dtype <U"),
    ("A complex", "A must be a numeric array (float64); got dtype complex128"),
    ("A objects", "A must be a numeric array; it holds Python objects"),
    ("not a zip", "not a valid .npz file (expected a zip archive of arrays"),
    (".npy", "not a valid .npz file (expected a zip archive of arrays"),
    ("A truncated", "array A cannot be read (EOF: reading array data, expected "),
], ids=["A strings", "lower strings", "A complex", "A objects", "not a zip", "npy", "A truncated"])
def test_malformed_npz(capsys, tmp_path, problem, command, kind, fragment):
    path = tmp_path / "bad.npz"
    h = problem[0]
    if kind == "A strings":
        _bad_npz(path, problem, A=np.full(h.A.shape, "abc"))
    elif kind == "lower strings":
        _bad_npz(path, problem, lower=np.full(h.rows, "low"))
    elif kind == "A complex":
        _bad_npz(path, problem, A=h.A.astype(complex))
    elif kind == "A objects":
        _bad_npz(path, problem, A=h.A.astype(object))
    elif kind == "not a zip":
        path.write_text("hello")
    elif kind == "A truncated":  # the zip's directory intact, A.npy's data cut short (was: "holds Python objects")
        import zipfile

        _bad_npz(path, problem)
        with zipfile.ZipFile(path) as z:
            members = {name: z.read(name) for name in z.namelist()}
        with zipfile.ZipFile(path, "w") as z:
            for name, data in members.items():
                z.writestr(name, data[:-8] if name == "A.npy" else data)
    else:
        with open(path, "wb") as f:
            np.save(f, h.A)
    code, _, err = run(capsys, command[0], path, *command[1:])
    assert_user_error(code, err, f"{path}: {fragment}")
    assert "allow_pickle" not in err


# ------------------------------------------------------------------ claims
@pytest.fixture
def empty_run(tmp_path):
    """A run directory with a results.csv (claims reads it before the scenario)."""
    from hikbench.bench.harness.columns import names
    d = tmp_path / "run"
    d.mkdir()
    (d / "results.csv").write_text(",".join(names()) + "\n")
    return d


@pytest.mark.parametrize("make, fragment", [
    (lambda d: d / "nosuch.csv", "--scenario {p}: no such file or directory"),
    (lambda d: _write(d / "ik12.npz", b"PK\x03\x04\xff\xfe binary"), "{p}: not a text CSV file"),
    (lambda d: _write(d / "x.csv", b"a,b\n1,2\n"), "{p}: missing column(s) step, solver, solve_time_min_s"),
    # a benchmark's results.csv has solver and solve_time_s too: it read as a scenario without hcod rows
    (lambda d: _results_csv(d / "results.csv"), "{p}: missing column(s) step, solve_time_min_s;"),
    (lambda d: _write(d / "one.csv", b"step,solver,solve_time_s\n0,hcod,0.001\n"),
     "{p}: one timed call per step (solve_time_s), no solve_time_min_s: the claims take the solver's cost"),
    (lambda d: _write(d / "e.csv", b""), "{p}: cannot read as CSV"),
    (lambda d: _mkdir(d / "empty"), "--scenario {p}: no *.csv file in this directory"),
], ids=["missing", "binary", "wrong columns", "results.csv", "one-call-per-step", "empty file",
        "empty directory"])
def test_claims_bad_scenario(capsys, tmp_path, empty_run, make, fragment):
    p = make(tmp_path)
    code, _, err = run(capsys, "claims", empty_run, "--scenario", p)
    assert_user_error(code, err, "hikbench claims: error:", fragment.format(p=p))


def _results_csv(path):
    from hikbench.bench.harness.columns import names

    path.write_text(",".join(names()) + "\n")
    return path


@pytest.mark.parametrize("command", [["claims"], ["report"], ["compare", "{d}"]], ids=["claims", "report", "compare"])
def test_a_file_given_as_run_directory(capsys, tmp_path, empty_run, command):
    """`claims suite.toml` said: run `hikbench run --out suite.toml` first."""
    f = tmp_path / "mini.toml"
    f.write_text("repeat = 1\n")
    code, _, err = run(capsys, command[0], f, *[a.format(d=empty_run) for a in command[1:]])
    assert_user_error(code, err, f"{f}: is a file; expected a run directory (the --out of `hikbench run`")


def _write(path, data: bytes):
    path.write_bytes(data)
    return path


def _mkdir(path):
    path.mkdir()
    return path


# ----------------------------------------------------------------- compare
@pytest.mark.parametrize("argv, fragment", [
    (["--alpha", "5"], "--alpha must be a significance level with 0 < alpha < 1 (e.g. 0.01); got 5"),
    (["--alpha", "0"], "--alpha must be a significance level with 0 < alpha < 1"),
    (["--alpha", "nan"], "--alpha must be a significance level with 0 < alpha < 1"),
    (["--threshold", "1"], "--threshold must be a finite number > 1"),
    (["--threshold", "nan"], "--threshold must be a finite number > 1"),
], ids=["alpha 5", "alpha 0", "alpha nan", "threshold 1", "threshold nan"])
def test_compare_option_errors(capsys, empty_run, argv, fragment):
    code, _, err = run(capsys, "compare", empty_run, empty_run, *argv)
    assert_user_error(code, err, "hikbench compare: error:", fragment)


# ------------------------------------------------------------------- solve
@pytest.mark.parametrize("solver, text, value", [
    ("yardstick", "iterations  -", None),
    ("cascade-clarabel", "iterations  -", None),
    ("hcod", "iterations  ", 2),
], ids=["yardstick", "cascade", "hcod"])
def test_solve_iterations_not_reported(capsys, problem, solver, text, value):
    from hikbench.solvers import registry
    if solver not in registry.available():
        pytest.skip(f"{solver} not installed")
    path = problem[1]
    code, out, err = run(capsys, "solve", path, "--solver", solver)
    assert code == 0, err
    line = next(ln for ln in out.splitlines() if ln.startswith("iterations"))
    assert line.startswith(text) and (value is None) == line.endswith("-"), line
    code, out, err = run(capsys, "solve", path, "--solver", solver, "--json")
    it = json.loads(out)["iterations"]
    assert it is None if value is None else it >= 1
