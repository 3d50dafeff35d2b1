"""The sweep of the cascades' settings (hikbench.bench.analysis.settings_sweep, docs/solvers.md
"Fair settings"): its grid and suite, and the choice (most problems verified, then the fastest,
then the plainest) on a results frame made for the purpose."""

from __future__ import annotations

import json
import tomllib

import pandas as pd
import pytest

from hikbench.bench.analysis import settings_sweep as sweep
from hikbench.bench.suites import load_suite


def test_the_suite_holds_every_backends_grid(tmp_path):
    path = tmp_path / "sweep.toml"
    path.write_text(sweep.suite_text())
    data = tomllib.loads(path.read_text())
    by_solver = {}
    for s in data["settings"]:
        by_solver.setdefault(s["solver"], []).append(s["options"])
    assert sorted(by_solver) == sorted(f"cascade-{b}" for b in sweep.BACKENDS)
    assert len(by_solver["cascade-quadprog"]) == 9 and len(by_solver["cascade-osqp"]) == 27
    assert len(by_solver["cascade-daqp"]) == 36
    assert {"tolerances": "high", "freeze": "relaxed", "regularization": 1e-10, "max_iter": 10000} in \
        by_solver["cascade-daqp"]
    suite = load_suite(str(path))
    assert list(suite.modes) == ["cold"] and suite.repeat == 3 and suite.timeout == 5.0


def _row(settings, problem, verified, t, options):
    return {"solver": "cascade-daqp", "settings": settings, "problem": problem, "yardstick": "certified",
            "verified_high": verified, "verified_default": verified, "verified_low": True,
            "time_median_s": t, "options": json.dumps(options)}


@pytest.mark.parametrize("t_plain, chosen", [(1.05e-3, "plain"), (2e-3, "capped")],
                         ids=["within-noise", "slower"])
def test_the_choice_is_the_most_solved_then_the_fastest_then_the_plainest(t_plain, chosen):
    plain = {"tolerances": "high", "freeze": "shift", "regularization": 1e-12}
    capped = {**plain, "max_iter": 10000}
    loose = {**plain, "regularization": 1e-8}
    rows = [_row(name, p, ok, t, opts) for name, opts, t, oks in (
        ("plain", plain, t_plain, (True, True, True)),
        ("capped", capped, 1e-3, (True, True, True)),
        ("loose", loose, 1e-4, (True, True, False)))   # fastest, but one problem fewer at high
        for p, ok in zip(("a", "b", "c"), oks)]
    got = sweep.choose(pd.DataFrame(rows))
    high = got[("cascade-daqp", "high")]
    assert (high["settings"], high["solved"], high["of"], high["union"]) == (chosen, 3, 3, 3)
    low = got[("cascade-daqp", "low")]
    assert low["settings"] == "loose" and low["solved"] == 3
    assert got[("cascade-daqp", "high")]["table"]["loose"]["solved"] == 2
