"""hikbench report (report.md + plots) and hikbench claims (PASS / FAIL / MISSING)."""

import json

import numpy as np
import pandas as pd
import pytest
from doubles import spec, write_suite

from hikbench.bench.analysis.claims import (
    FAIL,
    MISSING,
    PASS,
    check_claims,
    claim_a,
    claim_b,
    claim_c,
    claim_d,
    claim_e,
    paper_flops_formula,
)
from hikbench.bench.cli import main
from hikbench.bench.harness.columns import names


@pytest.fixture(scope="module")
def sweep_run(tmp_path_factory):
    d = tmp_path_factory.mktemp("sweep")
    suite = write_suite(d / "s.toml", ["yardstick", spec("SleepSolver"), spec("WrongSolver")],
                        grid={"n": [4, 8, 16], "depth": [1, 2, 3]}, repeat=2)
    assert main(["run", "--quiet", "--suite", str(suite), "--out", str(d / "out")]) == 0
    return d / "out"


def test_report_writes_markdown_and_plots(sweep_run):
    assert main(["report", str(sweep_run)]) == 0
    md = (sweep_run / "report.md").read_text()
    lines = md.splitlines()
    for i, line in enumerate(lines):  # a title line (and a blank) before every table
        if line.startswith("|") and (i == 0 or not lines[i - 1].startswith("|")):
            assert lines[i - 2].startswith("### "), f"table at line {i} has no title"
    assert "numpy" in md and "CPU" in md and "shifted geometric mean" in md
    plots = {p.name for p in (sweep_run / "plots").glob("*.png")}
    assert any(p.startswith("time_vs_dof") for p in plots)
    assert any(p.startswith("time_vs_depth") for p in plots)
    assert {"success_rate.png", "performance_profile_cold.png", "cold_vs_warm.png",
            "accuracy_per_level.png"} <= plots


def _rows(solver, n, depth, times, rows=6, flops=None, family="equality", mode="cold"):
    out = []
    for i, t in enumerate(times):
        r = {c: None for c in names()}
        r.update(problem=f"{family}/depth={depth},n={n},rows={rows}/seed={i}", family=family,
                 params=json.dumps({"n": n, "depth": depth, "rows": rows}), n=n, depth=depth, solver=solver,
                 settings="default", mode=mode, status="optimal", verified=True, time_median_s=t, flops=flops)
        out.append(r)
    return out


def _frame(rows):
    df = pd.DataFrame(rows)
    for c in ("params", "reason"):
        df[c] = df[c].fillna("")
    return df


def test_claim_a_pass_and_fail():
    rows = []
    for depth in (5, 6, 8, 10, 15, 20):
        rows += _rows("hcod", 30, depth, [1e-4 * (1 + 0.01 * s) for s in range(3)])
        rows += _rows("nullspace-svd", 30, depth, [1e-5 * depth * (1 + 0.01 * s) for s in range(3)])
    rows += _rows("hcod", 30, 2, [1e-6])  # below saturation: ignored
    assert claim_a(_frame(rows)).status == PASS
    swapped = [{**r, "solver": {"hcod": "nullspace-svd", "nullspace-svd": "hcod"}[r["solver"]]} for r in rows]
    assert claim_a(_frame(swapped)).status == FAIL
    assert claim_a(_frame(rows[:3])).status == MISSING


def test_claim_b_flops():
    rows = _rows("hcod", 36, 6, [1e-4], flops=27_000) + _rows("nullspace-cod", 36, 6, [1e-4], flops=124_000) \
        + _rows("nullspace-svd", 36, 6, [1e-4], flops=168_000)
    c = claim_b(_frame(rows))
    assert c.status == PASS and "27.0K" in c.measured and "26.9K" in c.paper
    assert claim_b(_frame(_rows("hcod", 36, 6, [1e-4], flops=1))).status == MISSING
    assert paper_flops_formula(36, 6, 6) == 15 * 6 * sum(k * (36 - 6 * k) for k in range(1, 7))


def test_claim_c_speedup():
    ok = _rows("hcod", 50, 5, [1e-4] * 3) + _rows("nullspace-svd", 50, 5, [5e-3] * 3)
    assert claim_c(_frame(ok)).status == PASS
    slow = _rows("hcod", 50, 5, [1e-3] * 3) + _rows("nullspace-svd", 50, 5, [1e-3] * 3)
    assert claim_c(_frame(slow)).status == FAIL


