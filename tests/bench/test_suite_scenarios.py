"""A suite's ``[[scenarios]]`` (bench/scenarios/suite.py): ``hikbench run`` runs each
(scenario, solver, warm-start mode) in the isolated worker after the problems, writes the
per-step CSVs of ``hikbench scenario`` under OUT/scenarios/<scenario>/ and one summary row
each to OUT/scenarios.csv; resuming skips them; the report shows them; bad entries are
one-line errors naming the key.

One small run (the reach scenario cut to a few steps) is shared by the module's tests."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pandas as pd
import pytest
from clitools import assert_user_error, run
from crash_doubles import AbortSolver  # noqa: F401 - (its file is the spec below)
from doubles import spec

from hikbench.bench.analysis.claims import find_scenario_csvs
from hikbench.bench.analysis.report import write_report
from hikbench.bench.cli import main
from hikbench.bench.scenarios.rows import (
    KEY,
    SCENARIOS_CSV,
    read_scenario_rows,
    run_stem,
    summary_row,
    write_scenario_row,
)
from hikbench.bench.scenarios.checks import check_run
from hikbench.bench.scenarios.runner import COLUMNS, ScenarioRun
from hikbench.bench.suites import load_suite
from hikbench.solvers import registry
from hikbench.solvers.peers import NOT_BUILT, load_module

PEERS = ("soth", "lexls")
BUILT = all(load_module(p) is not None for p in PEERS)
needs_peers = pytest.mark.skipif(not BUILT, reason=f"the C++ peers soth and lexls are {NOT_BUILT}")
STEPS = 3
ABORT = spec("AbortSolver").replace("doubles.py", "crash_doubles.py")
SOLVERS = ["hcod", "cascade-daqp", ABORT, *(PEERS if BUILT else ())]

SUITE = """repeat = 1
warmup = 0
modes = ["cold"]
solvers = ["yardstick"]

[[problems]]
family = "equality"
params = {{ n = 4, depth = 2, rows = 2 }}

