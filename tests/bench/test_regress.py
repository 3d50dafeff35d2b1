"""``hikbench regress``: the decision on paired rounds (synthetic runs), and the
command end to end on this checkout's HEAD as the base revision."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from hikbench.bench.analysis.regress import FAILING, decide, markdown, to_json
from hikbench.bench.cli import main
from tests.bench.doubles import spec

ROOT = Path(__file__).resolve().parents[2]
CASES = [("p1", "hcod", "default", "cold"), ("p1", "hcod", "default", "warm"), ("p2", "daqp", "default", "cold")]


def _frames(rounds: int, times: dict, noise: float, seed: int, verified=None) -> list[pd.DataFrame]:
    """``rounds`` results frames: each case's time_median_s = times[case] x lognormal(noise)."""
    rng = np.random.default_rng(seed)
    verified = verified or {}
    return [pd.DataFrame([{"problem": k[0], "solver": k[1], "settings": k[2], "mode": k[3],
                           "status": "optimal", "reason": "", "verified": verified.get(k, True),
                           "time_median_s": t * math.exp(noise * rng.standard_normal())}
                          for k, t in times.items()]) for _ in range(rounds)]


BASE_TIMES = {CASES[0]: 20e-6, CASES[1]: 12e-6, CASES[2]: 1e-3}


@pytest.mark.parametrize("seed", range(20), ids=lambda s: f"seed{s}")
def test_same_times_flag_nothing(seed):
    """A/A: both sides drawn from one distribution (5 % noise per round): no case fails."""
    dec = decide(_frames(6, BASE_TIMES, 0.05, seed), _frames(6, BASE_TIMES, 0.05, seed + 100))
    assert not dec.failed, markdown(dec, "")


@pytest.mark.parametrize("factor, verdict", [(1.4, "SLOWER"), (1.05, "ok"), (1 / 1.4, "faster")],
                         ids=["slower-1.4", "slower-1.05-under-threshold", "faster-1.4"])
def test_a_slowdown_is_flagged_past_the_threshold_only(factor, verdict):
    change = BASE_TIMES | {CASES[0]: BASE_TIMES[CASES[0]] * factor}
    dec = decide(_frames(8, BASE_TIMES, 0.02, 1), _frames(8, change, 0.02, 2))
    case = next(c for c in dec.cases if (c.problem, c.solver, c.settings, c.mode) == CASES[0])
    assert case.verdict == verdict, markdown(dec, "")
    np.testing.assert_allclose(case.ratio, factor, rtol=0.03)
    assert case.low <= case.ratio <= case.high
    assert bool(dec.failed) == (verdict == "SLOWER")


def test_a_significant_slowdown_near_the_threshold_is_borderline():
    change = BASE_TIMES | {CASES[0]: BASE_TIMES[CASES[0]] * 1.15}
    dec = decide(_frames(6, BASE_TIMES, 0.05, 3), _frames(6, change, 0.05, 4))
    assert [(c.problem, c.solver, c.settings, c.mode) for c in dec.borderline] == [CASES[0]]


def test_a_new_failure_is_a_regression():
    dec = decide(_frames(3, BASE_TIMES, 0.02, 5), _frames(3, BASE_TIMES, 0.02, 6, verified={CASES[2]: False}))
    assert [(c.verdict, c.solver) for c in dec.failed] == [("NEWLY FAILING", "daqp")]


def test_a_new_failure_names_its_level_and_amount():
    change = _frames(3, BASE_TIMES, 0.02, 6, verified={CASES[2]: False})
    for f in change:
        f.loc[f["solver"] == "daqp", ["verdict_side", "verdict_level", "verdict_diff"]] = ["worse", 2, 0.0123]
    [case] = decide(_frames(3, BASE_TIMES, 0.02, 5), change).failed
    assert (case.verdict, case.why) == ("NEWLY FAILING", "optimal: worse than the yardstick at level 2 by 0.0123")


