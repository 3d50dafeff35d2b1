"""Problem files and yardsticks are keyed by the problem's content
(bench/harness/cache.py): a suite run again after a family's parameters or a
user family's output changed under the same problem id writes its problem
files again, computes new yardsticks and runs its finished rows again; an
unchanged suite reuses them; a yardstick of other code is computed again."""

from __future__ import annotations

import dataclasses
import hashlib
import json

import numpy as np
import pytest
import tomli_w
from clitools import run
from doubles import spec, tiny

from hikbench.bench.harness import cache, yardstick
from hikbench.bench.harness.results import read_results
from hikbench.problems import generators
from hikbench.problems.files import load_npz
from hikbench.problems.hierarchy import Hierarchy, Level

# a user family whose output depends on a file beside it: same id, other rows when the file changes
USER_FAMILY = '''
from pathlib import Path
import numpy as np
from hikbench.problems.hierarchy import Hierarchy, Level

def scaled(seed=0):
    s = float(Path(__file__).with_name("scale.txt").read_text())
    rng = np.random.default_rng(seed)
    return Hierarchy.from_levels([Level.equality(s * rng.standard_normal((2, 4)), rng.standard_normal(2))
                                  for _ in range(2)])
'''


def _suite(path, family: str, params=None):
    group = {"family": family, "seeds": [0]} | ({"params": params} if params else {})
    path.write_text(tomli_w.dumps({"repeat": 1, "warmup": 0, "timeout": 20.0, "first_solve_timeout": 20.0,
                                   "modes": ["cold"], "solvers": [spec("SleepSolver")], "problems": [group]}))
    return path


def _run(capsys, suite, out):
    code, _, err = run(capsys, "run", "--quiet", "--suite", suite, "--out", out)
    assert code == 0 and "Traceback" not in err, err
    return err


def _state(out):
    """(problem file bytes, {yardstick file name: bytes}, rows)."""
    [problem] = (out / "problems").glob("*.npz")
    ysticks = {p.name: p.read_bytes() for p in (out / "yardstick").glob("*.npz")}
    return problem.read_bytes(), ysticks, read_results(out)


def _check_changed(err, before, after, out):
    """The second run rewrote the problem file, computed a new yardstick and ran the row again."""
    assert after[0] != before[0]
    assert "1 problem file(s)" in err and "their content changed" in err, err
    assert "1 finished row(s) run again: their problem's content changed" in err, err
    new = set(after[1]) - set(before[1])
    assert len(new) == 1, (before[1].keys(), after[1].keys())
    rows = after[2]
    assert len(rows) == 1 and rows["verified"].tolist() == [True]
    assert f"{rows['problem_hash'].iloc[0]}.npz" == new.pop()
    assert rows["problem_hash"].iloc[0] != before[2]["problem_hash"].iloc[0]
    h = load_npz(next((out / "problems").glob("*.npz")))
    assert cache.problem_hash(h) == rows["problem_hash"].iloc[0]
    np.testing.assert_allclose(json.loads(rows["level_norms"].iloc[0]), json.loads(rows["ref_level_norms"].iloc[0]),
                               rtol=1e-9, atol=1e-12)


def test_a_changed_builtin_family_gets_new_files_and_rows(tmp_path, capsys, monkeypatch):
    suite, out = _suite(tmp_path / "s.toml", "equality", {"n": 5}), tmp_path / "out"
    _run(capsys, suite, out)
    before = _state(out)
    fam = generators.FAMILIES["equality"]  # a new version of the family: another default, the same ids
    changed = dataclasses.replace(fam, defaults={k: v for k, v in fam.defaults.items() if k != "bound_scale"}
                                  | {"rows": fam.defaults["rows"] + 1})
    monkeypatch.setitem(generators.FAMILIES, "equality", changed)
    err = _run(capsys, suite, out)
    after = _state(out)
    assert after[2]["problem"].tolist() == before[2]["problem"].tolist()  # same id
    _check_changed(err, before, after, out)


def test_a_user_family_whose_output_changed_gets_new_files_and_rows(tmp_path, capsys):
    (tmp_path / "fam.py").write_text(USER_FAMILY)
    (tmp_path / "scale.txt").write_text("1.0")
    suite, out = _suite(tmp_path / "s.toml", f"{tmp_path / 'fam.py'}:scaled"), tmp_path / "out"
    _run(capsys, suite, out)
    before = _state(out)
    (tmp_path / "scale.txt").write_text("3.0")
    err = _run(capsys, suite, out)
    _check_changed(err, before, _state(out), out)


