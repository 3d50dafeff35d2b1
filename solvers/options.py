"""Checks of a solver's option values, for its constructor: the types of
:mod:`hikbench.problems.schema` read at the place :class:`~hikbench.problems.schema.Option`,
so a wrong value raises SolverOptionError
``<solver>: option <opt>=<value> is not allowed; expected <what>``.
bool is rejected wherever a number is expected (``true`` on the command line is
JSON for True, which Python would take as 1)."""

from __future__ import annotations

import numpy as np

from hikbench.problems.schema import Bool, List, Number, Option, Str
from hikbench.solvers.errors import SolverOptionError

__all__ = ["check_bool", "check_choice", "check_int", "check_number", "check_numbers"]


def _at(solver: str) -> Option:
    return Option(solver, SolverOptionError)


def check_number(solver: str, opt: str, value, *, low: float | None = None, high: float | None = None,
                 low_open: bool = False, high_open: bool = False, none_ok: bool = False) -> float | None:
    """``float(value)`` when value is a finite real number (not a bool) in the
    range given by low / high (open ends with low_open / high_open); None when
    value is None and none_ok; else SolverOptionError naming solver, option,
    value and the expected type and range."""
    field = Number(low, high, low_open=low_open, high_open=high_open, none_ok=none_ok)
    value = field.check(value, opt, _at(solver))
    return None if value is None else float(value)


def check_int(solver: str, opt: str, value, *, low: int = 1, none_ok: bool = False) -> int | None:
    """``int(value)`` when value is an integer (not a bool) >= low; None when
    value is None and none_ok; else SolverOptionError."""
    value = Number(low, integer=True, none_ok=none_ok).check(value, opt, _at(solver))
    return None if value is None else int(value)


def check_choice(solver: str, opt: str, value, choices):
    """value when it is a string among ``choices``; else SolverOptionError
    listing them."""
    return Str(choices, what=f"one of {', '.join(map(str, choices))}").check(value, opt, _at(solver))


def check_bool(solver: str, opt: str, value) -> bool:
    """value when it is True or False (not 0 / 1, not a string); else
    SolverOptionError."""
    return Bool("True or False").check(value, opt, _at(solver))


def check_numbers(solver: str, opt: str, value, *, low: float | None = None, what: str = ""):
    """A non-empty list (or tuple, or 1-D array) of finite real numbers >= low
    as a float ndarray, shape (len,); else SolverOptionError. ``what`` is
    appended to the expectation (e.g. "one weight per level")."""
    item = Number(low)
    rng = item.what[len("a finite number"):]  # " >= 0", or ""
    expected = f"a non-empty list of finite numbers{rng}{', ' + what if what else ''}"
    List(item, what=expected, sequences=True, whole=True).check(value, opt, _at(solver))
    return np.asarray(value, dtype=float)
