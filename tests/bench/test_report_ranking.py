"""The report's headline ranking: one problem set per mode, 1.00 = the fastest,
failures charged 10 x the slowest success on their problem (never the job
timeout), solvers that declined listed apart, non-strict solvers with their real
times and per-level gaps; report.json holds the numbers of report.md; the
claims section only in a paper run; a solver's colour the same in every figure."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from hikbench.bench.analysis.report import write_report
from hikbench.bench.analysis.shgeom import FAILURE_FACTOR, SHIFT_S
from report_runs import UNSOLVED, markdown_table as _table, write_run

@pytest.fixture(scope="module")
def report(tmp_path_factory):
    run = write_run(tmp_path_factory.mktemp("rank") / "run")
    write_report(run)
    return (run / "report.md").read_text(), json.loads((run / "report.json").read_text())


def test_the_fastest_shows_one_and_every_ranked_figure_is_over_the_stated_problems(report):
    md, _ = report
    head, rows = _table(md, "Ranking, cold: 2 solvers over the same 7 problems (time over the 6 solved by at least one)")
    by = {r[1]: dict(zip(head, r)) for r in rows}
    assert [r[1] for r in rows] == ["fast", "slow"]  # success first: 6/7, then 5/7
    assert by["fast"]["time vs fastest (1.00 = fastest)"] == "1.00"
    assert {c["success default"].split("(")[1] for c in by.values()} == {"6/7)", "5/7)"}
    assert {c["fastest on"].split("/")[1] for c in by.values()} == {"6"}
    assert f"{UNSOLVED}" in md and "No solver of the ranking solved 1 of the 7 problems" in md


def test_a_failure_is_charged_ten_times_the_slowest_success_on_its_problem(report):
    _, data = report
    slow = next(r for r in data["ranking"]["cold"]["solvers"] if r["solver"] == "slow")
    # problem 0: slow failed, fast took 1e-5 (the slowest success): charged 10 x 1e-5
    t_slow = np.array([FAILURE_FACTOR * 1e-5] + [1e-4] * 5)
    expected = np.exp(np.mean(np.log((t_slow + SHIFT_S) / (1e-5 + SHIFT_S))))  # (fast: 1 on each problem)
    assert slow["relative_time"] == pytest.approx(expected, rel=1e-12)
    assert slow["charged"] == 1


@pytest.mark.parametrize("timeout", [10.0, 0.25], ids=["timeout-10s", "timeout-0.25s"])
def test_no_table_holds_the_job_timeout(tmp_path, timeout):
    run = write_run(tmp_path / "run", timeout=timeout)
    write_report(run)
    data = json.loads((run / "report.json").read_text())
    cells = [c for t in data["tables"] if t["key"] != "run" for r in t["rows"] for c in r]
    us = f"{timeout * 1e6:.1f}"
    assert not [c for c in cells if us in c], us
    slow = next(r for r in data["ranking"]["cold"]["solvers"] if r["solver"] == "slow")
    assert slow["median_time_s"] == pytest.approx(1e-4)  # (its successes only)


def test_solvers_that_declined_are_listed_apart_with_their_count(report):
    md, data = report
    assert ("Not ranked in cold over these problems (declined some): picky declined 2 of its 7: ranked below on "
            "the problems it supports." in md)
    assert data["ranking"]["cold"]["not_ranked"] == {"picky": {"declined": 2, "of": 7}}
    head, rows = _table(md, "Each strict solver on the problems it attempted alone")
    picky = dict(zip(head, next(r for r in rows if r[0] == "picky")))
    assert (picky["attempted"], picky["declined"], picky["success"]) == ("5", "2", "100% (5/5)")


def test_non_strict_solvers_show_real_times_and_per_level_gaps(report):
    md, data = report
    head, rows = _table(md, "Non-strict solvers: real times and per-level gap to the yardstick")
    wsum = dict(zip(head, rows[0]))
    assert [r[0] for r in rows] == ["wsum"]
    assert wsum["median time [us]"] == "2.0"  # its own time, though never verified
    assert wsum["first level lost (rows)"] == "L1 (7)"
    assert wsum["median gap per level"] == "L0 +0, L1 +0.3"
    assert data["non_strict"]["cold"][0]["median_gap_per_level"] == pytest.approx([0.0, 0.3])
    assert "wsum" not in {r["solver"] for r in data["ranking"]["cold"]["solvers"]}


def test_report_json_holds_the_numbers_of_the_markdown(report):
    md, data = report
    head, rows = _table(md, "Ranking, cold")
    for r, j in zip(rows, data["ranking"]["cold"]["solvers"]):
        cell = dict(zip(head, r))
        assert cell["solver"] == j["solver"]
        assert cell["time vs fastest (1.00 = fastest)"] == f"{j['relative_time']:.2f}"
        assert cell["success default"] == f"{j['success_rate']:.0%} ({j['success']}/{j['problems']})"
    s = data["summary"]
    assert (s["rows"], s["problems"], s["wall_time_s"]) == (28, 7, 100.0)
    assert f"**Summary:** {s['rows']} rows: 4 solvers x 7 problems (cold); {s['verified']} verified" in md
    md_titles = [ln[4:] for ln in md.splitlines() if ln.startswith("### ")]
    assert [t["title"] for t in data["tables"]] == md_titles  # every table of report.md, in order


def test_report_opens_with_contents_summary_and_ranking_and_ends_with_the_environment(report):
    md, _ = report
    sections = [ln[3:] for ln in md.splitlines() if ln.startswith("## ")]
    assert sections[0] == "Ranking" and sections[-1] == "Environment"
    lines = [ln for ln in md.splitlines() if ln]
    assert lines[1].startswith("Contents: [Ranking](#ranking)") and lines[2].startswith("**Summary:**")
    assert md.index("### Package versions") > md.index("## Environment")


@pytest.mark.parametrize("suite, has_claims", [("quick", False), ("paper", True)], ids=["quick", "paper"])
def test_claims_section_only_in_a_paper_run(tmp_path, suite, has_claims):
    run = write_run(tmp_path / "run", suite=suite)
    write_report(run)
    md = (run / "report.md").read_text()
    assert ("## Claims of the paper" in md) == has_claims
    assert ("MISSING" in md) == has_claims
    assert (json.loads((run / "report.json").read_text())["claims"] is not None) == has_claims


def test_calibration_is_shown_once(report):
    md, data = report
    assert md.count("calibration [ms]") == 1 and "| h | 28 | 2.000 |" in md  # (the rows', not run.json's 1.000)
    assert "1.000 ms" not in md and data["calibration_ms"] == {"h": 2.0}