def test_an_unchanged_suite_reuses_its_files_and_rows(tmp_path, capsys):
    suite, out = _suite(tmp_path / "s.toml", "equality", {"n": 5}), tmp_path / "out"
    _run(capsys, suite, out)
    before = _state(out)
    [ystick] = (out / "yardstick").glob("*.npz")
    mtime = ystick.stat().st_mtime_ns
    err = _run(capsys, suite, out)
    assert err == ""
    after = _state(out)
    assert after[0] == before[0] and after[1] == before[1] and ystick.stat().st_mtime_ns == mtime
    assert after[2]["finished_at"].tolist() == before[2]["finished_at"].tolist()


def test_a_yardstick_of_other_code_is_computed_again(tmp_path, capsys, monkeypatch):
    suite, out = _suite(tmp_path / "s.toml", "equality", {"n": 5}), tmp_path / "out"
    _run(capsys, suite, out)
    [ystick] = (out / "yardstick").glob("*.npz")
    monkeypatch.setattr(yardstick, "yardstick_code", lambda: "0123456789abcdef")
    code, _, err = run(capsys, "run", "--quiet", "--rerun", "--suite", suite, "--out", out)
    assert code == 0, err
    assert "1 cached yardstick(s) computed again: the yardstick's code changed" in err, err
    with np.load(ystick) as z:
        assert str(z["code"]) == "0123456789abcdef" and z["x"].shape == (5,)
    assert read_results(out)["verified"].tolist() == [True]


def _documented_hash(h: Hierarchy) -> str:
    """The layout of bench/harness/cache.py's docstring, written out again."""
    d = hashlib.sha256(b"hikbench-problem-v1")
    d.update(np.array([h.n, h.depth, len(h.A)], dtype="<i8").tobytes())
    d.update(np.asarray(h.A, "<f8").tobytes(order="C"))
    d.update(np.asarray(h.lower, "<f8").tobytes() + np.asarray(h.upper, "<f8").tobytes())
    d.update(np.asarray(h.level, "<i8").tobytes())
    return d.hexdigest()[:16]


@pytest.mark.parametrize("seed", [0, 1, 2], ids=["seed0", "seed1", "seed2"])
def test_the_problem_hash_is_the_documented_digest(seed):
    h = tiny(seed, n=5, depth=3)
    assert cache.problem_hash(h) == _documented_hash(h)


def _edits():
    base = Hierarchy.from_levels([Level([[1.0, 2.0], [0.0, 1.0]], [0.0, -np.inf], [0.0, 1.0]),
                                  Level.equality([[1.0, 0.0]], [3.0])])
    A = base.A.copy()
    A[0, 1] = np.nextafter(2.0, 3.0)  # one ulp
    upper = base.upper.copy()
    upper[1] = 2.0
    return base, {
        "A one ulp": Hierarchy(A, base.lower, base.upper, base.level),
        "an upper bound": Hierarchy(base.A, base.lower, upper, base.level),
        "a row moved to the next level": Hierarchy(base.A, base.lower, base.upper, np.array([0, 1, 1])),
        "an extra variable": Hierarchy(np.hstack([base.A, np.zeros((3, 1))]), base.lower, base.upper,
                                       base.level),
    }


@pytest.mark.parametrize("what", list(_edits()[1]), ids=list(_edits()[1]))
def test_any_change_of_the_arrays_changes_the_problem_hash(what):
    base, edited = _edits()
    assert cache.problem_hash(edited[what]) != cache.problem_hash(base)


def test_names_do_not_change_the_problem_hash():
    base, _ = _edits()
    named = Hierarchy(base.A, base.lower, base.upper, base.level, names=["a", "b"])
    assert cache.problem_hash(named) == cache.problem_hash(base)


def test_the_yardstick_code_follows_its_sources(tmp_path, monkeypatch):
    (tmp_path / "ystick_a.py").write_text("X = 1\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    first = cache.yardstick_code(("ystick_a",))
    assert cache.yardstick_code(("ystick_a",)) == first
    (tmp_path / "ystick_a.py").write_text("X = 2\n")
    assert cache.yardstick_code(("ystick_a",)) != first
    assert len(cache.yardstick_code()) == 16
