"""The command line, called through main(argv): solve, generate, inspect,
export, list; user errors exit 2 with one line on stderr and no traceback."""

import json
import os

import numpy as np
import pytest
from clitools import assert_user_error, run

from hikbench.bench.cli import COMMANDS
from hikbench.problems import Hierarchy, Level
from hikbench.problems.files import load, save_npz
from hikbench.problems.generators import FAMILIES, all_families, generate
from hikbench.problems.soth import save_soth, soth_order
from hikbench.problems.verify import level_norms

INF = np.inf


# ------------------------------------------------------------------- solve
@pytest.mark.parametrize("extra", [[], ["--repeat", "3"], ["--repeat", "2", "--warm"]],
                         ids=["once", "repeat", "warm"])
def test_solve_json(capsys, problem, extra):
    h, path = problem
    code, out, err = run(capsys, "solve", path, "--solver", "yardstick", "--json", *extra)
    assert code == 0, err
    res = json.loads(out)
    assert {"solver", "status", "x", "level_norms", "iterations", "time_s"} <= set(res)
    assert set(res["time_s"]) >= {"median", "min"}
    assert res["solver"] == "yardstick" and res["status"] == "optimal"
    assert 0 < res["time_s"]["min"] <= res["time_s"]["median"]
    # level norms are recomputed from x by the problem model
    np.testing.assert_allclose(res["level_norms"], level_norms(h, np.array(res["x"])), rtol=1e-15, atol=0)
    # optimum: x1 = 2 - x0 with x1 <= 0.5 -> x0 >= 1.5; level 1 wants x0 = 3 -> x = (3, -1), norms (0, 0)
    np.testing.assert_allclose(res["x"], [3.0, -1.0], atol=1e-8)


@pytest.mark.parametrize("solver, note", [("yardstick", True), ("cascade-daqp", False)],
                         ids=["no warm start", "warm start"])
def test_solve_warm_notes_a_solver_without_warm_start(capsys, problem, solver, note):
    code, out, err = run(capsys, "solve", problem[1], "--solver", solver, "--warm", "--repeat", "2")
    assert code == 0 and "over 2 warm solve(s)" in out
    said = f"note: {solver} has no warm start: --warm times re-solves that redo a cold solve's work\n"
    assert err == (said if note else "")


@pytest.mark.parametrize("solver", ["hcod", "cascade-daqp"])
def test_solve_certify(capsys, problem, solver):
    """--certify: the exact optimum on the active set read off x, x = (3, -1) with norms (0, 0)
    (test_solve_json), in the JSON and the text."""
    path = problem[1]
    code, out, err = run(capsys, "solve", path, "--solver", solver, "--json", "--certify")
    assert code == 0, err
    cert = json.loads(out)["certificate"]
    assert cert["certified"] and cert["reason"] == "", cert
    np.testing.assert_allclose(cert["level_norms"], [0.0, 0.0], atol=1e-40)
    assert cert["x_is_optimal"] is True and cert["x_above_at_level"] is None, cert
    code, out, _ = run(capsys, "solve", path, "--solver", solver, "--certify")
    assert code == 0 and "certificate exact optimum, level norms" in out
    assert "x           attains it" in out


def test_solve_certify_says_when_x_is_not_the_certified_optimum(capsys, problem, tmp_path):
    """The certificate is of the exact optimum on the active set read off x, which every x
    has: an x above it is named not optimal (x = (0, 0): level 0's row x0 + x1 = 2 is off by 2,
    and its bound x1 <= 0.5 holds)."""
    f = tmp_path / "zero.py"
    f.write_text("import numpy as np\nfrom hikbench.solvers.base import SolveResult\n\nclass Zero:\n    name = 'zero'\n\n"
                 "    def solve(self, h):\n        return SolveResult(np.zeros(h.n), 'optimal')\n")
    code, out, err = run(capsys, "solve", problem[1], "--solver", f"{f}:Zero", "--json", "--certify")
    assert code == 1, err  # (x is not optimal: the exit status says so)
    cert = json.loads(out)["certificate"]
    assert cert["certified"] and cert["x_is_optimal"] is False and cert["x_above_at_level"] == 0, cert
    assert cert["verified"] == {"high": False, "default": False, "low": False}, cert
    assert cert["x_above_by"] == pytest.approx(json.loads(out)["level_norms"][0] - cert["level_norms"][0],
                                               rel=1e-12)
    code, out, _ = run(capsys, "solve", problem[1], "--solver", f"{f}:Zero", "--certify")
    assert code == 1
    assert "x           is NOT optimal at the default profile: above the certified optimum at level 0 by 2" in out


