"""A solver of one's own (docs/adding-a-solver.md): the template in
bench/examples/pinv_recursion.py through `hikbench solve`, `hikbench run` and a
package's entry point, without touching the registry."""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import tomli_w
from clitools import assert_user_error, run
from doubles import write_suite

from hikbench.bench.cli import main
from hikbench.bench.harness.results import read_results
from hikbench.problems import generators as G
from hikbench.problems.files import save_npz
from hikbench.solvers.yardstick import yardstick_solution

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "bench" / "examples" / "pinv_recursion.py"
SPEC = f"{EXAMPLE}:PinvRecursion"


@pytest.fixture
def equality_file(tmp_path):
    h = G.equality_stack(12, 3, 3, seed=0)
    path = tmp_path / "eq.npz"
    save_npz(h, path)
    return h, path


def test_solve_command_takes_a_module_class(capsys, equality_file):
    h, path = equality_file
    code, out, err = run(capsys, "solve", path, "--solver", SPEC, "--option", "rcond=1e-12", "--json")
    assert code == 0, err
    res = json.loads(out)
    assert res["solver"] == SPEC and res["status"] == "optimal"
    np.testing.assert_allclose(res["x"], yardstick_solution(h), rtol=0, atol=1e-12)


@pytest.mark.parametrize("solver, option, fragment", [
    (f"{EXAMPLE}:Nope", [], "has no attribute 'Nope'"),
    (SPEC, ["--option", "rcond=2"], "pinv-recursion: option rcond=2 is not allowed; expected a finite number"),
    (SPEC, ["--option", "tol=1"], "unknown option(s) 'tol'; allowed options: rcond"),
], ids=["no such class", "option value", "option name"])
def test_solve_command_names_what_is_wrong_with_a_module_class(capsys, equality_file, solver, option, fragment):
    code, _, err = run(capsys, "solve", equality_file[1], "--solver", solver, *option)
    assert_user_error(code, err, fragment)


def test_a_run_verifies_it_and_leaves_out_what_it_declines(tmp_path):
    """Equality stacks: verified against the reference, cold only (no warm start);
    IK-like (inequalities): `unsupported`, not a failure."""
    suite = tmp_path / "mine.toml"
    suite.write_bytes(tomli_w.dumps({
        "repeat": 2, "warmup": 1, "timeout": 60.0, "modes": ["cold", "warm"], "solvers": [SPEC],
        "problems": [{"family": "equality", "grid": {"n": [10], "depth": [3], "rows": [3]}, "seeds": [0, 1]},
                     {"family": "ik-like", "grid": {"n": [9]}, "seeds": [0]}]}).encode())
    assert main(["run", "--quiet", "--suite", str(suite), "--out", str(tmp_path / "out")]) == 0
    df = read_results(tmp_path / "out")
    assert set(df["solver"]) == {"pinv-recursion"} and set(df["mode"]) == {"cold"}
    eq, ik = df[df["family"] == "equality"], df[df["family"] == "ik-like"]
    assert len(eq) == 2 and set(eq["status"]) == {"optimal"} and set(eq["verified"]) == {True}
    assert len(ik) == 1 and ik["status"].tolist() == ["unsupported"]
    assert ik["reason"].tolist() == ["pinv-recursion: equality rows only"]


def test_an_entry_point_gives_it_a_registry_name(tmp_path, equality_file):
    """A distribution declaring ``[project.entry-points."hikbench.solvers"]`` (here its
    installed metadata, on PYTHONPATH) adds the solver under its name, as a built-in."""
    site = tmp_path / "site"
    dist = site / "pinv_demo-0.1.dist-info"
    dist.mkdir(parents=True)
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: pinv-demo\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text("[hikbench.solvers]\npinv = pinv_recursion:SOLVERS\n")
    shutil.copy(EXAMPLE, site / "pinv_recursion.py")
    env = {"PATH": "/usr/bin:/bin", "PYTHONPATH": str(site), "OPENBLAS_NUM_THREADS": "1"}

    def hikbench(*argv):
        return subprocess.run([sys.executable, "-m", "hikbench", *map(str, argv)], capture_output=True, text=True,
                              env=env, cwd=tmp_path, timeout=300, check=False)

    listed = hikbench("list", "solvers")
    assert listed.returncode == 0, listed.stderr
    assert any(line.split()[:1] == ["pinv-recursion"] for line in listed.stdout.splitlines()), listed.stdout
    solved = hikbench("solve", equality_file[1], "--solver", "pinv-recursion", "--json")
    assert solved.returncode == 0, solved.stderr
    res = json.loads(solved.stdout)
    assert res["status"] == "optimal"
    np.testing.assert_allclose(res["x"], yardstick_solution(equality_file[0]), rtol=0, atol=1e-12)


