"""`hikbench run` writes OUT/summary.json: rows, solvers, problems, verified
counts, statuses and wall time, the numbers of results.csv and run.json; the
report's one-line summary says the same."""

from __future__ import annotations

import json

import pandas as pd
import pytest

from hikbench.bench.cli import main

SUITE = """repeat = 1
warmup = 0
timeout = 20.0
modes = ["cold"]
solvers = ["nullspace-svd", "yardstick"]
[[problems]]
family = "equality"
grid = { n = [6, 8], depth = [2] }
[[problems]]
family = "ik-like"
grid = { n = [6] }
"""


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("summary")
    (d / "s.toml").write_text(SUITE)
    assert main(["run", "--quiet", "--suite", str(d / "s.toml"), "--out", str(d / "out")]) == 0
    return d / "out"


@pytest.mark.parametrize("key, expected", [
    ("rows", 6), ("problems", 3), ("solvers", ["nullspace-svd", "yardstick"]), ("modes", ["cold"]),
    ("unsupported", 1), ("sessions", 1),
], ids=["rows", "problems", "solvers", "modes", "unsupported", "sessions"])
def test_summary_json_counts(run_dir, key, expected):
    assert json.loads((run_dir / "summary.json").read_text())[key] == expected


def test_summary_json_matches_results_csv(run_dir):
    s = json.loads((run_dir / "summary.json").read_text())
    df = pd.read_csv(run_dir / "results.csv", keep_default_na=False)
    assert s["statuses"] == df["status"].value_counts().sort_index().to_dict()
    assert s["verified"] == int((df["verified"].astype(str) == "True").sum())
    assert s["verified"] + s["not_verified"] + s["unsupported"] == s["rows"]
    assert s["wall_time_s"] > 0


def test_report_opens_with_the_summary_of_summary_json(run_dir):
    assert main(["report", str(run_dir)]) == 0
    s = json.loads((run_dir / "summary.json").read_text())
    md = (run_dir / "report.md").read_text()
    assert f"**Summary:** {s['rows']} rows: 2 solvers x 3 problems (cold); {s['verified']} verified" in md
    assert json.loads((run_dir / "report.json").read_text())["summary"]["rows"] == s["rows"]
