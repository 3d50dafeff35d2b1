"""`hikbench run` writes OUT/summary.json: rows, solvers, problems, verified
counts, statuses and wall time, the numbers of results.csv and run.json; the
report's one-line summary says the same."""

from __future__ import annotations

import json

import pandas as pd
import pytest

from hikbench.bench.cli import main


@pytest.mark.parametrize("key, expected", [
    ("rows", 6), ("problems", 3), ("solvers", ["nullspace-svd", "yardstick"]), ("modes", ["cold"]),
    ("unsupported", 1), ("sessions", 1),
], ids=["rows", "problems", "solvers", "modes", "unsupported", "sessions"])
def test_summary_json_counts(declining_run, key, expected):
    assert json.loads((declining_run / "summary.json").read_text())[key] == expected


def test_summary_json_matches_results_csv(declining_run):
    s = json.loads((declining_run / "summary.json").read_text())
    df = pd.read_csv(declining_run / "results.csv", keep_default_na=False)
    assert s["statuses"] == df["status"].value_counts().sort_index().to_dict()
    assert s["verified"] == int((df["verified"].astype(str) == "True").sum())
    assert s["verified"] + s["not_verified"] + s["unsupported"] == s["rows"]
    assert s["wall_time_s"] > 0


def test_report_opens_with_the_summary_of_summary_json(declining_run):
    assert main(["report", str(declining_run)]) == 0
    s = json.loads((declining_run / "summary.json").read_text())
    md = (declining_run / "report.md").read_text()
    assert f"**Summary:** {s['rows']} rows: 2 solvers x 3 problems (cold); {s['verified']} verified" in md
    assert json.loads((declining_run / "report.json").read_text())["summary"]["rows"] == s["rows"]
