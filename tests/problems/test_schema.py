"""problems.schema: one type per kind of value, read at three places (a file, a named
value, a solver's option), each error one line naming the place, the value and what
was expected. Hypothesis draws values of every Python kind a file, a command line or
a caller may give."""

from __future__ import annotations

import math
import re
from numbers import Integral, Real

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hikbench.problems.errors import HikbenchError
from hikbench.problems.schema import Bool, Int, List, Named, Number, Option, SchemaError, Str, Where, checked


class _Err(HikbenchError):
    pass


VALUES = st.one_of(
    st.none(), st.booleans(), st.integers(-10**20, 10**20), st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=8), st.lists(st.floats(-5, 5), max_size=3),
    st.builds(np.float64, st.floats(-1e3, 1e3)), st.builds(np.int64, st.integers(-1000, 1000)),
    st.sampled_from([np.bool_(True), (1.0, 2.0), {"a": 1}, np.array([1.0, 2.0])]),
)
BOUNDS = st.one_of(st.none(), st.floats(-100, 100))


def _fits_number(v, low, high, low_open, high_open, integer) -> bool:
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, Integral if integer else Real) or not math.isfinite(v):
        return False
    return ((low is None or (v > low if low_open else v >= low))
            and (high is None or (v < high if high_open else v <= high)))


PLACES = [
    (Where("suite.toml", _Err), r"^suite\.toml: opt = .*: expected {what}$"),
    (Named("family 'f'", _Err), r"^family 'f': opt must be {what}; got .*$"),
    (Option("hcod", _Err), r"^hcod: option opt=.* is not allowed; expected {what}$"),
]


@settings(max_examples=300, deadline=None)
@given(value=VALUES, low=BOUNDS, high=BOUNDS, low_open=st.booleans(), high_open=st.booleans(),
       integer=st.booleans())
def test_number_accepts_exactly_finite_reals_in_range(value, low, high, low_open, high_open, integer):
    field = Number(low, high, low_open=low_open, high_open=high_open, integer=integer)
    want = _fits_number(value, low, high, low_open, high_open, integer)
    assert field.fits(value) == want
    for at, pattern in PLACES:
        if want:
            assert field.check(value, "opt", at) == value
            continue
        with pytest.raises(_Err) as err:
            field.check(value, "opt", at)
        message = str(err.value)
        assert "\n" not in message
        assert re.match(pattern.format(what=re.escape(field.what)), message), message


@pytest.mark.parametrize("field, what", [
    (Number(0), "a finite number >= 0"),
    (Number(0, 1, low_open=True), "a finite number > 0 and <= 1"),
    (Number(0, 1, high_open=True, none_ok=True), "a finite number >= 0 and < 1 or None"),
    (Number(1, unit="a ratio"), "a finite number >= 1 (a ratio)"),
    (Int(1), "an integer >= 1"),
    (Int(0, 10), "an integer >= 0 and <= 10"),
    (Bool(), "true or false"),
    (Bool("True or False"), "True or False"),
    (Str(("a", "b")), "one of 'a', 'b'"),
    (List(Number(0)), "a non-empty list of finite numbers >= 0"),
], ids=["low", "open-closed", "none-ok", "unit", "int", "int-range", "bool", "bool-python", "choice", "list"])
def test_what_each_type_says(field, what):
    assert field.what == what


@pytest.mark.parametrize("value, fits, kept", [
    (3, True, 3), (3.0, True, 3), (np.int64(4), True, 4), (2.5, False, None), (True, False, None),
    ("3", False, None), (math.inf, False, None),
], ids=["int", "whole-float", "numpy-int", "fraction", "bool", "string", "inf"])
def test_whole_floats(value, fits, kept):
    field = Number(integer=True, whole_floats=True)
    assert field.fits(value) == fits
    if fits:
        got = checked(field, value, "n")
        assert got == kept and isinstance(got, Integral)
    else:
        with pytest.raises(SchemaError, match=r"^n must be an integer; got "):
            checked(field, value, "n")


def test_a_misspelt_choice_gets_its_close_match_at_every_place():
    field = Str(("time", "stage", "none"))
    for at, start in ((Where("f.toml", _Err), "f.toml: warm_start = 'tme': expected one of"),
                      (Named("", _Err), "warm_start must be one of"),
                      (Option("hcod", _Err), "hcod: option warm_start='tme' is not allowed; expected one of")):
        with pytest.raises(_Err) as err:
            field.check("tme", "warm_start", at)
        assert str(err.value).startswith(start) and "(did you mean 'time'?)" in str(err.value), str(err.value)


@settings(max_examples=200, deadline=None)
@given(items=st.lists(st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-5, 5),
                                st.booleans(), st.text(max_size=2)), max_size=4),
       container=st.sampled_from([list, tuple, np.array]))
def test_a_whole_list_is_reported_as_one_value(items, container):
    """``whole``: the error names the option's whole value, whichever entry is wrong."""
    field = List(Number(0), what="a non-empty list of finite numbers >= 0", sequences=True, whole=True)
    try:
        value = container(items)
    except (TypeError, ValueError):  # np.array of mixed types
        return
    good = len(items) > 0 and all(_fits_number(v, 0, None, False, False, False) for v in list(value))
    if good:
        assert field.check(value, "weights", Option("weighted", _Err)) == list(value)
        return
    with pytest.raises(_Err) as err:
        field.check(value, "weights", Option("weighted", _Err))
    assert str(err.value) == (f"weighted: option weights={value!r} is not allowed; expected a non-empty list of "
                              f"finite numbers >= 0")


def test_a_list_in_a_file_names_the_entry():
    with pytest.raises(_Err, match=r"^f\.toml: target\[1\] = nan: expected a finite number$"):
        List(Number()).check([1.0, math.nan], "target", Where("f.toml", _Err))
    with pytest.raises(_Err, match=r"^f\.toml: target = \(1\.0, 2\.0\): expected"):  # a tuple is no TOML list
        List(Number()).check((1.0, 2.0), "target", Where("f.toml", _Err))
