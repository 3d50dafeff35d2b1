"""A damaged file under OUT/ (a cached yardstick, a problem file) does not crash
the next run on that OUT: it is computed or written again, which one line on
stderr says (bench/harness/runner.py, bench/suites/problemset.py)."""

from __future__ import annotations

import numpy as np
import pytest
from clitools import run
from doubles import spec, write_suite

from hikbench.bench.harness.results import read_results
from hikbench.problems.files import load_npz


def _first_run(tmp_path, capsys):
    suite = write_suite(tmp_path / "s.toml", [spec("SleepSolver")], grid={"n": [4], "depth": [1]}, repeat=1,
                        modes=("cold",))
    out = tmp_path / "out"
    assert run(capsys, "run", "--quiet", "--suite", suite, "--out", out)[0] == 0
    [ystick] = (out / "yardstick").glob("*.npz")
    [problem] = (out / "problems").glob("*.npz")
    return suite, out, ystick, problem


def _rerun(capsys, suite, out):
    code, _, err = run(capsys, "run", "--quiet", "--rerun", "--suite", suite, "--out", out)
    assert code == 0 and "Traceback" not in err, err
    return err


@pytest.mark.parametrize("damage", [b"", b"PK\x03\x04 cut short", b"not a zip at all"],
                         ids=["empty", "truncated zip", "garbage"])
def test_a_damaged_cached_yardstick_is_computed_again(tmp_path, capsys, damage):
    suite, out, ystick, _ = _first_run(tmp_path, capsys)
    ystick.write_bytes(damage)
    err = _rerun(capsys, suite, out)
    lines = [ln for ln in err.splitlines() if str(ystick) in ln]
    assert len(lines) == 1 and "cannot be read" in lines[0] and "computing the yardstick again" in lines[0], err
    with np.load(ystick) as z:
        assert z["x"].shape == (4,) and str(z["status"]) == "optimal"
    assert read_results(out)["verified"].tolist() == [True]


def test_a_cached_yardstick_of_another_size_is_computed_again(tmp_path, capsys):
    suite, out, ystick, _ = _first_run(tmp_path, capsys)
    with np.load(ystick) as z:
        key = {k: str(z[k]) for k in ("problem_hash", "code")}
    with open(ystick, "wb") as f:
        np.savez(f, x=np.zeros(7), status="optimal", reason="", **key)
    err = _rerun(capsys, suite, out)
    assert "expected float64 of shape (4,)" in err, err
    assert read_results(out)["verified"].tolist() == [True]


@pytest.mark.parametrize("damage", [b"", b"PK\x03\x04 cut short", b"not a zip at all", None],
                         ids=["empty", "truncated zip", "garbage", "cut after 100 bytes"])
def test_a_damaged_problem_file_is_written_again(tmp_path, capsys, damage):
    suite, out, _, problem = _first_run(tmp_path, capsys)
    problem.write_bytes(problem.read_bytes()[:100] if damage is None else damage)
    err = _rerun(capsys, suite, out)
    lines = [ln for ln in err.splitlines() if str(problem) in ln]
    assert len(lines) == 1 and "writing it again" in lines[0], err
    assert load_npz(problem).n == 4
