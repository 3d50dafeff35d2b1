"""Solver spellings are parsed once (bench/specs.py): each spelling gets its kind from the
text alone, and a bad one is the one-line error naming it that ``hikbench run`` and
``hikbench solve`` print."""

from __future__ import annotations

import pytest
from clitools import assert_user_error, run
from doubles import HERE, SleepSolver, spec, tiny

from hikbench.bench.specs import (
    CONTROLLER,
    EXTERNAL,
    OBJECT,
    PATTERN,
    REGISTRY,
    SolverSpec,
    SolverSpecError,
    located,
    warm_start_modes,
)
from hikbench.bench.suites import SuiteError, resolve_solvers
from hikbench.problems.errors import HikbenchError
from hikbench.solvers import registry
from hikbench.solvers.errors import SolverNotFoundError
from hikbench.solvers.hcod import HcodSolver

OUT = "{out}"
SPELLINGS = {  # text -> (kind, text after parsing, name of its rows or None)
    "registry": ("hcod", REGISTRY, "hcod", "hcod"),
    "alias": ("reference", REGISTRY, "yardstick", "yardstick"),
    "glob-star": ("cascade-*", PATTERN, "cascade-*", "cascade-*"),
    "glob-question": ("nullspace-?vd", PATTERN, "nullspace-?vd", "nullspace-?vd"),
    "glob-brackets": ("[hc]cod", PATTERN, "[hc]cod", "[hc]cod"),
    "module-class": ("hikbench.solvers.hcod:HcodSolver", OBJECT, "hikbench.solvers.hcod:HcodSolver",
                     "hikbench.solvers.hcod:HcodSolver"),
    "file-class": (spec("SleepSolver"), OBJECT, spec("SleepSolver"), spec("SleepSolver")),
    "module-glob-is-object": ("pkg.mod:Cls*", OBJECT, "pkg.mod:Cls*", "pkg.mod:Cls*"),
    "external": (f"external:p=true {OUT}", EXTERNAL, f"external:p=true {OUT}", "external:p"),
    "external-not-strict": (f"external:q[strict=false]=true {{problem}} {OUT}", EXTERNAL,
                            f"external:q[strict=false]=true {{problem}} {OUT}", "external:q"),
    "controller-outside-scenario": ("pink", REGISTRY, "pink", "pink"),
}


@pytest.mark.parametrize("text, kind, parsed, name", SPELLINGS.values(), ids=list(SPELLINGS))
def test_every_spelling_gets_its_kind_from_the_text(text, kind, parsed, name):
    s = SolverSpec.parse(text)
    assert (s.kind, s.text, s.name, str(s)) == (kind, parsed, name, parsed)
    assert (s.external is not None) == (kind == EXTERNAL)


def test_a_controller_is_one_where_controllers_are_taken():
    assert SolverSpec.parse("pink", controllers=True).kind == CONTROLLER
    assert SolverSpec.parse("hcod", controllers=True).kind == REGISTRY


@pytest.mark.parametrize("text, strict", [(f"external:p=true {OUT}", True),
                                          (f"external:p[strict=true]=true {OUT}", True),
                                          (f"external:p[strict=false]=true {OUT}", False)],
                         ids=["default", "strict-true", "strict-false"])
def test_an_external_spelling_holds_its_claim_and_command(text, strict):
    ext = SolverSpec.parse(text).external
    assert (ext.name, ext.strict, ext.command) == ("p", strict, f"true {OUT}")


def test_a_pattern_matches_registry_names_in_their_order():
    names = ["hcod", "cascade-osqp", "cascade-daqp", "yardstick"]
    assert SolverSpec.parse("cascade-*").matches(names) == ["cascade-osqp", "cascade-daqp"]
    assert SolverSpec.parse("x*").matches(names) == []


