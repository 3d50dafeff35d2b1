"""Verdicts at every accuracy profile (docs/verification.md, "Accuracy profiles"): a solver
returning the optimum perturbed by 1e-6 relative is refused at ``high`` and ``default`` and
passes at ``low``; every row records its level gaps and each profile's verdict, consistent
(high implies default implies low); ``run --accuracy`` picks the headline; the report ranks at
every profile, ranks an equality-only solver on the problems it supports, and its success per
family is the figure's."""

from __future__ import annotations

import json

import matplotlib.axes
import numpy as np
import pytest

from report_runs import markdown_table as _table

from hikbench.bench.analysis.report import write_report
from hikbench.bench.cli import main
from hikbench.bench.harness.results import read_results
from hikbench.problems.verify import PROFILES
from hikbench.solvers.base import SolveResult


class PerturbedOptimum:
    """hcod's point (the optimum) with each component times 1 + 1e-6 s_i, s_i = +-1 (seeded by
    the problem's size): an answer accurate to 1e-6 relative."""

    name = "perturbed-1e-6"
    strict = True

    def solve(self, h):
        from hikbench.solvers import registry

        x = registry.create("hcod").solve(h).x
        s = np.random.default_rng(h.n * 1000 + h.depth).choice([-1.0, 1.0], h.n)
        return SolveResult(x * (1 + 1e-6 * s), "optimal")


SPEC = f"{__file__}:PerturbedOptimum"
SUITE = """repeat = 1
warmup = 0
timeout = 30.0
modes = ["cold"]
solvers = ["hcod", "nullspace-svd", "{spec}"]
[[problems]]
family = "equality"
params = {{ depth = 3, n = 12 }}
seeds = [0, 1]
[[problems]]
family = "ik-like"
params = {{ n = 6 }}
[[problems]]
family = "degenerate"
params = {{ case = "rank_deficient", n = 5 }}
"""
DEGENERATE = "degenerate/case=rank_deficient,n=5/seed=0"


@pytest.fixture(scope="module")
def accuracy_run(tmp_path_factory):
    d = tmp_path_factory.mktemp("accuracy")
    (d / "s.toml").write_text(SUITE.format(spec=SPEC))
    assert main(["run", "--quiet", "--suite", str(d / "s.toml"), "--out", str(d / "out")]) == 0
    return d


def test_the_optimum_perturbed_by_1e_6_is_refused_at_high_and_default(accuracy_run):
    df = read_results(accuracy_run / "out")
    p = df[(df["solver"] == "perturbed-1e-6") & (df["family"] == "equality")]
    assert len(p) == 2 and p["yardstick"].eq("certified").all(), p["yardstick_reason"].tolist()
    assert p["verified_high"].eq(False).all() and p["verified_default"].eq(False).all(), p
    assert p["verified_low"].eq(True).all(), p["level_gaps"].tolist()
    assert p["verified"].eq(False).all() and p["verdict_side"].eq("worse").all()  # (the headline: default)
    for gaps in p["level_gaps"]:
        assert 1e-8 < max(json.loads(gaps)) <= 1e-6, gaps  # (what each profile's rtol is compared with)
    hcod = df[(df["solver"] == "hcod") & df["yardstick"].eq("certified")]
    assert len(hcod) == 3 and hcod["verified_high"].eq(True).all()
    for gaps in hcod["level_gaps"]:
        assert max(abs(g) for g in json.loads(gaps)) <= 1e-9, gaps


def test_each_row_records_every_profile_and_they_are_consistent(accuracy_run):
    df = read_results(accuracy_run / "out")
    cols = [f"verified_{p}" for p in PROFILES]
    assert cols == ["verified_high", "verified_default", "verified_low"]
    judged = df[df["yardstick"].eq("certified") & df["status"].ne("unsupported")]
    assert len(judged) >= 7
    for _, r in judged.iterrows():
        v = [r[c] for c in cols]
        assert all(isinstance(b, bool) for b in v), r
        assert v == sorted(v), f"{r['solver']} {r['problem']}: {v}"  # high <= default <= low (False < True)
        assert r["verified"] == r["verified_default"]
        assert len(json.loads(r["level_gaps"])) == r["depth"]
    uncertified = df[df["problem"] == DEGENERATE]
    assert uncertified[cols + ["verified"]].isna().all().all()  # (no verdict against an uncertified point)
    meta = json.loads((accuracy_run / "out" / "run.json").read_text())
    assert meta["accuracy"] == {"profile": "default", "rtol": 1e-8,
                                "profiles": {"high": 1e-9, "default": 1e-8, "low": 1e-6}}


def test_run_accuracy_chooses_the_headline_profile(accuracy_run, tmp_path, capsys):
    """--accuracy low: ``verified`` is verified_low (the perturbed optimum passes), run.json says
    so; another profile on the same OUT is refused (its rows' ``verified`` is the first one's)."""
    out = tmp_path / "low"
    assert main(["run", "--quiet", "--suite", str(accuracy_run / "s.toml"), "--out", str(out),
                 "--solvers", SPEC, "--accuracy", "low"]) == 0
    df = read_results(out)
    assert df["verified"].equals(df["verified_low"]) and df.loc[df["family"] == "equality", "verified"].all()
    assert json.loads((out / "run.json").read_text())["accuracy"]["profile"] == "low"
    capsys.readouterr()
    assert main(["run", "--quiet", "--suite", str(accuracy_run / "s.toml"), "--out", str(out),
                 "--solvers", SPEC, "--accuracy", "high"]) == 2
    err = capsys.readouterr().err
    assert "--accuracy high: the rows of" in err and "have the headline profile low" in err, err


