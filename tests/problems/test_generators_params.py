"""Generator parameters are checked where they enter, with messages naming them
(no numpy traceback or warning, no 'level 1, row 0: A holds NaN')."""

import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hikbench.problems.errors import HikbenchError
from hikbench.problems.generators import FAMILIES, degenerate, equality_stack, generate, ik_like, random_hierarchy
from hikbench.problems.hierarchy import Hierarchy


@pytest.mark.parametrize("params, message", [
    ({"cond": float("inf")}, r"cond must be a finite number >= 1 .*; got inf"),
    ({"cond": 0.5}, r"cond must be a finite number >= 1"),
    ({"cond": float("nan")}, r"cond must be a finite number >= 1"),
    ({"cond": "big"}, r"cond must be a finite number >= 1 .*; got 'big'"),
    ({"row_scale": float("inf")}, r"row_scale must be a finite number >= 1"),
    ({"box_bound": -1.0}, r"box_bound must be a finite number >= 0 .*; got -1.0"),
    ({"box_bound": float("inf")}, r"box_bound must be a finite number >= 0"),
    ({"equality_fraction": 1.5}, r"equality_fraction must be a finite number >= 0 and <= 1; got 1.5"),
    ({"equality_fraction": float("nan")}, r"equality_fraction must be a finite number >= 0 and <= 1"),
    ({"rows": -1}, r"rows must be >= 0 \(per level\); got -1"),
    ({"seed": -1}, r"seed must be an integer >= 0; got -1"),
    ({"seed": 1.5}, r"seed must be an integer >= 0; got 1.5"),
    ({"shared_rank": None}, r"shared_rank must be an integer >= 0 or one per level; got None"),
], ids=["cond inf", "cond < 1", "cond nan", "cond string", "row_scale inf", "box_bound negative",
        "box_bound inf", "equality_fraction > 1", "equality_fraction nan", "rows negative", "seed negative",
        "seed fraction", "shared_rank None"])
def test_random_hierarchy_parameters(params, message):
    base = {"n": 6, "depth": 2, "rows": 3, "box": True}
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(HikbenchError, match=message):
            random_hierarchy(**{**base, **params})


@pytest.mark.parametrize("make, message", [
    (lambda: equality_stack(6, 2, 3, seed=-1), "seed must be an integer >= 0; got -1"),
    (lambda: ik_like(6, seed=-2), "seed must be an integer >= 0; got -2"),
    (lambda: ik_like(2.5), "n must be an integer; got 2.5"),
    (lambda: degenerate("saturated", seed=-1), "seed must be an integer >= 0; got -1"),
    (lambda: degenerate("saturated", n=0), "degenerate needs n >= 1; got 0"),
    (lambda: generate("random", seed=-1), "seed must be an integer >= 0; got -1"),
], ids=["equality", "ik-like seed", "ik-like n", "degenerate seed", "degenerate n", "generate"])
def test_family_seeds_and_sizes(make, message):
    with pytest.raises(HikbenchError, match=message):
        make()


@pytest.mark.parametrize("params", [{"box_bound": 0.0}, {"cond": 1e12, "row_scale": 1e6},
                                    {"equality_fraction": 1.0, "inequality": "mixed"}],
                         ids=["zero box", "large cond", "all equalities"])
def test_edge_values_still_generate(params):
    h = random_hierarchy(6, 2, 3, box=True, **params)
    assert h.n == 6 and h.depth == 3


@pytest.mark.parametrize("family, params", [("ik-like", {"n": 8}), ("random", {"n": 6}), ("equality", {"n": 6}),
                                            ("degenerate", {"case": "free_rows"})],
                         ids=["ik-like", "random", "equality", "degenerate"])
def test_bound_scale_multiplies_every_bound(family, params):
    """Every family takes ``bound_scale``: the same rows, every bound (equality targets too)
    times it; the default is 1 (the problem unchanged)."""
    h = generate(family, seed=3, **params)
    assert generate(family, seed=3, bound_scale=1.0, **params) == h
    hs = generate(family, seed=3, bound_scale=1e-9, **params)
    np.testing.assert_array_equal(hs.A, h.A)
    np.testing.assert_array_equal(hs.lower, h.lower * 1e-9)
    np.testing.assert_array_equal(hs.upper, h.upper * 1e-9)


@pytest.mark.parametrize("value", [0, -1.0, float("inf"), float("nan"), "small", True],
                         ids=["zero", "negative", "inf", "nan", "string", "bool"])
def test_bad_bound_scale(value):
    with pytest.raises(HikbenchError, match=r"family 'ik-like': bound_scale must be a finite number > 0 "
                                            r"\(it multiplies every bound\); got "):
        generate("ik-like", bound_scale=value)


#: values of every type, sizes small (a float 3e4 is an integer n too: its n x n matrices would not be)
PARAM_VALUES = st.one_of(st.none(), st.booleans(), st.integers(-3, 12), st.floats(-3, 12),
                         st.sampled_from([float("nan"), float("inf"), -float("inf"), 1e300]),
                         st.text(max_size=4), st.sampled_from(["mixed", "rank_deficient", "none"]),
                         st.lists(st.integers(0, 4), max_size=3))


@pytest.mark.parametrize("family", list(FAMILIES), ids=list(FAMILIES))
@settings(max_examples=40, deadline=None)
@given(data=st.data())
def test_any_parameter_value_gives_a_problem_or_one_line_naming_it(family, data):
    """A family's parameter with any value: a problem, or a HikbenchError on one line that
    names the parameter (its checks go through hikbench.problems.schema)."""
    fam = FAMILIES[family]
    key = data.draw(st.sampled_from(sorted(fam.defaults)), label="parameter")
    value = data.draw(PARAM_VALUES, label="value")
    try:
        h = fam.generate(seed=0, **{key: value})
    except HikbenchError as err:
        message = str(err)
        assert "\n" not in message and key in message, message
    else:
        assert isinstance(h, Hierarchy)
