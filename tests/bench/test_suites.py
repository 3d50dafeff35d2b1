"""Suites: built-in TOML files parse and generate; solver patterns, settings,
modes and skipped solvers expand as documented in bench/suites/__init__.py."""

import textwrap

import pytest
from doubles import spec, write_suite

from hikbench.bench.suites.problemset import ProblemSpec, file_stem, generate
from hikbench.bench.suites import SuiteError, builtin_suites, expand, load_suite, suite_from_dict


@pytest.mark.parametrize("name", sorted(builtin_suites()), ids=str)
def test_builtin_suites_generate(name):
    suite = load_suite(name)
    problems = suite.problems()
    assert problems and suite.description
    ids = [p.id for p, _ in problems]
    assert len(ids) == len(set(ids))
    for p, _ in problems[:: max(1, len(problems) // 12)]:  # a sample: every family's parameters are accepted
        h = generate(p)
        assert h.n == p.params.get("n", h.n)


def test_quick_and_paper_cover_what_they_promise():
    quick = {p.family for p, _ in load_suite("quick").problems()}
    assert {"equality", "ik-like", "degenerate"} <= quick
    paper = [p for p, _ in load_suite("paper").problems()]
    assert any(p.params.get("n") == 36 and p.params.get("depth") == 6 and p.params.get("rows") == 6 for p in paper)
    assert any(p.params.get("n") == 50 for p in paper)
    depths = {p.params["depth"] for p in paper if p.params.get("n") == 30}
    assert len([d for d in depths if d * 6 >= 30]) >= 3  # past saturation
    assert "soth" in load_suite("peers").export


def test_generation_is_deterministic():
    p = ProblemSpec("equality", {"n": 8, "depth": 2, "rows": 3}, seed=4)
    a, b = generate(p), generate(p)
    assert (a.A == b.A).all() and (a.lower == b.lower).all()
    assert p.id == "equality/depth=2,n=8,rows=3/seed=4"
    assert "/" not in file_stem(p.id)


def test_expand_modes_settings_and_skips(tmp_path):
    path = write_suite(tmp_path / "s.toml", ["yardstick", spec("SleepSolver"), "nomatch-*"], grid={"n": [4]})
    path.write_text(path.read_text() + '\n[[settings]]\nsolver = "sleep"\nname = "slow"\noptions = { delay = 0.1 }\n')
    tasks, skipped = expand(load_suite(str(path)))
    got = sorted((t.entry.solver, t.entry.settings, t.mode) for t in tasks)
    assert got == [("sleep", "default", "cold"), ("sleep", "default", "warm"),
                   ("sleep", "slow", "cold"), ("sleep", "slow", "warm"),
                   ("yardstick", "default", "cold")]  # no warm start: no warm row
    assert skipped == {"nomatch-*": "pattern matches no installed solver"}
    tasks, _ = expand(load_suite(str(path)), solver_patterns=["yardstick"])
    assert {t.entry.solver for t in tasks} == {"yardstick"}


@pytest.mark.parametrize("data, match", [
    ({"problems": []}, "problems = \\[\\]: expected \\[\\[problems\\]\\] tables \\(at least one\\)"),
    ({"problems": [{"grid": {}}]}, "problems\\[0\\]: missing key 'family'"),
    ({"problems": [{"family": "equality", "bogus": 1}]}, "unknown key"),
    ({"modes": ["hot"], "problems": [{"family": "equality"}]}, "modes\\[0\\] = 'hot': expected one of 'cold', 'warm'"),
    ({"accuracy": "ultra", "problems": [{"family": "equality"}]}, "accuracy = 'ultra': expected one of 'high'"),
    ({"repeats": 3, "problems": [{"family": "equality"}]}, "unknown key"),
    ({"repeat": "abc", "problems": [{"family": "equality"}]}, "repeat = 'abc': expected an integer >= 1"),
    ({"problems": [{"family": "equality", "seeds": 3}]}, "seeds = 3: expected a non-empty list of integers"),
    ({"rounds": 0, "problems": [{"family": "equality"}]}, "rounds = 0: expected an integer >= 1"),
    ({"repeat": 3, "rounds": 4, "problems": [{"family": "equality"}]},
     "rounds = 4: expected at most repeat = 3 \\(each round times at least one solve of every row\\)"),
    ({"problems": [{"family": "equality", "params": {"n": 12}, "grid": {"n": [6, 12]}}]},
     "'n' is in both params \\(12\\) and grid \\(\\[6, 12\\]\\): expected it in one of them"),
], ids=["no-problems", "no-family", "group-key", "mode", "accuracy", "top-key", "repeat", "seeds", "rounds-0",
        "rounds-over-repeat", "params-and-grid"])
def test_bad_suites(data, match):
    with pytest.raises(SuiteError, match=match):
        suite_from_dict(data, "bad")


def test_settings_of_a_solver_the_suite_does_not_run_are_an_error():
    """A [[settings]] for an installed solver missing from the suite's solvers was dropped
    without a word (the user forgot to add the solver). With --solvers the settings of the
    solvers left out are expected to go."""
    suite = suite_from_dict({"solvers": ["yardstick"], "problems": [{"family": "equality"}],
                             "settings": [{"solver": "cascade-osqp", "name": "low",
                                           "options": {"accuracy": "low"}}]}, "mine")
    with pytest.raises(SuiteError, match="\\[\\[settings\\]\\] 'low': solver 'cascade-osqp' is not one of "
                                         "the suite's solvers \\(yardstick\\)"):
        expand(suite)
    assert {t.entry.solver for t in expand(suite, solver_patterns=["yardstick"])[0]} == {"yardstick"}


def test_unknown_solver_is_an_error_listing_the_known_ones():
    from hikbench.bench.suites import resolve_solvers
    from hikbench.solvers.errors import SolverNotFoundError

    with pytest.raises(SolverNotFoundError, match=r"unknown solver 'no-such-solver' \(in the suite\); "
                                                  r"known solvers: .*hcod.*yardstick"):
        resolve_solvers(["yardstick", "no-such-solver"])


def test_unknown_family_names_the_known_ones():
    from hikbench.problems.errors import UnknownFamilyError
    with pytest.raises(UnknownFamilyError, match="equality"):
        generate(ProblemSpec("nope", {}, 0))


def test_relative_py_paths_resolve_next_to_the_suite(tmp_path):
    import shutil
    from pathlib import Path

    shutil.copy(Path(__file__).with_name("doubles.py"), tmp_path / "mydoubles.py")
    (tmp_path / "s.toml").write_text('solvers = ["mydoubles.py:SleepSolver"]\n'
                                     '[[problems]]\nfamily = "mydoubles.py:tiny"\ngrid = { n = [4] }\n')
    tasks, skipped = expand(load_suite(str(tmp_path / "s.toml")))
    assert not skipped and [t.entry.solver for t in tasks] == ["sleep"]
    assert tasks[0].problem.id == "mydoubles.py:tiny/n=4/seed=0"
    assert generate(tasks[0].problem).n == 4


def test_robot_stacks_are_a_family_by_name(tmp_path):
    """`family = "robot-stack"` (docs/robots.md: the robot stacks' family for the harness) was an unknown
    family; a user's stack file is a value of its `stack` parameter."""
    from hikbench.bench.cli import main
    from hikbench.bench.harness.results import read_results
    from hikbench.problems.robots.testsets import stack_problem

    stack = tmp_path / "arm.toml"
    stack.write_text('name = "arm"\nrobot = "ur5"\ndt = 0.02\n[[levels]]\ntasks = [{ type = "joint_limits" }]\n'
                     '[[levels]]\ntasks = [{ type = "position", frame = "ee", target = [0.3, 0.3, 0.3] }]\n'
                     '[[levels]]\ntasks = [{ type = "posture" }]\n')
    (tmp_path / "s.toml").write_text(
        'solvers = ["hcod"]\nrepeat = 2\nmodes = ["cold"]\n[[problems]]\nfamily = "robot-stack"\n'
        f'grid = {{ stack = ["arm_reach", "{stack}"] }}\nparams = {{ robot = "ur5" }}\nseeds = [0]\n')
    tasks, skipped = expand(load_suite(str(tmp_path / "s.toml")))
    assert not skipped and len(tasks) == 2
    assert generate(tasks[0].problem) == stack_problem("arm_reach", 0, robot="ur5")
    assert main(["run", "--quiet", "--suite", str(tmp_path / "s.toml"), "--out", str(tmp_path / "out")]) == 0
    df = read_results(tmp_path / "out")
    assert len(df) == 2 and df["verified"].all() and set(df["n"]) == {6}


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