def test_a_declined_case_is_not_timed():
    """A solver's 9 us `unsupported` decline, twice as long on the change: not a timing case."""
    declines = [(k, "unsupported") for k in CASES[:1]]
    frames = {}
    for name, factor, seed in (("base", 1.0, 11), ("change", 2.0, 12)):
        frames[name] = _frames(6, BASE_TIMES | {CASES[0]: 9e-6 * factor}, 0.02, seed)
        for f in frames[name]:
            for (problem, solver, _, mode), status in declines:
                f.loc[(f["problem"] == problem) & (f["mode"] == mode), ["status", "verified"]] = [status, False]
    dec = decide(frames["base"], frames["change"])
    case = next(c for c in dec.cases if (c.problem, c.solver, c.settings, c.mode) == CASES[0])
    assert (case.verdict, case.why) == ("not timed", "declined (unsupported) on base and change"), markdown(dec, "")
    assert case.rounds == 0 and math.isnan(case.ratio) and not dec.failed


def test_the_paired_timer_leaves_out_declined_cases(tmp_path):
    from hikbench.bench.harness.interleave import PairedTimer
    from hikbench.problems.files import save_npz
    from tests.bench.doubles import tiny

    (tmp_path / "problems").mkdir()
    save_npz(tiny(), tmp_path / "problems" / "p1.npz")
    rows = pd.DataFrame([{"problem": "p1", "solver": s, "settings": "default", "mode": "cold", "status": st,
                          "problem_hash": "h", "options": "{}"}
                         for s, st in (("hcod", "optimal"), ("nullspace-svd", "unsupported"))])
    timer = PairedTimer.__new__(PairedTimer)  # (no workers: only the selection of the cases)
    timer.repeat, timer.verified = 15, {"base": rows, "change": rows}
    cases, skipped = timer._cases(tmp_path)
    assert [key for key, _ in cases] == [("p1", "hcod", "default", "cold")] and skipped == []


def test_a_case_gone_from_the_change_is_missing_when_its_solver_still_ran():
    change = {k: t for k, t in BASE_TIMES.items() if k != CASES[1]}
    dec = decide(_frames(3, BASE_TIMES, 0.02, 7), _frames(3, change, 0.02, 8),
                 change_meta={"selected_solvers": ["hcod", "daqp"]})
    assert [(c.verdict, c.mode) for c in dec.failed] == [("MISSING", "warm")]
    dropped = decide(_frames(3, BASE_TIMES, 0.02, 7), _frames(3, change, 0.02, 8),
                     change_meta={"selected_solvers": ["daqp"]})
    assert not dropped.failed
    gone = next(c for c in dropped.cases if c.mode == "warm")
    assert (gone.verdict, gone.why) == ("not timed", "only in the base's suite")


def test_the_markdown_and_json_outputs_carry_every_case(tmp_path):
    change = BASE_TIMES | {CASES[0]: BASE_TIMES[CASES[0]] * 1.4}
    dec = decide(_frames(8, BASE_TIMES, 0.02, 9), _frames(8, change, 0.02, 10, verified={CASES[2]: False}))
    to_json(dec, {"suite": "ci", "exit": 1}, tmp_path / "r.json")
    doc = json.loads((tmp_path / "r.json").read_text())
    assert doc["regression"] and doc["counts"]["SLOWER"] == 1 and doc["counts"]["NEWLY FAILING"] == 1
    assert [(c["problem"], c["mode"], c["verdict"]) for c in doc["cases"]] == [
        ("p2", "cold", "NEWLY FAILING"), ("p1", "cold", "SLOWER"), ("p1", "warm", "ok")]
    text = markdown(dec, "### head")
    rows = [ln for ln in text.splitlines() if ln.startswith("| p")]
    assert len(rows) == 3 and "SLOWER" in rows[1] and "1.4" in rows[1]
    assert {c.verdict for c in dec.failed} == {"SLOWER", "NEWLY FAILING"} <= set(FAILING)


def _regress(*argv, cwd: Path):
    return subprocess.run([sys.executable, "-m", "hikbench", "regress", *map(str, argv)], capture_output=True,
                          text=True, cwd=cwd, timeout=900, check=False)


