"""report.md's verified % matches its title (unsupported rows left out), and
report prints no numpy warnings on all-failed problems or bogus times."""

import json

import numpy as np
import pandas as pd
import pytest
from doubles import DECLINING_SUITE

from hikbench.bench.analysis.claims import slope_interval
from hikbench.bench.cli import main
from hikbench.bench.analysis.plots import loglog_slope, plot_profiles
from hikbench.bench.suites.problemset import ProblemSpec

def _table(md: str, title: str) -> dict:
    lines = md.splitlines()
    i = next(k for k, ln in enumerate(lines) if ln.startswith(f"### {title}"))
    head = [c.strip() for c in lines[i + 2].strip("|").split("|")]
    out = {}
    for ln in lines[i + 4:]:
        if not ln.startswith("|"):
            break
        cells = [c.strip() for c in ln.strip("|").split("|")]
        out[cells[0]] = dict(zip(head, cells))
    return out


@pytest.mark.filterwarnings("error")
def test_verified_percent_leaves_unsupported_rows_out(declining_run, capsys):
    assert main(["report", str(declining_run)]) == 0
    err = capsys.readouterr().err
    assert "Warning" not in err, err
    md = (declining_run / "report.md").read_text()
    solvers = _table(md, "Each strict solver on the problems it attempted alone")
    assert solvers["nullspace-svd"]["declined"] == "1"
    assert solvers["nullspace-svd"]["success"] == "100% (2/2)"  # 2 of the 2 rows it supports
    fam = _table(md, "Success rate per solver and family")
    assert fam["nullspace-svd"]["equality"] == "100%"
    assert fam["nullspace-svd"]["ik-like"] == "-"  # declined entirely: no rate, not 0%
    assert fam["yardstick"]["ik-like"] == "100%"


UNITS_SUITE = """repeat = 1
warmup = 0
timeout = 20.0
modes = ["cold", "warm"]
accuracy = "high"
solvers = ["hcod", "cascade-clarabel", "nullspace-svd"]
[[problems]]
family = "ik-like"
params = { n = 6 }
grid = { bound_scale = [1.0, 1e-9] }
seeds = [0, 1]
"""


@pytest.mark.filterwarnings("error")
def test_verified_per_bound_scale_when_a_run_has_one(declining_run, tmp_path):
    """A run whose problems carry ``bound_scale`` (the units suite) gets a table of verified
    rates per solver and scale; a run without one does not."""
    (tmp_path / "s.toml").write_text(UNITS_SUITE)
    assert main(["run", "--quiet", "--suite", str(tmp_path / "s.toml"), "--out", str(tmp_path / "out")]) == 0
    assert main(["report", str(tmp_path / "out")]) == 0
    units = _table((tmp_path / "out" / "report.md").read_text(), "Success rate per solver and bound_scale")
    assert units["hcod"]["x 1"] == units["hcod"]["x 1e-09"] == "100%"  # 2 seeds x cold, warm
    assert all(units["cascade-clarabel"][c].endswith("%") for c in ("x 1", "x 1e-09"))
    assert units["nullspace-svd"]["x 1e-09"] == "-"  # (declines inequalities)
    assert main(["report", str(declining_run)]) == 0
    assert "per solver and bound_scale" not in (declining_run / "report.md").read_text()


@pytest.mark.filterwarnings("error")
def test_report_with_bogus_times_and_timeouts(declining_run, tmp_path, capsys):
    """Negative times (an external program's -1) and all-failed problems: no RuntimeWarning."""
    import shutil
    run = tmp_path / "run"
    shutil.copytree(declining_run, run)
    df = pd.read_csv(run / "results.csv", keep_default_na=False)
    df.loc[df["solver"] == "yardstick", "time_median_s"] = -1.0
    df.loc[df["family"] == "ik-like", "status"] = "timeout"
    df["verified"] = df["verified"].astype(str)
    df.loc[df["family"] == "ik-like", "verified"] = "False"
    df.to_csv(run / "results.csv", index=False)
    meta = json.loads((run / "run.json").read_text())
    for s in meta["sessions"]:
        s["timeout"] = 0  # a bogus recorded timeout: the penalty falls back, no log of <= 0
    (run / "run.json").write_text(json.dumps(meta))
    assert main(["report", str(run)]) == 0
    assert "Warning" not in capsys.readouterr().err