def test_info_builds_registry_names_and_objects():
    assert SolverSpec.parse("hcod").info() is registry.get("hcod")
    assert SolverSpec.parse("hikbench.solvers.hcod:HcodSolver").info().factory is HcodSolver
    info = SolverSpec.parse(spec("SleepSolver")).info("sleep")
    assert info.name == "sleep" and info.factory.__name__ == SleepSolver.__name__
    assert callable(getattr(SolverSpec.parse("hcod").factory({})(), "solve", None))


def test_a_relative_file_is_located_against_a_folder_or_the_current_directory(tmp_path, monkeypatch):
    (tmp_path / "mine.py").write_text("")
    assert located("mine.py:Cls", tmp_path) == f"{tmp_path / 'mine.py'}:Cls"
    assert located("other.py:Cls", tmp_path) == "other.py:Cls"  # (not there: left for its error)
    assert located("hcod", tmp_path) == "hcod"
    assert located(f"external:p=./mine.py {OUT}", tmp_path) == f"external:p=./mine.py {OUT}"
    monkeypatch.chdir(tmp_path)
    assert SolverSpec.parse("mine.py:Cls").located().text == f"{tmp_path / 'mine.py'}:Cls"
    assert SolverSpec.parse(f"{HERE}:X").located().text == f"{HERE}:X"


BAD_EXTERNAL = {  # text -> what its error says (after the text)
    "no-name": (f"external:=true {OUT}", "expected external:NAME=CMD"),
    "no-command": ("external:p=", "expected external:NAME=CMD"),
    "no-out": ("external:p=true {problem}", "CMD must contain the placeholder {out}"),
    "misspelt-placeholder": (f"external:p=true {{problm}} {OUT}", "unknown placeholder {problm} (did you mean "
                                                                   "{problem}?)"),
    "open-quote": (f"external:p=true '{OUT}", "cannot be split like a shell command line"),
    "no-program": (f"external:p=no-such-program-here {OUT}", "program 'no-such-program-here' is not found on PATH"),
    "bad-strict": (f"external:p[strict=no]=true {OUT}", "strict=no: expected strict=true"),
    "unclosed": (f"external:p[strict=false=true {OUT}", "no ']=' after the declaration"),
}


@pytest.mark.parametrize("text, says", BAD_EXTERNAL.values(), ids=list(BAD_EXTERNAL))
def test_a_bad_external_spelling_is_an_error_naming_it(text, says):
    with pytest.raises(SolverSpecError) as err:
        SolverSpec.parse(text)
    assert str(err.value).startswith(f"{text!r}: ") and says in str(err.value)
    with pytest.raises(SuiteError) as err:
        resolve_solvers([text], where="--solvers")
    assert str(err.value).startswith(f"--solvers: {text!r}: ") and says in str(err.value)


BAD_OBJECTS = {  # text -> what SolverSpec.info's error says
    "no-module": (":HcodSolver", "expected 'module:attribute' or 'file.py:attribute'"),
    "no-attribute": ("hikbench.solvers.hcod:", "expected 'module:attribute' or 'file.py:attribute'"),
    "unknown-module": ("no_such_module_x:Cls", "cannot import module 'no_such_module_x'"),
    "unknown-attribute": ("hikbench.solvers.hcod:NoSuchSolver", "module 'hikbench.solvers.hcod' has no "
                                                                "attribute 'NoSuchSolver'"),
    "no-file": ("no_such_dir/mine.py:Cls", "no such file no_such_dir/mine.py"),
    "not-a-solver": (spec("HERE"), "is not a solver: expected a class with a solve(hierarchy) method"),
}


@pytest.mark.parametrize("text, says", BAD_OBJECTS.values(), ids=list(BAD_OBJECTS))
def test_an_object_that_cannot_be_built_is_an_error_naming_it(text, says):
    s = SolverSpec.parse(text)  # (the text alone: imported where it is built)
    assert s.kind == OBJECT
    with pytest.raises(HikbenchError) as err:
        s.info()
    assert str(err.value).startswith(repr(text)) and says in str(err.value)