def test_claims_d_e_from_scenario_csv(tmp_path):
    steps = np.arange(20)
    act = (steps % 7 == 3).astype(int)
    rows = []
    for ws, base in (("none", 10), ("stage", 5), ("time", 1)):
        for s, a in zip(steps, act):
            rows.append({"solver": "hcod", "step": s, "warm_start": ws, "solve_time_min_s": 3e-3,
                         "iterations": base + 2 * a, "activations": a})
    rows += [{"solver": "cascade-osqp", "step": s, "warm_start": "none", "solve_time_min_s": 30e-3,
              "iterations": 0, "activations": 0} for s in steps]
    sc = pd.DataFrame(rows)
    d = claim_d(sc)
    assert d.status == PASS and d.measured.endswith("10.0x; on 20 of the reach scenario's 700 steps (a run cut by "
                                                    "--steps)"), d.measured
    e = claim_e(sc)
    assert e.status == PASS and "2.00 extra iterations per activation" in e.measured
    assert e.measured.endswith("; on 20 of the reach scenario's 700 steps (a run cut by --steps)")
    many = sc.assign(iterations=sc["iterations"] + 8 * sc["activations"])  # 10 per activation: not "about 2"
    assert claim_e(many).status == FAIL
    assert claim_d(None).status == MISSING and claim_e(None).status == MISSING


def test_claim_e_leaves_out_the_cold_first_step_of_time_warm_start():
    """The first step of a `time` warm-started run is a cold solve (no record yet), and it
    counted among the warm steps with activations: 9 iterations for 1 activation there made
    the median 5 extra iterations per activation (FAIL) where every warm step took 2."""
    steps = np.arange(10)
    rows = []
    for ws, base in (("none", 10), ("stage", 5), ("time", 1)):
        for s in steps:
            a = int(s == 5 or (ws == "time" and s == 0))
            it = 9 if (ws == "time" and s == 0) else base + 2 * a
            rows.append({"solver": "hcod", "step": s, "warm_start": ws, "solve_time_min_s": 3e-3,
                         "iterations": it, "activations": a})
    e = claim_e(pd.DataFrame(rows))
    assert e.status == PASS, e.measured
    assert e.measured.endswith("2.00 extra iterations per activation (quiet steps: 1; the cold first step "
                               "(step 0) left out); median time per step (not judged) none 3.000, stage 3.000, "
                               "time 3.000 ms; on 10 of the reach scenario's 700 steps (a run cut by --steps)")


def test_claims_command_exit_codes(sweep_run, tmp_path, capsys):
    assert main(["claims", str(sweep_run)]) == 1  # everything MISSING
    assert main(["claims", str(sweep_run), "--allow-missing"]) == 0
    out = capsys.readouterr().out
    assert "| (a) depth past saturation | MISSING |" in out
    assert [c.status for c in check_claims(sweep_run)] == [MISSING] * 5


def test_scenario_csvs_are_found_and_concatenated(sweep_run, tmp_path):
    """`hikbench scenario reach` writes one CSV per (solver, warm-start mode)."""
    from hikbench.bench.analysis.claims import load_scenario

    d = tmp_path / "scenarios" / "reach"
    d.mkdir(parents=True)
    for ws, it in (("none", 10), ("stage", 5), ("time", 1)):
        pd.DataFrame({"solver": "hcod", "warm_start": ws, "step": range(6), "solve_time_min_s": 3e-3,
                      "iterations": [it, it, it + 1, it, it, it], "activations": [0, 0, 1, 0, 0, 0]}
                     ).to_csv(d / f"reach_talos_hcod_{ws}_.csv", index=False)
    pd.DataFrame({"solver": "cascade-daqp", "warm_start": "n/a", "step": range(6), "solve_time_min_s": 3e-2,
                  "iterations": 3, "activations": 0}).to_csv(d / "reach_talos_cascade-daqp.csv", index=False)
    sc = load_scenario(tmp_path)
    assert len(sc) == 24
    claims = check_claims(sweep_run, scenario=d)
    assert [c.status for c in claims[3:]] == [PASS, PASS]
    # where the CSVs came from is named: the search ends at ./results/scenarios/reach, the working
    # directory's, which a report of any run read without saying so
    assert all(c.measured.endswith(f" (CSVs of {d})") for c in claims[3:]), [c.measured for c in claims[3:]]


def test_times_from_several_hosts_are_normalised():
    from hikbench.bench.analysis.report import normalise_hosts

    times = {c: [1.0, 1.0, 2.0] for c in ("time_median_s", "time_p90_s", "time_p99_s", "time_max_s", "time_min_s")}
    df = pd.DataFrame({"host": ["a", "a", "b"], "calib_ns": [1e6, 1e6, 2e6], **times})
    out, note = normalise_hosts(df)
    for c in times:  # (every time column, the tail's too)
        np.testing.assert_allclose(out[c], [1.0, 1.0, 1.0], rtol=1e-12, err_msg=c)
    assert "host a" in note
    _, note = normalise_hosts(df[df["host"] == "a"])
    assert note.startswith("as measured")
