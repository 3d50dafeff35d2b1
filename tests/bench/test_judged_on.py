"""A solver whose levels are row-normalised (Solver.judged_on, DAQP's hierarchical QP) is judged
by hikbench run against the yardstick of the row-normalised hierarchy, and its row says so."""

import json

import numpy as np
import pytest
import tomli_w

from hikbench.bench.cli import main
from hikbench.bench.harness.results import read_results
from hikbench.problems.generators import generate
from hikbench.problems.hierarchy import row_normalised
from hikbench.problems.verify import level_norms
from hikbench.solvers import registry

#: conflicting levels (level 1's 4 rows in the 2 directions level 0 leaves) whose rows' norms spread
#: over 100x: the optimum of the rows as given and that of the row-normalised rows differ from level 1
#: on. (With shared_rank 2, levels of rank 2 have full rank once each row is divided by its rounded
#: norm: the exact optimum of the row-normalised rows, of norm 5e16, is refused as rank-deficient
#: only to rounding.)
PARAMS = {"n": 6, "depth": 3, "rows": 4, "row_scale": 100.0, "inequality": "none", "box": False}


@pytest.fixture(scope="module")
def judged_run(tmp_path_factory):
    d = tmp_path_factory.mktemp("judged")
    suite = {"repeat": 1, "warmup": 0, "timeout": 30.0, "modes": ["cold"], "solvers": ["daqp-hqp"],
             "problems": [{"family": "random", "params": PARAMS, "seeds": [0]}],
             "settings": [{"solver": "daqp-hqp", "name": "as-given", "options": {"normalised": False}}]}
    (d / "s.toml").write_bytes(tomli_w.dumps(suite).encode())
    assert main(["run", "--quiet", "--suite", str(d / "s.toml"), "--out", str(d / "out")]) == 0
    return read_results(d / "out").set_index("settings")


def test_the_row_normalised_claim_is_judged_on_the_row_normalised_hierarchy(judged_run):
    row = judged_run.loc["default"]
    assert row["status"] == "optimal" and row["verified"] == True  # noqa: E712 - (a numpy bool)
    assert row["yardstick_reason"].startswith("judged on the row-normalised hierarchy (the solver's claim): ")
    # its yardstick's norms are the optimum of the row-normalised hierarchy (hcod's), not the raw one's
    h = generate("random", seed=0, **PARAMS)
    hn = row_normalised(h)
    ref = np.array(json.loads(row["ref_level_norms"]))
    np.testing.assert_allclose(ref, level_norms(hn, registry.create("hcod").solve(hn).x), rtol=1e-6, atol=1e-9)
    raw = np.array(json.loads(judged_run.loc["as-given", "ref_level_norms"]))
    np.testing.assert_allclose(raw, level_norms(h, registry.create("hcod").solve(h).x), rtol=1e-6, atol=1e-9)


def test_the_same_x_claimed_on_the_rows_as_given_is_worse_where_levels_conflict(judged_run):
    row = judged_run.loc["as-given"]
    assert row["status"] == "optimal" and row["verified"] == False  # noqa: E712
    assert row["verdict_side"] == "worse" and row["verdict_level"] >= 1
    assert not row["yardstick_reason"].startswith("judged on")


@pytest.mark.parametrize("options, judged_on, optimal", [([], "row-normalised", True),
                                                         (["--option", "normalised=false"], "rows", False)],
                         ids=["row-normalised", "as-given"])
def test_solve_certifies_x_on_the_hierarchy_the_solver_claims(tmp_path, capsys, options, judged_on, optimal):
    from hikbench.problems.files import save_npz
    from hikbench.problems.hierarchy import Hierarchy, Level

    # level 1: x_1 = 0.5 and 10 x_1 = 0 conflict, their rows' norms 1 and 10
    h = Hierarchy.from_levels([Level(np.eye(2), -np.ones(2), np.ones(2)),
                               Level.equality(np.array([[1.0, 0.0], [10.0, 0.0]]), [0.5, 0.0]),
                               Level.equality(np.eye(2), [0.0, 0.3])])
    save_npz(h, tmp_path / "c.npz")
    code = main(["solve", str(tmp_path / "c.npz"), "--solver", "daqp-hqp", "--certify", "--json", *options])
    assert code == (0 if optimal else 1)  # (--certify exits 1 when x is not optimal)
    cert = json.loads(capsys.readouterr().out)["certificate"]
    assert cert["certified"] and cert["judged_on"] == judged_on
    assert cert["x_is_optimal"] is optimal


def test_a_class_claiming_an_unknown_hierarchy_is_refused_naming_it(tmp_path, capsys):
    (tmp_path / "mine.py").write_text(
        "import numpy as np\n"
        "from hikbench.solvers.base import OPTIMAL, Solver, SolveResult\n"
        "class Mine(Solver):\n"
        "    name = 'mine'\n"
        "    judged_on = 'columns'\n"
        "    def solve(self, h):\n"
        "        return SolveResult(np.zeros(h.n), OPTIMAL)\n")
    suite = {"repeat": 1, "modes": ["cold"], "solvers": [f"{tmp_path / 'mine.py'}:Mine"],
             "problems": [{"family": "random", "params": PARAMS, "seeds": [0]}]}
    (tmp_path / "s.toml").write_bytes(tomli_w.dumps(suite).encode())
    assert main(["run", "--quiet", "--suite", str(tmp_path / "s.toml"), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "judged_on = 'columns': expected 'rows' or 'row-normalised'" in err