@pytest.mark.parametrize("text", ["no-such-solver", "hcdo", "nosuch-*"], ids=["unknown", "misspelt", "pattern"])
def test_an_unknown_registry_name_names_the_known_solvers(text):
    with pytest.raises(SolverNotFoundError) as err:
        SolverSpec.parse(text).info()
    assert f"unknown solver {text!r}" in str(err.value) and "found solvers: " in str(err.value)
    if text == "hcdo":
        assert "did you mean 'hcod'?" in str(err.value)


@pytest.mark.parametrize("text", [f"external:p=true {OUT}", "pink"], ids=["external", "controller"])
def test_a_spelling_without_a_solver_object_has_no_info(text):
    s = SolverSpec.parse(text, controllers=True)
    with pytest.raises(HikbenchError, match="is no solver object .+: expected a registry name or module:Class"):
        s.info()


CLI_ERRORS = {  # --solvers TEXT -> what the one line says
    "unknown": ("no-such-solver", "unknown solver 'no-such-solver' (in --solvers)"),
    "misspelt": ("hcdo", "did you mean 'hcod'?"),
    "no-out": ("external:p=true {problem}", "--solvers: 'external:p=true {problem}': CMD must contain the "
                                            "placeholder {out}"),
    "no-program": (f"external:p=no-such-program-here {OUT}", "is not found on PATH"),
    "unknown-module": ("no_such_module_x:Cls", "cannot import module 'no_such_module_x'"),
    "not-a-solver": (spec("HERE"), "is not a solver"),
}


@pytest.mark.parametrize("text, says", CLI_ERRORS.values(), ids=list(CLI_ERRORS))
def test_a_bad_solver_on_the_command_line_is_one_line(tmp_path, capsys, text, says):
    code, _, err = run(capsys, "run", "--quiet", "--suite", "quick", "--out", tmp_path / "out", "--solvers", text)
    assert_user_error(code, err, says)
    assert not (tmp_path / "out").exists()


def test_solve_refuses_an_external_program_in_one_line(tmp_path, capsys):
    from hikbench.problems.files import save_npz

    save_npz(tiny(), tmp_path / "p.npz")
    code, _, err = run(capsys, "solve", tmp_path / "p.npz", "--solver", f"external:p=true {OUT}")
    assert_user_error(code, err, "an external program is no solver object (`hikbench run --solvers` runs it)")
    code, _, err = run(capsys, "solve", tmp_path / "p.npz", "--solver", "external:p=true {problem}")
    assert_user_error(code, err, "'external:p=true {problem}': CMD must contain the placeholder {out}")


class _Warm:
    """A module:Class solver with the HCOD warm-start option."""

    def __init__(self, warm_start="stage"):
        self.warm_start = warm_start

    def solve(self, h):  # pragma: no cover - never called
        raise AssertionError


WARM = {  # (solver, asked, option) -> modes
    "hcod-default": ("hcod", (), None, ["time"]),
    "hcod-asked": ("hcod", ("none", "stage"), None, ["none", "stage"]),
    "hcod-option": ("hcod", (), "stage", ["stage"]),
    "hcod-asked-over-option": ("hcod", ("none",), "stage", ["none"]),
    "no-option": ("nullspace-svd", ("time",), "time", [None]),
    "class-default": ("class", (), None, ["stage"]),
}


@pytest.mark.parametrize("solver, asked, option, modes", WARM.values(), ids=list(WARM))
def test_warm_start_modes(solver, asked, option, modes):
    info = (registry.SolverInfo("warm", "", _Warm) if solver == "class" else registry.get(solver))
    assert warm_start_modes(info, asked, option) == modes


def test_a_warm_start_parameter_without_default_is_an_error():
    def factory(warm_start):  # pragma: no cover - never called
        raise AssertionError

    with pytest.raises(HikbenchError, match="its warm_start parameter has no default value"):
        warm_start_modes(registry.SolverInfo("nodefault", "", factory))