@pytest.mark.filterwarnings("error")
def test_speed_table_keeps_a_solver_without_a_verified_row(declining_run, tmp_path):
    # a solver whose every row failed verification keeps its column ("-"), like a problem no
    # solver verified keeps its row: leaving them out hid them from the table
    import shutil
    run = tmp_path / "run"
    shutil.copytree(declining_run, run)
    df = pd.read_csv(run / "results.csv", keep_default_na=False)
    df["verified"] = df["verified"].astype(str)
    df.loc[df["solver"] == "nullspace-svd", "verified"] = "False"
    df.loc[df["solver"] == "nullspace-svd", "reason"] = "level 3: " + "why " * 30 + "THE END"
    df.loc[df["family"] == "ik-like", "verified"] = "False"
    df.to_csv(run / "results.csv", index=False)
    assert main(["report", str(run)]) == 0
    md = (run / "report.md").read_text()
    # without a verified row it has no time (a charge is no time: it read 60000000.0 us)
    solvers = _table(md, "Each strict solver on the problems it attempted alone")
    assert solvers["nullspace-svd"]["success"] == "0% (0/2)"
    assert solvers["nullspace-svd"]["sgm of its verified times [us]"] == "-"
    assert "why why THE END" in md  # (a reason cut at 80 characters lost its end)
    speed = _table(md, "Median cold time per problem")
    assert sorted(speed) == ["equality/depth=2,n=6", "equality/depth=2,n=8", "ik-like/n=6"]
    for problem, row in speed.items():
        assert row["nullspace-svd"] == ("unsupported" if problem.startswith("ik-like") else "-")
        assert (row["yardstick"] == "-") == problem.startswith("ik-like"), row
        if row["yardstick"] != "-":
            assert float(row["yardstick"]) > 0


def test_performance_profiles_compare_solvers_on_the_problems_they_support(declining_run):
    """Problems are grouped by the solvers that support them, one profile per group: one
    profile over every problem would count nullspace-svd's `unsupported` ik-like row as a
    failure (its curve could not pass 2/3) while the tables leave such rows out."""
    from hikbench.bench.analysis.report import _profile_groups, solver_label
    from hikbench.bench.harness.results import read_results

    df = read_results(declining_run)
    df = df.assign(label=solver_label(df))
    groups = {slug: (what, sorted(g["problem"].unique()), sorted(g["label"].unique()))
              for what, slug, g in _profile_groups(df[df["mode"] == "cold"])}
    assert groups == {
        "_eq": (", 2 problems equality-only (2 solvers)",
                ["equality/depth=2,n=6/seed=0", "equality/depth=2,n=8/seed=0"], ["nullspace-svd", "yardstick"]),
        "_ineq": (", 1 problem with inequalities (1 solver; unsupported by nullspace-svd)", ["ik-like/n=6/seed=0"], ["yardstick"]),
    }
    assert main(["report", str(declining_run)]) == 0
    plots = {p.name for p in (declining_run / "plots").glob("performance_profile_*.png")}
    # (a profile over fewer than 5 problems is named, not drawn: a handful of ties)
    assert plots == set()
    md = (declining_run / "report.md").read_text()
    assert ("Performance profile, cold, 1 problem with inequalities (1 solver; unsupported by nullspace-svd): "
            "not drawn: 1 problem, fewer than 5.") in md


@pytest.mark.filterwarnings("error")
@pytest.mark.parametrize("times", [
    [[np.nan, np.nan], [1e-4, 2e-4]],
    [[0.0, -1.0], [1e-4, np.inf]],
], ids=["all-NaN problem", "nonpositive times"])
def test_profiles_without_warnings(tmp_path, times):
    t = pd.DataFrame(times, columns=["a", "b"], index=["p1", "p2"])
    styles = {s: {"color": "k", "marker": "o", "linestyle": "-"} for s in t.columns}
    assert plot_profiles(t, tmp_path / "p.png", "t", styles=styles) == tmp_path / "p.png"


@pytest.mark.filterwarnings("error")
@pytest.mark.parametrize("fit", [loglog_slope, slope_interval], ids=["plots", "claims"])
def test_slopes_skip_nonpositive(fit):
    x = np.array([0, 1, 2, 4, 8, 16.0])
    y = np.array([-1.0, 1e-4, 2e-4, 4e-4, 8e-4, 1.6e-3])
    assert fit(x, y)[0] == pytest.approx(1.0, rel=1e-9)  # (exact doubling: a line)


@pytest.mark.parametrize("params, pid", [
    ({}, "equality/seed=3"),
    ({"n": 8, "depth": 2}, "equality/depth=2,n=8/seed=3"),
], ids=["no params", "params"])
def test_problem_id_has_no_empty_segment(params, pid):
    assert ProblemSpec("equality", params, 3).id == pid


def test_shifted_geometric_mean_value_and_bad_times():
    """A negative or NaN time is a ValueError naming the entry, not a NaN with a
    RuntimeWarning (the report charges failures before aggregating)."""
    from hikbench.bench.analysis.shgeom import shifted_geometric_mean

    t = np.array([1e-5, 3e-5, 7e-5])
    expected = np.exp(np.log(t + 1e-5).mean()) - 1e-5  # the definition, shift 10 us
    np.testing.assert_allclose(shifted_geometric_mean(t), expected, rtol=1e-15)
    assert np.isnan(shifted_geometric_mean([]))
    for bad, what in (([1e-5, -1.0], "time 1 is -1.0"), ([np.nan], "time 0 is nan"), ([1.0, np.inf], "time 1 is inf")):
        with pytest.raises(ValueError, match=f"^shifted geometric mean: {what}; expected finite times >= 0"):
            shifted_geometric_mean(bad)
    with pytest.raises(ValueError, match="shift is 0"):
        shifted_geometric_mean([1.0], shift=0)


