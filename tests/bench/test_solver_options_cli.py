"""A bad solver option value on the command line: exit 2 with one line on
stderr naming solver, option, value and what is expected; no traceback."""

import numpy as np
import pytest

from hikbench.bench.cli import main
from hikbench.problems import Hierarchy, Level
from hikbench.problems.files import save_npz
from hikbench.solvers import registry


@pytest.fixture
def problem(tmp_path):
    """level 0: a box [-1, 1]^2; level 1: x0 + x1 = 1."""
    h = Hierarchy.from_levels([Level(np.eye(2), [-1.0, -1.0], [1.0, 1.0], "box"),
                               Level.equality([[1.0, 1.0]], [1.0], "task")])
    path = tmp_path / "p.npz"
    save_npz(h, path)
    return str(path)


@pytest.mark.parametrize("solver, option, message", [
    ("dls", "damping=abc", "dls: option damping='abc' is not allowed; expected a finite number >= 0"),
    ("dls", "damping=[1]", "dls: option damping=[1] is not allowed; expected a finite number >= 0"),
    ("dls-liegeois", "tol=abc", ("dls-liegeois: option tol='abc' is not allowed; expected a finite "
                                 "number > 0")),
    ("weighted", 'weights={"a":1}', ("weighted: option weights={'a': 1} is not allowed; expected a non-empty "
                                     "list of finite numbers >= 0, one weight per level")),
    ("weighted", "weights=[1,nan]", ("weighted: option weights='[1,nan]' is not allowed; expected a "
                                     "non-empty list of finite numbers >= 0, one weight per level")),
    ("nullspace-svd", "rank_rtol=abc", ("nullspace-svd: option rank_rtol='abc' is not allowed; expected a "
                                        "finite number >= 0 and < 1")),
    ("cascade-osqp", "slack_tol=abc", ("cascade-osqp: option slack_tol='abc' is not allowed; expected a "
                                       "finite number >= 0 or None")),
], ids=["dls-damping-str", "dls-damping-list", "liegeois-tol", "weights-dict", "weights-nan",
        "nullspace-rank_rtol", "cascade-slack_tol"])
def test_bad_option_value_exits_2_with_one_line(capsys, problem, solver, option, message):
    if solver not in registry.available():
        pytest.skip(f"{solver} is not installed")
    code = main(["solve", problem, "--solver", solver, "--option", option])
    _, err = capsys.readouterr()
    assert code == 2
    assert err.strip().splitlines() == [f"hikbench solve: error: {message}"], err