#: level 0: x0 = 1e6 and x0 = -1e6 (in conflict: x0* = 0, level 0's norm sqrt(2) 1e6); level 1:
#: x0 = 1. x0 = 1e-3 raises level 0's norm by 5e-13 (second order), far within its tolerance
#: (rtol x 1.4e6), and lowers level 1's by 1e-3: below the exact optimum there
TRADE = Hierarchy.from_levels([Level.equality([[1.0], [1.0]], [1e6, -1e6]), Level.equality([[1.0]], [1.0])])


@pytest.mark.parametrize("x0, code, words", [
    (0.0, 0, "x           attains it (no level above it"),
    (1e-3, 0, "below it at level 1 by 0.001"),
    (1e-5, 0, "below it at level 1 by 1e-05"),
], ids=["optimum", "below-by-1e-3", "below-by-1e-5"])
def test_solve_certify_says_below_when_x_is_below_the_optimum(capsys, tmp_path, x0, code, words):
    """An x below the certified optimum at a level (bought within the tolerance of a level
    above) attains it at the profile and is said to be *below* it, never "above ... by" a
    negative amount (before: "above the certified optimum at level 1 by -0.001", exit 0)."""
    save_npz(TRADE, tmp_path / "trade.npz")
    f = tmp_path / "fixed.py"
    f.write_text("import numpy as np\nfrom hikbench.solvers.base import SolveResult\n\nclass Fixed:\n"
                 "    name = 'fixed'\n\n    def solve(self, h):\n"
                 f"        return SolveResult(np.array([{x0!r}]), 'optimal')\n")
    rc, out, err = run(capsys, "solve", str(tmp_path / "trade.npz"), "--solver", f"{f}:Fixed", "--certify")
    assert rc == code, out + err
    assert words in out and "above the certified optimum" not in out, out
    rc, out, err = run(capsys, "solve", str(tmp_path / "trade.npz"), "--solver", f"{f}:Fixed", "--certify", "--json")
    cert = json.loads(out)["certificate"]
    assert cert["x_is_optimal"] is True and cert["x_above_at_level"] is None and cert["x_above_by"] is None, cert


def test_solve_text(capsys, problem):
    code, out, _ = run(capsys, "solve", problem[1])
    assert code == 0
    assert "status      optimal" in out and "level norms" in out


def test_solve_soth_file(capsys, problem, tmp_path):
    h, _ = problem
    path = tmp_path / "p.soth"
    save_soth(h, path)
    code, out, _ = run(capsys, "solve", str(path), "--json")
    assert code == 0
    np.testing.assert_allclose(json.loads(out)["x"], [3.0, -1.0], atol=1e-8)


@pytest.mark.parametrize("argv, fragments", [
    (["solve", "{missing}"], ["hikbench solve: error:", "no such file"]),
    (["solve", "{path}", "--solver", "nope"], ["unknown solver 'nope'", "found solvers:"]),
    (["solve", "{path}", "--solver", "hcdo"], ["unknown solver 'hcdo'; did you mean 'hcod'? (found solvers:"]),
    (["solve", "{path}", "--option", "tol=1"], ["unknown option(s) 'tol'"]),
    (["solve", "{path}", "--option", "novalue"], ["--option 'novalue': expected KEY=VALUE"]),
    (["solve", "{path}", "--repeat", "0"], ["--repeat must be >= 1; got 0"]),
    (["solve", "{garbage}"], ["g.npz: not a valid .npz file"]),
    (["solve", "{badsoth}"], ["line 1: expected 'size', got 'sizes'"]),
], ids=["missing file", "unknown solver", "misspelt solver", "unknown option", "option syntax", "repeat", "bad npz",
        "bad soth"])
def test_solve_user_errors(capsys, problem, tmp_path, argv, fragments):
    (tmp_path / "g.npz").write_bytes(b"garbage")
    (tmp_path / "b.soth").write_text("variable sizes 2")
    names = {"path": problem[1], "missing": str(tmp_path / "none.npz"), "garbage": str(tmp_path / "g.npz"),
             "badsoth": str(tmp_path / "b.soth")}
    code, _, err = run(capsys, *[a.format(**names) for a in argv])
    assert_user_error(code, err, *fragments)