[[scenarios]]
name = "reach"
solvers = {solvers}
warm_start = ["time"]
steps = {steps}
repeat = 1
"""


def _suite_text(solvers=SOLVERS, steps=STEPS) -> str:
    return SUITE.format(solvers=json.dumps(list(solvers)), steps=steps)


@pytest.fixture(scope="module")
def scenario_run(tmp_path_factory):
    """OUT of a run of the reach scenario cut to STEPS steps, one timed call per step."""
    d = tmp_path_factory.mktemp("scen")
    (d / "s.toml").write_text(_suite_text())
    assert main(["run", "--quiet", "--suite", str(d / "s.toml"), "--out", str(d / "out")]) == 0
    return d / "out"


@pytest.fixture(scope="module")
def reach():
    from hikbench.problems.robots.scenarios import load_scenario

    return load_scenario("reach")


def _rows(out) -> pd.DataFrame:
    return read_scenario_rows(out).set_index("solver")


def test_each_run_writes_the_per_step_files_of_hikbench_scenario(scenario_run, reach):
    for label in ("hcod (time)", "cascade-daqp"):
        stem = run_stem("reach", "talos", label)
        df = pd.read_csv(scenario_run / "scenarios" / "reach" / f"{stem}.csv")
        assert list(df.columns[:len(COLUMNS)]) == list(COLUMNS)
        assert df["step"].tolist() == list(range(STEPS))
        assert (df["repeat"] == 1).all()
        q = np.load(scenario_run / "scenarios" / "reach" / f"{stem}_q.npy")
        assert q.shape == (STEPS + 1, reach.robot.nq)


def test_hcod_runs_in_the_asked_warm_start_and_a_solver_without_the_option_once(scenario_run):
    rows = _rows(scenario_run)
    assert rows.loc["hcod", "warm_start"] == "time"
    assert rows.loc["cascade-daqp", "warm_start"] == "n/a"
    assert (rows.loc[["hcod", "cascade-daqp"], "status"] == "finished").all()
    assert (rows.loc[["hcod", "cascade-daqp"], ["steps", "steps_run", "repeat"]].to_numpy()
            == [[STEPS, STEPS, 1]] * 2).all()
    assert (rows["scenario_steps"] == 700).all()  # (problems/robots/scenarios/reach.toml)


@pytest.mark.parametrize("solver, label", [("hcod", "hcod (time)"), ("cascade-daqp", "cascade-daqp")],
                         ids=["hcod", "cascade-daqp"])
def test_the_summary_row_is_the_per_step_csv_summarized_and_its_checks(scenario_run, reach, solver, label):
    row = _rows(scenario_run).loc[solver]
    path = scenario_run / row["csv"]
    assert path.name == f"{run_stem('reach', 'talos', label)}.csv"
    df = pd.read_csv(path)
    t = df["solve_time_min_s"].to_numpy()
    np.testing.assert_allclose(
        row[["time_median_s", "time_p99_s", "time_min_s", "time_max_s", "first_median_s", "iterations_mean"]]
        .to_numpy(dtype=float),
        [np.median(t), np.percentile(t, 99), t.min(), t.max(), np.median(df["solve_time_first_s"]),
         df["iterations"].mean()], rtol=1e-12, atol=0)
    assert row["steps_not_optimal"] == (df["status"] != "optimal").sum()
    q = np.load(path.with_name(path.stem + "_q.npy"))
    checks = check_run(ScenarioRun(reach, solver, str(df["warm_start"].iloc[0]), df, q))
    failed = [c.name for c in checks if c.passed is False]
    unjudged = sum(c.passed is None for c in checks)  # (the suite's runs are cut: some checks are not judged)
    assert (row["checks_passed"], row["checks_failed"], row["checks_not_judged"]) == (
        len(checks) - len(failed) - unjudged, len(failed), unjudged)
    assert (row["failed_checks"] if isinstance(row["failed_checks"], str) else "") == "; ".join(failed)


def test_a_solver_that_kills_its_worker_costs_its_row_only(scenario_run):
    rows = _rows(scenario_run)
    crashed = rows.loc["abort"]
    assert crashed["status"] == "crashed" and "SIGABRT" in crashed["reason"]
    assert pd.isna(crashed["csv"]) and pd.isna(crashed["time_median_s"])
    assert len(rows) == len(SOLVERS)
    assert not list((scenario_run / "scenarios" / "reach").glob("reach_talos_abort*"))


def test_summary_json_counts_the_scenario_runs(scenario_run):
    """summary.json's ``scenarios``: every row of scenarios.csv, the crashed one among them, and
    the report's opening line says so."""
    from hikbench.bench.harness.summary import summary_line

    summary = json.loads((scenario_run / "summary.json").read_text())
    rows = read_scenario_rows(scenario_run)
    finished = rows["status"].eq("finished")
    assert summary["scenarios"] == {
        "runs": len(SOLVERS), "finished": len(SOLVERS) - 1,
        "all_checks_passed": int((finished & rows["checks_failed"].eq(0)).sum()),
        "statuses": {"crashed": 1, "finished": len(SOLVERS) - 1}}
    assert f"{len(SOLVERS)} scenario runs, {len(SOLVERS) - 1} finished" in summary_line(summary)


@needs_peers
@pytest.mark.parametrize("peer", PEERS)
def test_the_peers_run_the_scenario_in_their_time_warm_start(scenario_run, peer):
    row = _rows(scenario_run).loc[peer]
    assert (row["warm_start"], row["status"], row["steps_run"]) == ("time", "finished", STEPS)
    assert (scenario_run / "scenarios" / "reach" / f"reach_talos_{peer}_time.csv").exists()


def test_a_second_run_skips_the_finished_scenario_runs(scenario_run, tmp_path, capsys):
    out = tmp_path / "out"
    shutil.copytree(scenario_run, out)
    before = (out / SCENARIOS_CSV).read_bytes()
    (tmp_path / "s.toml").write_text(_suite_text())
    code, stdout, _ = run(capsys, "run", "--quiet", "--suite", tmp_path / "s.toml", "--out", out)
    assert code == 0
    assert f"{len(SOLVERS)} scenario runs in the suite, {len(SOLVERS)} already done, 0 written" in stdout
    assert (out / SCENARIOS_CSV).read_bytes() == before


