"""A suite's ``module:function`` problem family that is not one, raises or returns
something other than a Hierarchy stops the run with one line naming the family and
the seed (exit 2), before any job."""

from __future__ import annotations

import re

import pytest
import tomli_w
from clitools import assert_user_error, run

FAMILIES = '''
import numpy as np

def raises(seed=0, **params):
    raise ValueError("no problem today")

def none(seed=0, **params):
    return None

def array(seed=0, **params):
    return np.eye(3)

not_a_function = 42
'''


@pytest.mark.parametrize("func, expected", [
    ("raises", r"family '.*fam\.py:raises', seed 0: calling it raised ValueError: no problem today at fam\.py:5"),
    ("none", r"family '.*fam\.py:none', seed 0: returned NoneType; expected a hikbench\.problems\.hierarchy\.Hierarchy"),
    ("array", r"family '.*fam\.py:array', seed 0: returned ndarray; expected a hikbench\.problems\.hierarchy"),
    ("not_a_function", r"family '.*fam\.py:not_a_function', seed 0: int is not a function"),
    ("os:getcwd", r"family 'os:getcwd', seed 0: calling it raised TypeError: "),
], ids=["raises", "returns-none", "returns-array", "not-callable", "not-a-family"])
def test_a_broken_user_family_is_one_line(tmp_path, capsys, func, expected):
    (tmp_path / "fam.py").write_text(FAMILIES)
    family = func if ":" in func else f"{tmp_path / 'fam.py'}:{func}"
    suite = tmp_path / "s.toml"
    suite.write_text(tomli_w.dumps({"repeat": 1, "modes": ["cold"], "solvers": ["yardstick"],
                                    "problems": [{"family": family, "seeds": [0]}]}))
    code, _, err = run(capsys, "run", "--quiet", "--suite", suite, "--out", tmp_path / "out")
    assert_user_error(code, err, "hikbench run: error: ")
    assert re.search(expected, err), err
    assert not (tmp_path / "out" / "results.csv").exists()