# ---------------------------------------------------------------- generate
@pytest.mark.parametrize("fmt, ext", [("npz", ".npz"), ("soth", ".soth")], ids=["npz", "soth"])
def test_generate_writes_loadable_deterministic_files(capsys, tmp_path, fmt, ext):
    out_dir = tmp_path / "gen"
    code, out, err = run(capsys, "generate", "random", "--seed", "4", "--seeds", "2", "--param", "n=6",
                         "--param", "inequality=one-sided", "--param", "rank=[2,3,1,2]",
                         "--out", str(out_dir),
                         "--format", fmt)
    assert code == 0, err
    paths = out.split()
    assert [os.path.basename(p) for p in paths] == [
        f"random-inequality=one-sided-n=6-rank=2,3,1,2-seed{s}{ext}" for s in (4, 5)]
    for seed, path in zip((4, 5), paths):
        expected = generate("random", seed=seed, n=6, inequality="one-sided", rank=[2, 3, 1, 2])
        got = load(path)
        if fmt == "npz":
            assert got == expected
        else:
            np.testing.assert_array_equal(got.A, soth_order(expected).A)


@pytest.mark.parametrize("family", list(all_families()))
def test_generate_every_family(capsys, tmp_path, family):
    code, out, err = run(capsys, "generate", family, "--out", str(tmp_path))
    assert code == 0, err
    assert load(out.strip()) == generate(family, seed=0)


@pytest.mark.parametrize("argv, fragments", [
    (["generate", "nope", "--out", "{d}"], ["unknown family 'nope'; expected one of"]),
    (["generate", "random", "--param", "depht=3", "--out", "{d}"], ["unknown parameter 'depht' (did you mean 'depth'?)"]),
    (["generate", "random", "--param", "n=abc", "--out", "{d}"], ["n must be an integer; got 'abc'"]),
    (["generate", "random", "--param", "cond=big", "--out", "{d}"], ["cond must be a finite number >= 1"]),
    (["generate", "random", "--param", "box=1", "--out", "{d}"], ["box must be true or false"]),
    (["generate", "random", "--param", "n", "--out", "{d}"], ["--param 'n': expected KEY=VALUE"]),
    (["generate", "random", "--param", "rank=9", "--out", "{d}"], ["level 0: rank 9 must be in [0, rows=5]"]),
    (["generate", "random", "--param", "rank=x", "--out", "{d}"], ["rank must be an integer; got 'x'"]),
    (["generate", "random", "--seeds", "0", "--out", "{d}"], ["--seeds must be >= 1"]),
    (["generate", "random", "--out", "{file}/sub"], ["cannot create the directory"]),
    (["generate", "robot-stack", "--param", "stack=nope", "--out", "{d}"], ["unknown stack 'nope' (shipped: "]),
    (["generate", "robot-stack", "--param", "robot=r2d2", "--out", "{d}"], ["robot 'r2d2' is not in the installed"]),
], ids=["family", "param name", "int", "float", "bool", "syntax", "rank", "rank type", "seeds", "out",
        "robot-stack stack", "robot-stack robot"])
def test_generate_user_errors(capsys, tmp_path, argv, fragments):
    (tmp_path / "f").write_text("a file")
    code, _, err = run(capsys, *[a.format(d=tmp_path, file=tmp_path / "f") for a in argv])
    assert_user_error(code, err, *fragments)


# ----------------------------------------------------------------- inspect
def test_inspect_table(capsys, problem):
    code, out, _ = run(capsys, "inspect", problem[1])
    assert code == 0
    lines = out.splitlines()
    assert lines[0].endswith("n = 2, depth = 2, rows = 3 (2 equality, 1 inequality, 0 free), total rank = 2")
    assert lines[1].split() == ["level", "name", "rows", "eq", "1-sided", "2-sided", "free", "rank", "cond",
                                "proj", "rank", "proj", "sv", "min", "proj", "cond", "conflicts"]
    # level 0: 2 rows (1 eq, 1 one-sided), rank 2; level 1: x0 = 3, rank 1, decided above: conflicts 1
    assert lines[2].split()[:2] == ["0", "reach"] and lines[2].split()[2:8] == ["2", "1", "1", "0", "0", "2"]
    assert lines[3].split()[-5:] == ["1", "0", "-", "-", "1"]
    # (the problem has an inequality row: the footer says its conflicts count it as active)
    assert lines[-1].startswith("(inequality rows above a level count as active there")