USER_FILE = '''
from hikbench.solvers.nullspace import SOLVERS

PinvAll = next(i.factory for i in SOLVERS if i.name == "pinv-all")


class Zero(PinvAll):  # inherits name = "pinv-all"
    def solve(self, hierarchy):
        res = super().solve(hierarchy)
        res.x[:] = 0.0
        return res


class Mine(Zero):
    name = "mine"


class AlsoMine(Zero):
    name = "mine"


class NotASolver:
    name = "not-a-solver"
'''


@pytest.mark.parametrize("solvers, fragments", [
    (["{f}:Zero"], ["solver '{f}:Zero' is named 'pinv-all' (its attribute `name`), the name of a registered solver"]),
    (["pinv-all", "{f}:Zero"], ["is named 'pinv-all'"]),
    (["{f}:Mine", "{f}:AlsoMine"], ["two solvers are named 'mine': {f}:Mine and {f}:AlsoMine"]),
    (["{f}:NotASolver"], ["'{f}:NotASolver' is not a solver: expected a class with a solve(hierarchy) method"]),
], ids=["inherited registered name", "beside the registered one", "same name twice", "no solve method"])
def test_a_run_refuses_a_solver_whose_rows_would_land_under_another_name(capsys, tmp_path, solvers, fragments):
    """Rows are keyed by the solver's name: a user's class named like a registered solver
    (an inherited `name`) or like another of the run's would write, skip or hide their rows."""
    f = tmp_path / "mine.py"
    f.write_text(USER_FILE)
    suite = tmp_path / "s.toml"
    suite.write_bytes(tomli_w.dumps({"repeat": 1, "modes": ["cold"], "solvers": ["yardstick"], "problems": [
        {"family": "equality", "grid": {"n": [6], "depth": [2], "rows": [2]}, "seeds": [0]}]}).encode())
    code, _, err = run(capsys, "run", "--quiet", "--suite", suite, "--out", tmp_path / "out", "--solvers",
                       *[s.format(f=f) for s in solvers])
    assert_user_error(code, err, *[x.format(f=f) for x in fragments])
    assert not (tmp_path / "out" / "results.csv").exists()


def test_solve_command_refuses_a_class_without_solve(capsys, tmp_path, equality_file):
    f = tmp_path / "mine.py"
    f.write_text(USER_FILE)
    code, _, err = run(capsys, "solve", equality_file[1], "--solver", f"{f}:NotASolver")
    assert_user_error(code, err, "is not a solver: expected a class with a solve(hierarchy) method")


_BAD = """
import numpy as np
from hikbench.solvers.base import SolveResult


class WrongShape:
    name = "wrong-shape"

    def solve(self, h):
        return SolveResult(np.zeros(h.n + 1), "optimal")


class Array:
    name = "array"

    def solve(self, h):
        return np.zeros(h.n)
"""


@pytest.mark.parametrize("cls, reason", [
    ("WrongShape", "wrong-shape: solve() returned x of shape (5,): expected (4,), one value per variable"),
    ("Array", "array: solve() returned ndarray: expected a hikbench.solvers.base.SolveResult"),
], ids=["wrong-shape", "ndarray"])
def test_an_answer_off_the_contract_is_an_error_row_naming_it(tmp_path, capsys, cls, reason):
    """x of the wrong length was recorded `optimal` with an empty reason (verdict "no x"), an
    ndarray instead of a SolveResult gave "AttributeError ... at worker.py:55" (run) or a
    traceback (solve, scenario)."""
    (tmp_path / "bad.py").write_text(_BAD)
    suite = write_suite(tmp_path / "s.toml", ["yardstick"], grid={"n": [4], "depth": [1]}, modes=("cold",),
                        repeat=1)
    assert main(["run", "--quiet", "--suite", str(suite), "--out", str(tmp_path / "out"),
                 "--solvers", f"{tmp_path / 'bad.py'}:{cls}"]) == 0
    row = read_results(tmp_path / "out").iloc[0]
    assert (row["status"], row["reason"]) == ("error", reason)
    problem = next((tmp_path / "out" / "problems").glob("*.npz"))
    capsys.readouterr()
    assert main(["solve", str(problem), "--solver", f"{tmp_path / 'bad.py'}:{cls}"]) == 1
    assert f"status      error ({reason})" in capsys.readouterr().out


_FACTORIES = """
from hikbench.solvers.base import Solver


class NeedsModel(Solver):
    name = "needs-model"

    def __init__(self, model):
        self.model = model

    def solve(self, h):
        raise AssertionError("never built")


def plain_function(h, x):
    return x


def makes_an_int():
    return 42


class RaisesInInit(Solver):
    name = "raises-in-init"

    def __init__(self):
        raise RuntimeError("cannot open the model")

    def solve(self, h):
        raise AssertionError("never built")


class RaisesInSolve(Solver):
    name = "raises-in-solve"

    def solve(self, h):
        raise RuntimeError("singular")
"""