def test_limit_counts_the_scenario_rows_after_the_problem_rows(scenario_run, tmp_path, capsys):
    out = tmp_path / "out"
    shutil.copytree(scenario_run, out)
    before = (out / SCENARIOS_CSV).read_bytes()
    (tmp_path / "s.toml").write_text(_suite_text())
    code, stdout, _ = run(capsys, "run", "--quiet", "--rerun", "--limit", 1, "--suite", tmp_path / "s.toml",
                          "--out", out)
    assert code == 0
    assert "1 written" in stdout.splitlines()[0]  # (the problem row took the one row of the limit)
    assert f"{len(SOLVERS)} scenario runs in the suite, 0 already done, 0 written" in stdout
    assert (out / SCENARIOS_CSV).read_bytes() == before


def test_a_row_run_again_replaces_the_row_of_its_key(tmp_path):
    key = {"scenario": "reach", "robot": "talos", "solver": "hcod", "warm_start": "time", "steps": 3,
           "scenario_steps": 700, "repeat": 1}
    write_scenario_row(tmp_path, summary_row(key, {"status": "timeout", "reason": "no answer"}, None))
    write_scenario_row(tmp_path, summary_row({**key, "solver": "lexls"}, {"status": "error", "reason": "x"}, None))
    write_scenario_row(tmp_path, summary_row(key, {"status": "crashed", "reason": "again"}, None))
    df = read_scenario_rows(tmp_path)
    assert df[list(KEY)].duplicated().sum() == 0
    assert df.set_index("solver")["status"].to_dict() == {"lexls": "error", "hcod": "crashed"}


def test_the_report_shows_the_scenario_table(scenario_run, tmp_path):
    out = tmp_path / "out"
    shutil.copytree(scenario_run, out)
    text = write_report(out).read_text()
    assert "[Scenarios](#scenarios)" in text and "\n## Scenarios\n" in text
    assert f"| reach | talos | hcod | time | {STEPS} (cut: the scenario has 700) |" in text
    assert "| reach | talos | abort | n/a |" in text and "| crashed: " in text
    hcod = _rows(out).loc["hcod"]  # (a cut run: the checks of its final values are not judged, and it says so)
    counts = int(hcod["checks_passed"]), int(hcod["checks_failed"]), int(hcod["checks_not_judged"])
    assert counts[2] > 0, counts
    assert f"| {counts[0]}/{sum(counts)} passed, {counts[2]} not judged" in text, text
    assert f"{len(SOLVERS)} scenario runs, {len(SOLVERS) - 1} finished" in text  # (its opening line)
    data = json.loads((out / "report.json").read_text())
    assert [r["solver"] for r in data["scenarios"]] == read_scenario_rows(out)["solver"].tolist()
    table = next(t for t in data["tables"] if t["key"] == "scenarios")
    assert table["columns"][:6] == ["scenario", "robot", "solver", "warm start", "steps", "median [us]"]
    assert len(table["rows"]) == len(SOLVERS)


def test_a_report_of_a_run_without_scenarios_has_no_scenario_section(declining_run, tmp_path):
    out = tmp_path / "out"
    shutil.copytree(declining_run, out)
    text = write_report(out).read_text()
    assert "Scenarios" not in text
    assert json.loads((out / "report.json").read_text())["scenarios"] == []


def test_the_claims_find_the_scenario_csvs_of_the_run(scenario_run):
    found = find_scenario_csvs(scenario_run)
    assert found and {p.parent for p in found} == {scenario_run / "scenarios" / "reach"}
    assert {p.name for p in found} >= {"reach_talos_hcod_time.csv", "reach_talos_cascade-daqp.csv"}