def _one_line_error(capsys, argv, *needles):
    """``hikbench regress ARGV`` (in this process) exits 2 with one line naming ``needles``."""
    assert main(["regress", *map(str, argv)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    for needle in needles:
        assert needle in err, err


def test_a_base_revision_that_does_not_exist_is_an_error(tmp_path, capsys):
    _one_line_error(capsys, ["--base", "no-such-branch-xyz", "--repo", ROOT, "--out", tmp_path],
                    "no-such-branch-xyz", "not a revision")


def test_a_folder_outside_git_is_an_error(tmp_path, capsys):
    _one_line_error(capsys, ["--base", "HEAD", "--repo", tmp_path, "--out", tmp_path / "o"],
                    "not in a git repository")


@pytest.mark.parametrize("pyproject, needle", [
    (None, "has no pyproject.toml"),
    ("[project]\nname = 'broken'\nversion = 'not a version'\n", "does not install"),
], ids=["no-pyproject", "bad-pyproject"])
def test_a_base_revision_that_does_not_install_is_an_error(tmp_path, capsys, pyproject, needle):
    repo = tmp_path / "repo"
    repo.mkdir()
    (repo / "README").write_text("not hikbench\n")
    if pyproject:
        (repo / "pyproject.toml").write_text(pyproject)
    git = ["git", "-C", str(repo), "-c", "user.name=t", "-c", "user.email=t@t"]
    subprocess.run(["git", "init", "-q", str(repo)], check=True)
    subprocess.run([*git, "add", "."], check=True)
    subprocess.run([*git, "commit", "-q", "-m", "a revision"], check=True)
    _one_line_error(capsys, ["--base", "HEAD", "--repo", repo, "--out", tmp_path / "o"], needle)


@pytest.mark.parametrize("argv, needle", [
    (["--threshold", "0.9"], "--threshold"), (["--alpha", "1"], "--alpha"),
    (["--min-rounds", "5", "--max-rounds", "3"], "--min-rounds"), (["--budget", "-1"], "--budget"),
    (["--repeat", "1"], "--repeat"), (["--suite", "missing.toml"], "no such file"),
], ids=["threshold", "alpha", "rounds", "budget", "repeat", "suite-file"])
def test_bad_options_are_one_line_errors(tmp_path, capsys, argv, needle):
    _one_line_error(capsys, ["--base", "HEAD", *argv, "--out", tmp_path], needle)


@pytest.fixture(scope="module")
def gate_out(tmp_path_factory):
    """One folder for the end-to-end runs: the base's install is made once."""
    return tmp_path_factory.mktemp("regress")


def _suite(path: Path, solver: str) -> Path:
    path.write_text(f'repeat = 3\nwarmup = 1\ntimeout = 60.0\nmodes = ["cold"]\nsolvers = ["{solver}"]\n\n'
                    f'[[problems]]\nfamily = "equality"\nparams = {{ n = 8, depth = 2, rows = 3 }}\n'
                    f'seeds = [0]\n')
    return path


@pytest.mark.slow
@pytest.mark.parametrize("solver, code", [("hcod", 0), (spec("BaseOnlySolver"), 1)],
                         ids=["same-solver-passes", "new-failure-fails"])
def test_the_gate_end_to_end(gate_out, solver, code):
    """HEAD as the base, the working tree as the change, a one-case suite: exit 0 when
    the case passes on both; exit 1 when it is verified on the base alone. The
    Markdown and JSON outputs say the same. (Slow: about 20 s each on an idle
    2-core machine; `.ci/run` runs the gate itself after `make test`.)"""
    suite = _suite(gate_out / f"suite-{code}.toml", solver)
    md, js = gate_out / f"gate-{code}.md", gate_out / f"gate-{code}.json"
    proc = _regress("--base", "HEAD", "--repo", ROOT, "--suite", suite, "--out", gate_out / "out",
                    "--min-rounds", 2, "--max-rounds", 2, "--markdown", md, "--json", js, cwd=gate_out)
    assert proc.returncode == code, proc.stdout + proc.stderr
    doc = json.loads(js.read_text())
    assert doc["exit"] == code and doc["rounds"] == 2 and doc["regression"] == bool(code)
    [case] = doc["cases"]
    assert case["verdict"] == ("NEWLY FAILING" if code else case["verdict"])
    if not code:
        assert case["verdict"] in ("ok", "faster", "inconclusive") and case["rounds"] == 2
        assert case["ratio"] > 0
    text = md.read_text()
    assert case["problem"] in text and case["verdict"] in text
    assert ("REGRESSION" in text) == bool(code)


def test_a_problem_whose_content_changed_is_not_timed():
    """Base and change generated different problems under one id (problem_hash differs):
    the case is listed, not judged, and a note names the problem."""
    base = [f.assign(problem_hash="aaaa") for f in _frames(4, BASE_TIMES, 0.02, 11)]
    change = [f.assign(problem_hash=["bbbb", "bbbb", "aaaa"]) for f in
              _frames(4, BASE_TIMES | {CASES[0]: 3 * BASE_TIMES[CASES[0]]}, 0.02, 12)]
    dec = decide(base, change)
    p1 = [(c.verdict, c.why) for c in dec.cases if c.problem == "p1"]
    assert p1 == [("not timed", "the problem differs between base and change")] * 2
    assert not dec.failed and any("p1" in n and "problem_hash" in n for n in dec.notes)


@pytest.mark.parametrize("edit", [None, "__init__.py", "_kernel.py"],
                         ids=["same-sources", "wrapper-edited", "kernel-source-edited"])
def test_the_base_shares_the_compiled_kernels_of_the_files_that_are_the_same(tmp_path, edit):
    """The working tree's numba cache is copied into the base's install, and the base's hcod
    files that are the working tree's (all but __init__.py, which the cache's stamp leaves out)
    get their modification times: a kernel whose files are all the same loads, any other compiles."""
    from hikbench.bench.harness.revisions import share_numba_cache
    from hikbench.solvers import hcod

    mine = Path(hcod.__file__).parent
    theirs = tmp_path / "site" / "hikbench" / "solvers" / "hcod"
    theirs.mkdir(parents=True)
    for f in mine.glob("*.py"):
        (theirs / f.name).write_bytes(f.read_bytes())
    if edit:
        (theirs / edit).write_text((theirs / edit).read_text() + "\n# an edit\n")
    shared = share_numba_cache(tmp_path / "site")
    kernel_files = sorted(p.name for p in mine.glob("*.py") if p.name != "__init__.py")
    assert shared == [f for f in kernel_files if f != edit]
    assert sorted(p.name for p in (theirs / "__pycache__").glob("*.nb[ic]")) == \
        sorted(p.name for p in (mine / "__pycache__").glob("*.nb[ic]"))
    assert (theirs / "_linalg.py").stat().st_mtime_ns == (mine / "_linalg.py").stat().st_mtime_ns
    if edit == "_kernel.py":
        assert (theirs / "_kernel.py").stat().st_mtime_ns != (mine / "_kernel.py").stat().st_mtime_ns


@pytest.mark.skipif(not hasattr(os, "sched_setaffinity"), reason="no CPU affinity on this OS")
def test_each_paired_round_times_both_sides_in_fresh_workers_on_one_cpu(tmp_path):
    """One vCPU can run 1.5x slower than the other for minutes: every paired round starts a
    new worker on each side (two rounds: four processes) and pins both to one CPU, the CPU
    taking turns from round to round; every case gets a time in each round."""
    from types import SimpleNamespace

    from hikbench.bench.harness.interleave import PairedTimer
    from hikbench.bench.harness.revisions import working_side
    from hikbench.bench.suites.problemset import file_stem
    from hikbench.problems.files import save
    from hikbench.problems.generators import generate

    problem = "equality/depth=2,n=6,rows=2/seed=0"
    (tmp_path / "rounds" / "change-1" / "problems").mkdir(parents=True)
    save(generate("equality", seed=0, depth=2, n=6, rows=2),
         tmp_path / "rounds" / "change-1" / "problems" / f"{file_stem(problem)}.npz")
    frame = pd.DataFrame([{"problem": problem, "solver": "nullspace-svd", "settings": "default", "mode": mode,
                           "options": "{}", "problem_hash": "h", "status": "optimal", "verified": True,
                           "time_median_s": 1e-5} for mode in ("cold", "warm")])
    rounds = SimpleNamespace(out=tmp_path, frames={"base": [frame], "change": [frame]})
    side = working_side(tmp_path)
    timer = PairedTimer(side, side, rounds, repeat=3)
    try:
        timer.run_round()
        timer.run_round()
        pinned = [os.sched_getaffinity(w.proc.pid) for w in timer.workers.values()]
    finally:
        timer.close()
    assert timer.done == 2 and len(timer.cases) == 2
    pids = timer.pids["base"] + timer.pids["change"]
    assert len(pids) == 4 and len(set(pids)) == 4
    allowed = sorted(os.sched_getaffinity(0))
    assert timer.cpus == [allowed[0], allowed[1 % len(allowed)]] and pinned == [{timer.cpus[-1]}] * 2
    for name in ("base", "change"):
        times = pd.concat(timer.frames[name])["time_median_s"]
        assert len(times) == 4 and (times > 0).all()