def test_inspect_json(capsys, problem):
    code, out, _ = run(capsys, "inspect", problem[1], "--json")
    assert code == 0
    res = json.loads(out)
    assert (res["n"], res["depth"], res["rows"]) == (2, 2, 3)
    assert [L["conflicts"] for L in res["levels"]] == [0, 1]
    assert res["levels"][1]["projected_cond"] is None


# ------------------------------------------------------------------ export
def test_export_soth_and_back(capsys, problem, tmp_path):
    h, path = problem
    code, out, _ = run(capsys, "export", path, "--format", "soth")
    assert code == 0 and out.strip() == str(tmp_path / "p.soth")
    code, out, _ = run(capsys, "export", out.strip(), "--format", "npz", "--out", str(tmp_path / "q.npz"))
    assert code == 0
    back = load(tmp_path / "q.npz")
    np.testing.assert_array_equal(back.A, h.A)  # equalities already first in each level
    np.testing.assert_array_equal(back.upper, h.upper)


def test_export_to_stdout(capsys, problem):
    code, out, _ = run(capsys, "export", problem[1], "--format", "soth", "--out", "-")
    assert code == 0 and out.startswith("variable size 2\n") and out.rstrip().endswith("end")


@pytest.mark.parametrize("argv, fragments", [
    (["export", "{path}", "--format", "npz"], ["is the input file"]),
    (["export", "{path}", "--format", "npz", "--out", "{d}/x.txt"], ["must end in .npz"]),
    (["export", "{path}", "--format", "soth", "--out", "{d}/x.npz"], ["must not end in .npz"]),
    (["export", "{path}", "--format", "npz", "--out", "-"], ["only for --format soth"]),
    (["export", "{path}", "--format", "soth", "--out", "{d}/no/x.soth"], ["cannot write"]),
    (["export", "{huge}", "--format", "soth"], [("{huge}: cannot be written as SOTH text: level 0, row 0: finite "
                                                "lower bound -1e+30 has magnitude >= 1e+25")]),
], ids=["overwrite input", "npz extension", "soth extension", "stdout npz", "missing dir", "bound beyond 1e25"])
def test_export_user_errors(capsys, problem, tmp_path, argv, fragments):
    huge = tmp_path / "huge.npz"
    save_npz(Hierarchy(np.eye(2), [-1e30, 0.0], [1.0, 1.0], [0, 0]), huge)
    code, _, err = run(capsys, *[a.format(path=problem[1], d=tmp_path, huge=huge) for a in argv])
    fragments = [f.format(huge=huge) for f in fragments]
    assert_user_error(code, err, *fragments)


# -------------------------------------------------------------------- list
@pytest.mark.parametrize("what, expected", [("solvers", "yardstick"), ("families", "ik-like"), ("robots", "talos")],
                         ids=["solvers", "families", "robots"])
def test_list(capsys, what, expected):
    code, out, _ = run(capsys, "list", what)
    assert code == 0
    assert any(line.split()[0] == expected for line in out.splitlines())


def test_list_families_shows_every_family(capsys):
    _, out, _ = run(capsys, "list", "families")
    assert [line.split()[0] for line in out.splitlines()] == [*FAMILIES, "robot-stack", "testset", "hard"] \
        == list(all_families())


# ------------------------------------------------------------ usage errors
@pytest.mark.parametrize("argv, fragment", [
    ([], "the following arguments are required: COMMAND"),
    (["frobnicate"], "invalid choice: 'frobnicate'"),
    (["solve"], "the following arguments are required: file"),
    (["solve", "p.npz", "--bogus"], "unrecognized arguments: --bogus"),
    (["solve", "p.npz", "--repeat", "many"], "argument --repeat: invalid int value: 'many'"),
    (["export", "p.npz", "--format", "csv"], "argument --format: invalid choice: 'csv'"),
    (["list", "planets"], "cannot list 'planets'"),
    (["run", "--suite", "quick", "--sol", "hcod"], "unrecognized arguments: --sol hcod"),
    (["solve", "p.npz", "--rep", "3"], "unrecognized arguments: --rep 3"),
], ids=["no command", "unknown command", "missing file", "unknown option", "bad int", "bad choice", "list",
        "no abbreviation of --solvers", "no abbreviation of --repeat"])