@pytest.fixture(scope="module")
def report(accuracy_run, tmp_path_factory):
    """report.md and report.json of the run, and the cells success_rate.png drew (the texts of
    its heatmap, per solver label and family)."""
    drawn: list[tuple] = []
    real = matplotlib.axes.Axes.text

    def text(self, x, y, s, *args, **kwargs):
        drawn.append((self, x, y, s))
        return real(self, x, y, s, *args, **kwargs)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(matplotlib.axes.Axes, "text", text)
        write_report(accuracy_run / "out")
    cells = {}
    for ax, x, y, s in drawn:
        if ax.get_title().startswith("Success per solver and family"):
            rows = [t.get_text() for t in ax.get_yticklabels()]
            cols = [t.get_text() for t in ax.get_xticklabels()]
            cells[(rows[int(y)], cols[int(x)])] = s
    out = accuracy_run / "out"
    return (out / "report.md").read_text(), json.loads((out / "report.json").read_text()), cells


def test_the_ranking_shows_success_at_every_profile(report):
    md, data, _ = report
    head, rows = _table(md, "Ranking, cold:")
    assert head[2:5] == ["success high", "success default", "success low"]
    by = {r[1]: dict(zip(head, r)) for r in rows}
    # 4 problems, one uncertified (no row verified there): the perturbed optimum passes 2 at low only
    assert by["perturbed-1e-6"]["success high"] == "0% (0/4)"
    assert by["perturbed-1e-6"]["success default"] == "0% (0/4)"
    assert by["perturbed-1e-6"]["success low"] == "75% (3/4)"
    assert by["hcod"]["success high"] == "75% (3/4)" and rows[0][1] == "hcod"
    ranked = data["ranking"]["cold"]["solvers"]
    assert {r["solver"]: r["success_at"] for r in ranked}["hcod"] == {"high": 3, "default": 3, "low": 3}


def test_an_equality_only_solver_is_ranked_on_the_problems_it_supports(report):
    md, data, _ = report
    assert data["ranking"]["cold"]["not_ranked"] == {"nullspace-svd": {"declined": 2, "of": 4}}
    head, rows = _table(md, "Ranking, cold, on the 2 problems nullspace-svd supports: 3 solvers")
    assert sorted(r[1] for r in rows) == ["hcod", "nullspace-svd", "perturbed-1e-6"]
    by = {r[1]: dict(zip(head, r)) for r in rows}
    assert by["nullspace-svd"]["success default"] == "100% (2/2)"
    assert by["perturbed-1e-6"]["success default"] == "0% (0/2)" and rows[-1][1] == "perturbed-1e-6"
    (sup,) = data["ranking"]["cold"]["supported"]
    assert sup["for"] == ["nullspace-svd"] and sup["problems"] == 2
    assert all(p.startswith("equality/") for p in sup["problem_ids"])


def test_success_per_family_is_the_figures(report):
    """report.md's table and success_rate.png show the same numbers; the problem without a
    certified yardstick (rank_deficient) is left out of both (the table counted it as a
    failure: degenerate 0% beside the figure's empty cell)."""
    md, _, cells = report
    head, rows = _table(md, "Success rate per solver and family")
    table = {(r[0], f): c for r in rows for f, c in zip(head[1:], r[1:])}
    assert cells, "success_rate.png drew no cell"
    assert {k: v for k, v in table.items() if v != "-"} == cells
    assert table[("hcod", "equality")] == "100%" and table[("perturbed-1e-6", "equality")] == "0%"
    assert table[("hcod", "degenerate")] == "-"  # (its one problem has no certified yardstick)
    assert "without a certified yardstick left out" in md


def test_a_verdict_needs_every_level_within_its_tolerance():
    """judge: an x below the reference at level 0 and above it at level 1 is not verified at any
    profile (the lexicographic verify calls it lower: its first differing level decides), so a
    row verified at one profile is verified at every looser one."""
    from hikbench.problems import Hierarchy, Level
    from hikbench.problems.verify import judge, verify

    h = Hierarchy.from_levels([Level.equality([[1.0, 0.0]], [0.0]), Level.equality([[0.0, 1.0]], [0.0])])
    x, x_ref = np.array([0.0, 5.0]), np.array([1.0, 0.0])  # norms (0, 5) vs (1, 0)
    assert verify(h, x, x_ref, rtol=1e-9).lower == "a"
    for p, prof in PROFILES.items():
        v = judge(h, x, x_ref, prof.rtol)
        assert (v.level, v.lower, v.difference) == (1, "b", 5.0), p
    assert judge(h, x_ref, x_ref, 1e-9).equal