@pytest.mark.parametrize("cls, fragment", [
    ("NeedsModel", "solver '{f}:NeedsModel': cannot be built with the options given (none): missing a required "
                   "argument: 'model'; a solver's factory is called with keyword options only"),
    ("plain_function", "cannot be built with the options given (none): missing a required argument: 'h'"),
    ("makes_an_int", "solver '{f}:makes_an_int': its factory returned int: expected a solver, an object with a "
                     "solve(hierarchy) method"),
], ids=["required argument", "a function of the problem", "factory returns no solver"])
def test_a_factory_that_cannot_make_a_solver_is_a_user_error(capsys, tmp_path, equality_file, cls, fragment):
    f = tmp_path / "factories.py"
    f.write_text(_FACTORIES)
    code, _, err = run(capsys, "solve", equality_file[1], "--solver", f"{f}:{cls}")
    assert_user_error(code, err, fragment.format(f=f))


@pytest.mark.parametrize("cls, reason", [
    ("RaisesInInit", "RuntimeError: cannot open the model"),
    ("RaisesInSolve", "RuntimeError: singular"),
], ids=["constructor", "solve"])
def test_solve_command_reports_a_solvers_exception_as_status_error(capsys, tmp_path, equality_file, cls, reason):
    """The solver's own exception is its answer (exit 1, status error), in text and in JSON:
    the constructor's gave a traceback, and --json printed text."""
    f = tmp_path / "factories.py"
    f.write_text(_FACTORIES)
    code, out, err = run(capsys, "solve", equality_file[1], "--solver", f"{f}:{cls}")
    # (the worker's reason ends with where it was raised, as in a row of `run`)
    assert (code, err) == (1, "") and f"status      error ({reason} at factories.py:" in out
    code, out, err = run(capsys, "solve", equality_file[1], "--solver", f"{f}:{cls}", "--json", "--certify")
    assert (code, err) == (1, "")
    got = json.loads(out)
    assert got.pop("reason").startswith(f"{reason} at factories.py:")
    assert got == {"solver": f"{f}:{cls}", "status": "error", "x": None,
                   "level_norms": None, "iterations": None, "time_s": None, "certificate": None}


def test_a_solver_file_imports_its_sibling_modules(capsys, tmp_path, equality_file):
    """``python mine.py`` finds a module beside it; so does ``--solver mine.py:Class``
    (it was a traceback: ModuleNotFoundError)."""
    (tmp_path / "helpers_of_mine.py").write_text("from hikbench.solvers.nullspace import SOLVERS\n"
                                                 "PINV = next(i.factory for i in SOLVERS if i.name == 'pinv-all')\n")
    (tmp_path / "mine.py").write_text("import helpers_of_mine\n\n\nclass Mine(helpers_of_mine.PINV):\n"
                                      "    name = 'mine'\n")
    code, out, err = run(capsys, "solve", equality_file[1], "--solver", f"{tmp_path / 'mine.py'}:Mine", "--json")
    assert code == 0, err
    np.testing.assert_allclose(json.loads(out)["x"], yardstick_solution(equality_file[0]), rtol=0, atol=1e-12)
    assert str(tmp_path) not in sys.path


@pytest.mark.parametrize("text, fragment", [
    ("x = 1 / 0\n", "importing {f} raised ZeroDivisionError: division by zero at broken.py:1"),
    ("def f(:\n", "importing {f} raised SyntaxError: invalid syntax (broken.py, line 1)"),
    ("import no_such_module_of_mine\n", "importing {f} raised ModuleNotFoundError: No module named "
                                         "'no_such_module_of_mine' at broken.py:1"),
], ids=["raises", "syntax", "missing import"])
def test_a_solver_file_that_fails_to_import_is_a_user_error(capsys, tmp_path, equality_file, text, fragment):
    f = tmp_path / "broken.py"
    f.write_text(text)
    code, _, err = run(capsys, "solve", equality_file[1], "--solver", f"{f}:Mine")
    assert_user_error(code, err, fragment.format(f=f))
    assert not any(name.startswith("_hikbench_user_") and "broken" in name for name in sys.modules)


def test_a_module_in_the_current_directory_gets_a_hint(capsys, tmp_path, equality_file, monkeypatch):
    (tmp_path / "mine.py").write_text("")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "path", [p for p in sys.path if p not in ("", ".", str(tmp_path))])
    code, _, err = run(capsys, "solve", equality_file[1], "--solver", "mine:Mine")
    assert_user_error(code, err, "cannot import module 'mine'", "the current directory is not searched: give the "
                                 "file (mine.py:Mine) or set PYTHONPATH")