def test_usage_errors_exit_2_with_one_line(capsys, argv, fragment):
    """docs/cli.md, "Exit codes": `hikbench COMMAND: error: ...`, pointing at that command's --help."""
    code, _, err = run(capsys, *argv)
    assert_user_error(code, err, fragment)
    prog = "hikbench" if not argv or argv[0] not in COMMANDS else f"hikbench {argv[0]}"
    assert err.startswith(f"{prog}: error: "), err
    assert "--help" not in err or err.rstrip().endswith(f"(see `{prog} --help`)"), err  # (argparse's)


@pytest.mark.parametrize("flags", [["--solvers", "hcod", "yardstick"], ["--solver", "hcod", "--solver", "yardstick"],
                                   ["--solvers", "hcod", "--solvers", "yardstick"]],
                         ids=["one-list", "repeated-solver", "repeated-solvers"])
def test_run_takes_every_solver_of_repeated_flags(flags):
    """`hikbench run --solver a --solver b` runs both, as `scenario --solver` does (no flag
    silently replacing the one before)."""
    from hikbench.bench.cli import build_parser

    args = build_parser().parse_args(["run", "--suite", "quick", *flags])
    assert args.solvers == ["hcod", "yardstick"]


@pytest.mark.parametrize("argv", [["--help"]] + [[c, "--help"] for c in COMMANDS], ids=["main", *COMMANDS])
def test_help_exits_0(capsys, argv):
    code, out, _ = run(capsys, *argv)
    assert code == 0 and "usage: hikbench" in out


def test_export_notes_what_soth_loses(capsys, tmp_path):
    h = Hierarchy.from_levels([Level([[1.0, 0.0], [0.0, 1.0]], [-INF, 1.0], [INF, 1.0], "named"),
                               Level(np.zeros((0, 2)), [], [])], x0=[0.0, 1.0])
    save_npz(h, tmp_path / "h.npz")
    code, _, err = run(capsys, "export", str(tmp_path / "h.npz"), "--format", "soth")
    assert code == 0
    assert err == ("hikbench export: note: level names are dropped; x0 is dropped; rows are reordered "
                   "(equality rows first in each level); 1 free row(s), which SOTH's own reader refuses; "
                   "empty level(s), which SOTH's own reader refuses\n")


def test_export_notes_bounds_soth_drops(capsys, tmp_path):
    """SOTH reads an inequality bound beyond +-1e10 as no bound; an equality target is not thresholded, so it is not noted."""
    h = Hierarchy([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]], [0.0, -5e11, 3e12], [5e10, 1.0, 3e12], [0, 0, 1])
    save_npz(h, tmp_path / "b.npz")
    code, out, err = run(capsys, "export", str(tmp_path / "b.npz"), "--format", "soth", "--out", "-")
    assert code == 0 and "5e10" not in out and "50000000000.0" in out
    assert err == ("hikbench export: note: 2 finite inequality bound(s) beyond +-1e+10, "
                   "which SOTH's own reader takes as no bound\n")


SLOW_WARMUP = '''
import time
from doubles import SleepSolver


class SlowWarmup(SleepSolver):
    def warmup(self):
        time.sleep(3.0)
'''


@pytest.mark.parametrize("cls, note", [("SlowWarmup", True), ("SleepSolver", False)], ids=["slow", "quick"])
def test_solve_notes_a_long_warm_up(capsys, tmp_path, monkeypatch, cls, note):
    """hcod's first solve in a fresh process compiles for about 70 s: not in silence."""
    from doubles import tiny

    from hikbench.bench.commands import solve

    monkeypatch.setattr(solve, "NOTE_AFTER_S", 1.0)  # (the worker's import of slow.py and first solve: < 1 s)
    (tmp_path / "slow.py").write_text(SLOW_WARMUP)
    save_npz(tiny(), tmp_path / "eq.npz")
    code, _, err = run(capsys, "solve", tmp_path / "eq.npz", "--solver", f"{tmp_path / 'slow.py'}:{cls}")
    assert code == 0, err
    assert ("preparing its first solve in a fresh worker process" in err) == note, err