def test_performance_profile_fractions_and_failures():
    """Dolan-More: the fraction of *all* problems within tau of the best; NaN, inf
    and <= 0 are failures; a problem nobody solved counts against every solver."""
    from hikbench.bench.analysis.shgeom import performance_profile

    t = pd.DataFrame([[1.0, 2.0], [2.0, 1.0], [np.nan, 3.0], [0.0, np.inf]], columns=["a", "b"])
    taus, frac = performance_profile(t, points=50)
    assert taus[0] == 1.0 and taus[-1] == pytest.approx(10.0, rel=1e-12)  # max(10, 2 x the worst ratio 2)
    np.testing.assert_allclose([frac["a"][0], frac["b"][0]], [0.25, 0.5], rtol=0, atol=0)
    np.testing.assert_allclose([frac["a"][-1], frac["b"][-1]], [0.5, 0.75], rtol=0, atol=0)
    assert performance_profile(pd.DataFrame([[0.0, np.nan]], columns=["a", "b"])) is None


@pytest.mark.parametrize("verified, t, usable, usable_zero_ok", [
    (True, 1e-5, True, True),
    (True, 0.0, False, True),
    (True, -1e-6, False, False),
    (True, float("nan"), False, False),
    (True, float("inf"), False, False),
    (False, 1e-5, False, False),
], ids=["timed", "zero", "negative", "nan", "inf", "unverified"])
def test_timed_rows(verified, t, usable, usable_zero_ok):
    from hikbench.bench.analysis.shgeom import timed

    df = pd.DataFrame({"verified": [verified], "time_median_s": [t]})
    assert timed(df).tolist() == [usable]
    assert timed(df, zero_ok=True).tolist() == [usable_zero_ok]


def test_a_partial_run_says_so_and_tells_not_run_from_not_verified(tmp_path):
    """A run stopped by --limit: the report says which rows are missing, tells a solver that
    never ran a problem from one without a verified row ('-'), and marks a median over some
    seeds only with (k/m), so that it does not look like one over all of them."""
    (tmp_path / "s.toml").write_text(DECLINING_SUITE.replace("grid = { n = [6] }", "grid = { n = [6] }\nseeds = [0, 1]"))
    out = tmp_path / "out"
    run = ["run", "--quiet", "--suite", str(tmp_path / "s.toml"), "--out", str(out)]
    assert main([*run, "--limit", "5"]) == 0  # both equality problems, nullspace-svd declining ik-like seed 0
    assert json.loads((out / "run.json").read_text())["suite_rows"] == 8
    assert main(["report", str(out)]) == 0
    md = (out / "report.md").read_text()
    assert ("**Incomplete run: 5 of the suite's 8 (`hikbench run` with the same suite and --out runs the "
            "other 3).**") in md
    speed = _table(md, "Median cold time per problem")
    assert speed["ik-like/n=6"]["yardstick"] == "not run"
    assert speed["ik-like/n=6"]["nullspace-svd"] == "unsupported"
    assert float(speed["equality/depth=2,n=6"]["yardstick"]) > 0

    assert main(run) == 0
    df = pd.read_csv(out / "results.csv", keep_default_na=False)
    df["verified"] = df["verified"].astype(str)
    df.loc[(df["problem"] == "ik-like/n=6/seed=1") & (df["solver"] == "yardstick"), "verified"] = "False"
    df.to_csv(out / "results.csv", index=False)
    assert main(["report", str(out)]) == 0
    md = (out / "report.md").read_text()
    assert "Incomplete run" not in md and "| rows | 8 (the whole suite) |" in md
    cell = _table(md, "Median cold time per problem")["ik-like/n=6"]["yardstick"]
    assert cell.endswith(" (1/2)") and float(cell.split()[0]) > 0, cell


def test_report_removes_its_old_figures_and_refuses_an_empty_run(declining_run, tmp_path, capsys):
    import shutil
    run = tmp_path / "run"
    shutil.copytree(declining_run, run)
    (run / "plots").mkdir(exist_ok=True)
    (run / "plots" / "performance_profile_cold_eq2.png").write_bytes(b"stale")  # a partial run's figure
    (run / "plots" / "mine.png").write_bytes(b"the user's")
    assert main(["report", str(run)]) == 0
    assert not (run / "plots" / "performance_profile_cold_eq2.png").exists()
    assert (run / "plots" / "mine.png").exists()
    capsys.readouterr()
    header = (run / "results.csv").read_text().splitlines()[0]
    (run / "results.csv").write_text(header + "\n")
    assert main(["report", str(run)]) == 2
    assert "results.csv has no rows; expected the rows of a `hikbench run`" in capsys.readouterr().err
