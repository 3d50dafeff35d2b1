"""hikbench claims: each verdict follows from the data the claim is about
(no unrelated problems pooled, no partial comparison passed as PASS)."""

import json

import numpy as np
import pandas as pd
import pytest

from hikbench.bench.analysis.claims import FAIL, MISSING, PASS, claim_a, claim_b, claim_c, claim_d, slope_interval
from hikbench.bench.harness.columns import names


def _row(solver, n, depth, rows, t, seed=0, flops=None, verified=True):
    r = {c: None for c in names()}
    r.update(problem=f"equality/depth={depth},n={n},rows={rows}/seed={seed}", family="equality",
             params=json.dumps({"n": n, "depth": depth, "rows": rows}), n=n, depth=depth, solver=solver,
             settings="default", mode="cold", status="optimal", verified=verified, time_median_s=t, flops=flops,
             reason="")
    return r


def _sweep(hcod_t, svd_t, n=30, rows=6, depths=(5, 6, 8, 10, 12, 16, 20)):
    return [_row(s, n, d, rows, f(d)) for d in depths for s, f in (("hcod", hcod_t), ("nullspace-svd", svd_t))]


def test_claim_a_uses_one_fixed_dof_sweep():
    """The paper suite also has n=36 (depth 6) and a DOF sweep at depth 4, saturated too: their
    times are of other problem sizes and must not enter the slope of the n = 30 depth sweep."""
    sweep = _sweep(lambda d: 1e-5, lambda d: 1e-5 * d)
    # a bigger problem (n = 36, saturated at depth 6) where hcod is slower: pooled, it tilts hcod's slope
    others = [_row("hcod", 36, 6, 6, 1e-4, seed=s) for s in range(3)]
    others += [_row("nullspace-svd", 36, 6, 6, 6e-5, seed=s) for s in range(3)]
    c = claim_a(pd.DataFrame(sweep + others))
    h = slope_interval([r["depth"] for r in sweep if r["solver"] == "hcod"],
                       [r["time_median_s"] for r in sweep if r["solver"] == "hcod"])
    assert c.status == PASS, c.measured
    assert "n=30, rows=6" in c.measured and f"slope hcod {h[0]:.2f}" in c.measured, c.measured


def test_claim_a_missing_when_no_single_sweep_has_three_depths():
    # three saturated depths in all, but each at another n: no depth sweep at a fixed DOF
    rows = [_row(s, n, d, 6, 1e-5 * d) for n, d in ((12, 4), (24, 4), (30, 8)) for s in ("hcod", "nullspace-svd")]
    c = claim_a(pd.DataFrame(rows))
    assert c.status == MISSING and "fixed n and rows" in c.measured, c.measured


def test_claim_a_counts_only_depths_with_a_time_it_can_fit():
    """A sweep whose nullspace-svd times were 0 at all but two depths: the depths were counted
    before the log-log fit dropped those times, so the claim gave FAIL with a "nan" slope."""
    rows = _sweep(lambda d: 1e-5, lambda d: 1e-5 * d if d in (5, 6) else 0.0)
    c = claim_a(pd.DataFrame(rows))
    assert c.status == MISSING and "3 saturated depths" in c.measured, c.measured


@pytest.mark.parametrize("present", [("hcod", "nullspace-svd"), ("hcod", "nullspace-cod")],
                         ids=["no-cod", "no-svd"])
def test_claim_b_missing_without_both_recursions(present):
    flops = {"hcod": 27e3, "nullspace-cod": 124e3, "nullspace-svd": 168e3}
    c = claim_b(pd.DataFrame([_row(s, 36, 6, 6, 1e-4, flops=flops[s]) for s in present]))
    missing = ({"nullspace-cod", "nullspace-svd"} - set(present)).pop()
    assert c.status == MISSING and missing in c.measured, c.measured


def test_claim_c_compares_the_same_problems():
    """nullspace-svd verified only on the easy problem: its median must not be set against
    hcod's median over harder problems it failed."""
    rows = [_row("hcod", 50, 5, 8, 1e-4, seed=0), _row("nullspace-svd", 50, 5, 8, 3e-4, seed=0)]
    for seed in (1, 2):  # hcod slow but right, nullspace-svd fast and wrong (unverified)
        rows += [_row("hcod", 50, 5, 8, 1e-2, seed=seed),
                 _row("nullspace-svd", 50, 5, 8, 1e-6, seed=seed, verified=False)]
    c = claim_c(pd.DataFrame(rows))
    assert c.status == PASS and "3.0x" in c.measured and "1 problems" in c.measured, c.measured
    only_unverified = [r for r in rows if r["problem"].endswith("seed=1")]
    assert claim_c(pd.DataFrame(only_unverified)).status == MISSING


@pytest.mark.parametrize("side, used", [("no certified yardstick", True),
                                        ("no certified yardstick; worse than its point", False)],
                         ids=["equal-to-an-uncertified-yardstick", "worse-than-it"])
def test_claim_c_takes_rows_equal_to_an_uncertified_yardstick_and_says_so(side, used):
    """A problem beyond the certificate's budget: rows equal to its (uncertified) yardstick count
    as solved, said in the measured text; a row worse than that point does not."""
    rows = [_row("hcod", 50, 5, 8, 1e-4, verified=None), _row("nullspace-svd", 50, 5, 8, 5e-4, verified=None)]
    rows[0]["verdict_side"] = "no certified yardstick"
    rows[1]["verdict_side"] = side
    c = claim_c(pd.DataFrame(rows))
    if used:
        assert c.status == PASS and "5.0x" in c.measured, c.measured
        assert "2 of 2 rows judged against a yardstick that is not certified" in c.measured, c.measured
    else:
        assert c.status == MISSING, c.measured


def _scenario(modes):
    rows = [{"solver": "hcod", "warm_start": m, "step": k, "solve_time_min_s": t, "iterations": 1, "activations": 0}
            for m, t in modes.items() for k in range(5)]
    rows += [{"solver": "cascade-daqp", "warm_start": "n/a", "step": k, "solve_time_min_s": 1e-3, "iterations": 1,
              "activations": 0} for k in range(5)]
    return pd.DataFrame(rows)


def test_claim_d_is_about_time_warm_start():
    # hcod without warm start (0.4 ms) is not the paper's warm-started 3 ms figure
    c = claim_d(_scenario({"none": 4e-4, "stage": 3e-4}))
    assert c.status == MISSING and "none, stage" in c.measured, c.measured
    c = claim_d(_scenario({"none": 4e-4, "time": 1e-4}))
    assert c.status == PASS and "hcod (time warm start) 0.100 ms" in c.measured, c.measured
    no_column = _scenario({"time": 1e-3}).drop(columns="warm_start")
    c = claim_d(no_column)
    assert c.status == FAIL and "warm start not recorded" in c.measured, c.measured
    assert np.isclose(float(c.measured.split(";")[0].split(": ")[-1].rstrip("x")), 1.0)
