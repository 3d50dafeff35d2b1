"""Which yardstick a row is judged against (column ``yardstick``): certified rows are verified,
reference-only and none rows never are (docs/verification.md, "The yardstick of a run")."""

from __future__ import annotations

import pandas as pd
import pytest

from doubles import spec

from hikbench.bench.cli import main


def _run(tmp_path, solvers, problems: str, certify_timeout: float = 30.0) -> pd.DataFrame:
    suite = tmp_path / "s.toml"
    suite.write_text(f'repeat = 1\nwarmup = 0\ntimeout = 20.0\nmodes = ["cold"]\ncertify_timeout = {certify_timeout}\n'
                     f'solvers = {list(solvers)!r}\n'.replace("'", '"') + problems)
    assert main(["run", "--quiet", "--suite", str(suite), "--out", str(tmp_path / "out")]) == 0
    return pd.read_csv(tmp_path / "out" / "results.csv")


@pytest.mark.parametrize("i", [0, pytest.param(1, marks=pytest.mark.slow)], ids=["A1e-12", "A1e100"])
def test_a_solver_returning_the_old_yardsticks_point_on_a_rescaled_problem_is_not_verified(tmp_path, i):
    """The old yardstick's point on random n=12 seed 0 with A x 1e-12 (x 1e100) is above the
    optimum from level 1 (level 3); the run's yardstick is certified, the double returning the
    old point is worse, hcod is verified."""
    df = _run(tmp_path, [spec("OldYardstickSolver"), "hcod"],
              f'[[problems]]\nfamily = "{spec("rescaled_random")}"\nparams = {{ i = {i} }}\n')
    assert df["yardstick"].eq("certified").all(), df["yardstick_reason"].tolist()
    old = df[df["solver"] == "old-yardstick"].iloc[0]
    assert old["verified"] is False or old["verified"] == False  # noqa: E712 - (a CSV bool)
    assert old["verdict_side"] == "worse" and old["verdict_level"] == (1 if i == 0 else 3)
    assert df[df["solver"] == "hcod"]["verified"].eq(True).all()


def test_a_problem_the_certificate_refuses_is_judged_by_no_row(tmp_path):
    """rank_deficient: levels rank-deficient only to rounding have another exact optimum, and the
    certificate refuses the yardstick: reference-only, the reason said, no row verified."""
    df = _run(tmp_path, ["hcod", spec("WrongSolver")],
              '[[problems]]\nfamily = "degenerate"\nparams = { case = "rank_deficient", n = 5 }\n')
    assert df["yardstick"].eq("reference-only").all()
    assert df["yardstick_reason"].str.contains("the exact certificate refused it").all()
    assert df["verified"].isna().all()
    side = df.set_index("solver")["verdict_side"]
    assert side["hcod"] == "no certified yardstick"  # (equal to the point, which is not a verdict)
    assert side["wrong"] == "no certified yardstick; worse than its point"


@pytest.mark.parametrize(("cost", "n", "fragment"), [(None, 80, "did not finish in certify_timeout"),
                                                      (1e3, 12, "was not tried")], ids=["timed-out", "not-tried"])
def test_a_certificate_beyond_its_budget_leaves_a_reference_only_yardstick(tmp_path, monkeypatch, cost, n, fragment):
    """A certificate that does not finish in certify_timeout (its worker is stopped), or whose
    estimated time is beyond twice it (not tried), leaves the point as reference-only: the run
    goes on, the point is kept (ref_level_norms), no row is verified."""
    from hikbench.problems import exact

    monkeypatch.setattr(exact, "COST_S", 0.0 if cost is None else cost)
    # (IK-like n = 80: a certificate of 0.5-1.4 s, beyond 0.1 s)
    df = _run(tmp_path, ["hcod"], f'[[problems]]\nfamily = "ik-like"\nparams = {{ n = {n} }}\n',
              certify_timeout=0.1)
    assert df["yardstick"].eq("reference-only").all()
    assert df["yardstick_reason"].str.contains(fragment).all(), df["yardstick_reason"].tolist()
    assert df["ref_level_norms"].notna().all() and df["verified"].isna().all()


def test_the_lowest_candidate_is_taken_and_named():
    """Of the independent yardstick's point and hcod's, the lexicographically lower is the
    yardstick (here the old yardstick's point on A x 1e-12, above hcod's from level 1); a tie keeps
    the independent one; a missing candidate leaves the other."""
    from doubles import OldYardstickSolver, rescaled_random

    from hikbench.bench.harness.yardstick import lowest
    from hikbench.solvers.hcod import HcodSolver

    h = rescaled_random(i=0)
    x_old, x_hcod = OldYardstickSolver().solve(h).x, HcodSolver().solve(h).x
    x, note = lowest(h, {"x": x_old, "x_hcod": x_hcod})
    assert x is x_hcod and note == "hcod's point (the independent yardstick's is above it at level 1)"
    x, note = lowest(h, {"x": x_hcod, "x_hcod": x_hcod.copy()})
    assert x is x_hcod and note == "the independent yardstick's point"
    x, note = lowest(h, {"x": None, "reason": "yardstick error: E", "x_hcod": x_hcod})
    assert x is x_hcod and "no independent point: yardstick error: E" in note
    assert lowest(h, {"x": None, "x_hcod": None}) == (None, "")


def test_the_ranking_tells_problems_without_a_certified_yardstick_from_unsolved_ones():
    """The ranking's note lists the problems left out because their yardstick is not certified
    apart from those no solver solved."""
    from hikbench.bench.analysis.report import _uncertified_problems

    df = pd.DataFrame({"problem": ["a", "a", "b", "c"], "yardstick": ["certified", "certified", "reference-only",
                                                                      "none"]})
    assert _uncertified_problems(df) == {"b", "c"}
    assert _uncertified_problems(df.drop(columns=["yardstick"])) == frozenset()
