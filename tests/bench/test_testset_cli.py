"""`hikbench testset check|add` and `hikbench run` on a test set (docs/testset.md): the hash
check's exit codes, candidates certified from a user's file, a suite judged against the stored
optima, and a sequence solved in order on one object."""

from __future__ import annotations

import shutil

import numpy as np
import pandas as pd
import pytest
import tomli_w
from clitools import assert_user_error, run

from hikbench.problems.testset import TestSet, set_folder
from hikbench.solvers.yardstick import yardstick_solution
from hikbench.problems.verify import level_norms


def test_check_passes_on_the_shipped_set(capsys):
    code, out, err = run(capsys, "testset", "check")
    n = len(TestSet.read("hlsp-1"))
    assert code == 0 and f"hlsp-1: {n} problems, {n} files match the manifest's SHA-256" in out, out + err


def test_check_fails_on_a_changed_file(tmp_path, capsys):
    folder = tmp_path / "set"
    shutil.copytree(set_folder("hlsp-1"), folder)
    first = TestSet.read(folder).entries[0]
    data = bytearray((folder / first.file).read_bytes())
    data[-1] ^= 1
    (folder / first.file).write_bytes(bytes(data))
    code, out, err = run(capsys, "testset", "check", folder)
    assert code == 1 and first.id in err and "1 file(s) disagree" in out, out + err


def test_add_certifies_a_users_problem_file(tmp_path, capsys, problem):
    h, path = problem
    code, out, err = run(capsys, "testset", "add", path, "--out", tmp_path / "cand", "--workers", "1")
    assert code == 0 and "1 of 1 candidates certified" in out, out + err
    ts = TestSet.read(tmp_path / "cand")
    (e,) = ts.entries
    assert e.provenance["source"] == path and ts.check_hashes() == []
    np.testing.assert_allclose(e.level_norms, level_norms(h, yardstick_solution(h)), rtol=1e-12, atol=1e-12)


def test_add_names_a_missing_file(tmp_path, capsys):
    code, out, err = run(capsys, "testset", "add", tmp_path / "none.npz", "--out", tmp_path / "cand")
    assert_user_error(code, err, "none.npz: no such file")


def test_a_suite_on_the_set_is_judged_against_the_stored_optima(tmp_path, capsys):
    """Two problems of hlsp-1 and its first sequence, hcod only: every row's yardstick is the
    stored certified optimum, and hcod (time) meets the optimum at every step of the sequence."""
    ts = TestSet.read("hlsp-1")
    ids = [ts.entries[0].id, next(e.id for e in ts.entries if e.family.startswith("robot:"))]
    suite = tmp_path / "s.toml"
    suite.write_text(tomli_w.dumps({"repeat": 1, "modes": ["cold"], "solvers": ["hcod"], "sequences": ["hlsp-1"],
                                    "problems": [{"family": "testset", "params": {"set": "hlsp-1"},
                                                  "grid": {"problem": ids}}]}))
    code, out, err = run(capsys, "run", "--quiet", "--suite", suite, "--out", tmp_path / "out")
    assert code == 0, out + err
    df = pd.read_csv(tmp_path / "out" / "results.csv")
    assert len(df) == 2 and (df["yardstick"] == "certified").all() and df["verified"].all(), df.to_string()
    assert df["yardstick_reason"].str.contains("stored in test set hlsp-1").all()
    seq = pd.read_csv(tmp_path / "out" / "sequences.csv")
    assert len(seq) == len(ts.sequences) and (seq["status"] == "finished").all() and set(seq["warm_start"]) == {"time"}
    assert (seq["verified_steps"] == seq["steps"]).all(), seq.to_string()
    code, out, err = run(capsys, "report", tmp_path / "out")
    report = (tmp_path / "out" / "report.md").read_text()
    assert code == 0 and "## Sequences" in report, out + err
    for sid, ids in ts.sequences.items():
        assert f"| {sid} | hcod | time | {len(ids)}/{len(ids)} |" in report, sid


@pytest.mark.parametrize("spec", ["arm_reach", "arm_reach:"], ids=["no-colon", "no-robot"])
def test_a_bad_run_spec_is_one_line(capsys, spec):
    code, out, err = run(capsys, "testset", "build", "--parts", "robots", "--runs", spec, "--out", "/nonexistent")
    assert_user_error(code, err, f"--runs {spec!r}: expected SCENARIO:ROBOT")


def test_the_selected_steps_are_every_kth_the_changes_and_one_sequence():
    """60 steps, changes at 7, 8, 31, 33, 35, 41, 47: every 10th, the changes (at most 3 of
    those outside the sequence, spread evenly), and 10 consecutive steps from a fifth of them
    before the first change in the second half (31: from 29)."""
    from hikbench.bench.testset.record import Step, select_steps

    changed = {7, 8, 31, 33, 35, 41, 47}
    rec = [Step(k, None, None, k in changed) for k in range(60)]
    single, run = select_steps(rec, every=10, sequence=10)
    assert [s.step for s in run] == list(range(29, 39))
    assert [s.step for s in single] == [0, 7, 8, 10, 20, 40, 41, 47, 50]
    single, run = select_steps(rec, every=10, sequence=10, max_changes=3)
    assert [s.step for s in single] == [0, 7, 10, 20, 40, 41, 47, 50]


def test_add_reads_a_lexls_file_and_tries_its_solution_first(tmp_path, capsys):
    """x_0 + x_1 = 2 above x_0 = 3 (LexLS layout, #HierType 100): the file's #Solution (3, -1)
    is the optimum, certified from the given point."""
    p = tmp_path / "two.dat"
    p.write_text("#nVar\n2\n#nObj\n2\n#nCtr\n1 1\n#HierType\n100\n#ObjType\n200 200\n"
                 "#OBJECTIVE\n1 1 2\n#OBJECTIVE\n1 0 3\n#Solution\n3 -1\n")
    code, out, err = run(capsys, "testset", "add", p, "--out", tmp_path / "cand", "--workers", "1")
    assert code == 0 and "1 of 1 candidates certified" in out, out + err
    (e,) = TestSet.read(tmp_path / "cand").entries
    assert e.optimum["certified_from"] == "given" and e.provenance["format"] == "LexLS hierarchy text"
    np.testing.assert_array_equal(e.x, [3.0, -1.0])
    np.testing.assert_array_equal(e.level_norms, [0.0, 0.0])


def test_add_records_a_scenarios_steps_as_certified_candidates(tmp_path, capsys):
    """12 steps of arm_reach on panda: every 5th step, the active-set changes and a sequence of 4,
    each certified (from the controller's u or another point), the sequence's steps in order."""
    pytest.importorskip("pinocchio")
    code, out, err = run(capsys, "testset", "add", "--scenario", "arm_reach", "--robot", "panda", "--steps", "12",
                         "--every", "5", "--sequence", "4", "--out", tmp_path / "cand", "--workers", "1")
    assert code == 0, out + err
    ts = TestSet.read(tmp_path / "cand")
    assert len(ts) >= 6 and ts.check_hashes() == [] and all(e.family == "robot:arm_reach" for e in ts.entries)
    ((sid, ids),) = ts.sequences.items()
    steps = [ts.entry(pid).provenance["step"] for pid in ids]
    assert len(steps) == 4 and steps == list(range(steps[0], steps[0] + 4))
    assert {0, 5, 10} <= {e.provenance["step"] for e in ts.entries} | set(range(steps[0], steps[0] + 4))