def test_the_peers_suite_runs_the_reach_scenario_with_the_peers_and_a_cascade():
    (entry,) = load_suite("peers").scenarios
    assert entry["name"] == "reach" and entry["robot"] == "talos"
    assert entry["solvers"] == ["hcod", "soth", "lexls", "nipm-hlsp", "daqp-hqp", "cascade-daqp"]
    assert entry["warm_start"] == ["time"]


BAD = [
    ("[[scenarios]]\nsteps = 3\n", "scenarios[0]: missing key 'name'"),
    ('[[scenarios]]\nname = "dance"\n', "scenarios[0].name: unknown scenario 'dance'"),
    ('[[scenarios]]\nname = "reach"\nsteps = 0\n', "scenarios[0].steps = 0: expected an integer >= 1"),
    ('[[scenarios]]\nname = "reach"\nstep = 3\n', "unknown key scenarios[0].step (did you mean 'steps'?)"),
    ('[[scenarios]]\nname = "reach"\ntimeout = -1\n', "scenarios[0].timeout = -1: expected a number of seconds"),
    ('[[scenarios]]\nname = "reach"\nrobot = "r2d2"\n', "scenarios[0].robot: robot 'r2d2'"),
    ('[[scenarios]]\nname = "reach"\nsolvers = ["nosuch"]\n', "unknown solver 'nosuch' (in suite"),
    ('[[scenarios]]\nname = "reach"\nsolvers = ["hcod"]\nwarm_start = ["sometimes"]\n',
     "scenarios[0].warm_start: solver 'hcod'"),
    ('[[scenarios]]\nname = "reach"\nsolvers = ["hcod"]\nwarm_start = ["time", "time"]\n',
     "scenarios[0].warm_start = ['time', 'time']: expected each mode once"),
    ('[[scenarios]]\nname = "reach"\nsolvers = ["hcod"]\n[[scenarios]]\nname = "reach"\nsolvers = ["hcod"]\n',
     "scenarios[1]: runs hcod (time) on reach (talos, 700 steps) as scenarios[0] does"),
    ('[[scenarios]]\nname = "missing.toml"\n', "scenarios[0].name: "),
]


@pytest.mark.parametrize("entry, fragment", BAD, ids=[
    "no-name", "unknown-scenario", "steps-0", "misspelt-key", "negative-timeout", "unknown-robot",
    "unknown-solver", "unknown-mode", "mode-twice", "run-twice", "missing-file"])
def test_a_bad_scenario_entry_is_one_line_naming_its_key(tmp_path, capsys, entry, fragment):
    suite = tmp_path / "s.toml"
    suite.write_text('solvers = ["yardstick"]\n[[problems]]\nfamily = "equality"\n' + entry)
    code, _, err = run(capsys, "run", "--quiet", "--suite", suite, "--out", tmp_path / "out")
    assert_user_error(code, err, fragment)
    assert not (tmp_path / "out").exists()  # (refused before anything is written)


def test_a_solver_that_is_not_installed_is_skipped_with_its_hint(tmp_path, capsys):
    missing = sorted(registry.missing())
    if not missing:
        pytest.skip("every optional solver is installed here")
    from hikbench.bench.scenarios.suite import expand_scenarios

    suite = tmp_path / "s.toml"
    suite.write_text('[[problems]]\nfamily = "equality"\n[[scenarios]]\nname = "reach"\n'
                     f'solvers = ["hcod", "{missing[0]}"]\n')
    tasks, skipped = expand_scenarios(load_suite(str(suite)))
    assert [t.solver for t in tasks] == ["hcod"]
    assert skipped[missing[0]] == f"not installed: {registry.missing()[missing[0]]}"


def test_the_columns_page_holds_the_generated_scenario_columns():
    from pathlib import Path

    from hikbench.bench.scenarios.rows import markdown

    page = Path(__file__).resolve().parents[2] / "docs" / "columns.md"
    assert markdown() in page.read_text(), (
        "docs/columns.md's scenarios.csv table is out of date: paste hikbench.bench.scenarios.rows.markdown()")
