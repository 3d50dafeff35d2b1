"""A small typed schema for the values a user gives: the files (suite, stack and
scenario TOML), a solver's options, a problem family's parameters, a task's
numbers. One place that says what a value may be and how its error reads, one line each.

Why a module of our own rather than pydantic or msgspec: the errors must be
one line naming the file, the key path (``events[2].time``) and what was
expected, with the close matches of a misspelt key (difflib) and the value
that was given; both libraries would need their error objects rewritten into
that form, their unknown-key errors carry no close matches, and NaN passes
their float type unless every field is constrained. What the files need (a
few scalar types with ranges, lists, tables with known keys) fits in the
classes below, without a new core dependency.

Usage::

    SCHEMA = Table({"dt": Number(low=0, low_open=True, unit="s"), "tags": List(Str())},
                   required=("dt",))
    data = read_toml(path, MyError, "a scenario")        # one-line errors for bytes and syntax
    SCHEMA.check(data, Where(str(path), MyError))        # raises MyError naming path and key

A value's error reads ``FILE: KEY.PATH = VALUE: expected WHAT``; an unknown key
``FILE: unknown key KEY.PATH (did you mean 'x'?); expected one of a, b``; a
missing one ``FILE: KEY.PATH: missing key 'k' (WHAT)``.

The same types check a value given in code or on a command line, where the
place (:class:`Where` and its subclasses) says how the error reads:

    checked(Number(1, unit="a condition number"), cond, "cond", MyError)
        # MyError("cond must be a finite number >= 1 (a condition number); got 0.5")
    Number(0, 1, high_open=True).check(rtol, "rank_rtol", Option("nullspace-svd", SolverOptionError))
        # "nullspace-svd: option rank_rtol=2 is not allowed; expected a finite number >= 0 and < 1"
"""

from __future__ import annotations

import difflib
import math
import tomllib
from dataclasses import dataclass
from numbers import Integral, Real
from pathlib import Path

import numpy as np

from hikbench.problems.errors import HikbenchError

__all__ = ["Any", "Bool", "Int", "List", "Named", "Number", "Option", "SchemaError", "Str", "Table", "Vec",
           "Where", "checked", "read_toml", "short"]

SHORT_REPR = 60  # characters of a value quoted in an error


#: upper bounds of the counts (repetitions, samples, rounds, warm-up solves, steps) and of the durations
#: (timeouts, budgets) a file or an option takes: far beyond any real run, and small enough that what is
#: sized from them (sample arrays, deadlines passed to the OS's timers) fits the machine
MAX_COUNT = 1_000_000
MAX_SECONDS = 7 * 24 * 3600.0  # one week


def check_at_most(option: str, value, high, what: str) -> None:
    """HikbenchError ``--repeat must be <= 1000000 (WHAT); got 1000000000000`` when ``value``
    (None: not given) is larger than ``high``."""
    if value is not None and value > high:
        raise HikbenchError(f"{option} must be <= {_num(high)} ({what}); got {_num(value)}")


class SchemaError(HikbenchError, ValueError):
    """A file's value that does not fit its schema (used when the caller names no error class)."""


def short(value) -> str:
    """``repr(value)`` on one line, cut to SHORT_REPR characters."""
    text = " ".join(repr(value).split())
    return text if len(text) <= SHORT_REPR else text[: SHORT_REPR - 4] + " ..."


@dataclass(frozen=True)
class Where:
    """The file being checked (``where``: its name as errors print it) and the
    HikbenchError subclass its errors are raised as."""

    where: str
    error: type[HikbenchError] = SchemaError

    def fail(self, path: str, value, expected: str, choices=None):
        """Raise ``FILE: PATH = VALUE: expected EXPECTED``, with the close matches of
        ``value`` among ``choices`` when given."""
        at = f"{path} = {short(value)}: " if path else f"{short(value)}: "
        raise self.error(f"{self.where}: {at}expected {expected}{_close(value, choices)}")

    def say(self, message: str):
        """Raise ``FILE: MESSAGE``."""
        raise self.error(f"{self.where}: {message}")


@dataclass(frozen=True)
class Named(Where):
    """A value given in code or on a command line (a family's parameter, a task's gain):
    ``[WHERE: ]PATH must be EXPECTED; got VALUE``, ``where`` an optional prefix
    (``family 'ik-like'``)."""

    where: str = ""

    def fail(self, path: str, value, expected: str, choices=None):
        at = f"{self.where}: " if self.where else ""
        raise self.error(f"{at}{path} must be {expected}; got {short(value)}{_close(value, choices)}")

    def say(self, message: str):
        raise self.error(f"{self.where}: {message}" if self.where else message)


@dataclass(frozen=True)
class Option(Where):
    """A solver's (or a controller's) option, ``where`` its name:
    ``SOLVER: option PATH=VALUE is not allowed; expected EXPECTED``."""

    def fail(self, path: str, value, expected: str, choices=None):
        raise self.error(f"{self.where}: option {path}={value!r} is not allowed; expected {expected}"
                         f"{_close(value, choices)}")


def checked(field: "Field", value, name: str, error: type[HikbenchError] = SchemaError, where: str = ""):
    """``value`` when it fits ``field``; else ``error`` naming it (:class:`Named`)."""
    return field.check(value, name, Named(where, error))


def _join(path: str, key) -> str:
    if isinstance(key, int):
        return f"{path}[{key}]"
    return f"{path}.{key}" if path else str(key)


class _Misfit(Exception):
    """Raised by :class:`_Probe`: the value does not fit (caught by :meth:`Field.fits`)."""


class _Probe(Where):
    def fail(self, path, value, expected, choices=None):
        raise _Misfit

    def say(self, message):
        raise _Misfit


class Field:
    """A value's type; ``what`` says it in an error ("an integer >= 1")."""

    what = "a value"

    def check(self, value, path: str, at: Where):
        """``value`` (tables: with their defaults filled), or raise through ``at``."""
        raise NotImplementedError

    def fits(self, value) -> bool:
        """Whether ``value`` fits, without an error."""
        try:
            self.check(value, "", _Probe(""))
        except _Misfit:
            return False
        return True


class Any(Field):
    """Anything (checked by the code that uses it)."""

    def __init__(self, what: str = "a value"):
        self.what = what

    def check(self, value, path, at):
        return value


class Bool(Field):
    """True or False (not 0 / 1, not a string); numpy's bool too. ``what``: ``"true or
    false"`` as a file spells them, ``"True or False"`` for a Python value."""

    def __init__(self, what: str = "true or false"):
        self.what = what

    def check(self, value, path, at):
        if not isinstance(value, (bool, np.bool_)):
            at.fail(path, value, self.what)
        return bool(value)




def _num(v) -> str:
    return str(v) if isinstance(v, int) else f"{v:g}"


def _range_text(low, high, low_open, high_open) -> str:
    """``>= 0``, ``< 1``, ``> 0 and <= 1``."""
    parts = []
    if low is not None:
        parts.append(f"{'>' if low_open else '>='} {_num(low)}")
    if high is not None:
        parts.append(f"{'<' if high_open else '<='} {_num(high)}")
    return " and ".join(parts)


class Number(Field):
    """A finite real number (an integer or a float, numpy's too, not a bool) in a range.

    ``integer``: an integer (``whole_floats``: a float with an integer value, 3.0, too,
    returned as an int); ``none_ok``: None too; ``unit``: said after the range, in
    parentheses."""

    def __init__(self, low=None, high=None, *, low_open=False, high_open=False, unit="", integer=False,
                 whole_floats=False, none_ok=False, what=""):
        self.low, self.high, self.low_open, self.high_open = low, high, low_open, high_open
        self.integer, self.whole_floats, self.none_ok = integer, whole_floats, none_ok
        rng = _range_text(low, high, low_open, high_open)
        kind = "an integer" if integer else "a finite number"
        self.what = what or (f"{kind}{' ' + rng if rng else ''}{f' ({unit})' if unit else ''}"
                             f"{' or None' if none_ok else ''}")

    def check(self, value, path, at):
        if value is None and self.none_ok:
            return None
        if isinstance(value, (bool, np.bool_)) or not self._type_ok(value) or not math.isfinite(value) \
                or not self._in_range(value):
            at.fail(path, value, self.what)
        return int(value) if self.integer and isinstance(value, float) else value

    def _type_ok(self, value) -> bool:
        if not self.integer:
            return isinstance(value, Real)
        if isinstance(value, Integral):
            return True
        return self.whole_floats and isinstance(value, float) and math.isfinite(value) and value == int(value)

    def _in_range(self, v) -> bool:
        low_ok = self.low is None or (v > self.low if self.low_open else v >= self.low)
        return low_ok and (self.high is None or (v < self.high if self.high_open else v <= self.high))


def Int(low=None, high=None, unit="", *, none_ok=False) -> Number:  # noqa: N802 - a type, like the classes
    """An integer (not a bool, not a float) in [low, high]; None too with ``none_ok``."""
    return Number(low, high, unit=unit, integer=True, none_ok=none_ok)


class Str(Field):
    """A string (non-empty unless ``empty``), one of ``choices`` when given."""

    def __init__(self, choices=None, *, empty=False, what=""):
        self.choices, self.empty = (tuple(choices) if choices is not None else None), empty
        self.what = what or (f"one of {', '.join(map(repr, self.choices))}" if self.choices is not None else
                             "a string" if empty else "a non-empty string")

    def check(self, value, path, at):
        if not isinstance(value, str) or (not self.empty and not value) or \
                (self.choices is not None and value not in self.choices):
            at.fail(path, value, self.what + _close(value, self.choices))
        return value


def _close(value, choices) -> str:
    """`` (did you mean 'x'?)`` for a misspelt string among ``choices``."""
    if not isinstance(value, str) or not choices:
        return ""
    near = difflib.get_close_matches(value, list(choices), n=2)
    return f" (did you mean {' or '.join(map(repr, near))}?)" if near else ""


class List(Field):
    """A list of ``item`` with ``min_len`` to ``max_len`` entries. ``sequences``: a tuple
    or a 1-D ndarray too (a value from Python); ``whole``: an entry that does not fit is
    reported as the whole list's error (an option's value), not at its index."""

    def __init__(self, item: Field, min_len=1, max_len=None, what="", *, sequences=False, whole=False):
        self.item, self.min_len, self.max_len = item, min_len, max_len
        self.sequences, self.whole = sequences, whole
        size = (f"{min_len}" if max_len == min_len else
                f"a non-empty list" if min_len == 1 and max_len is None else "a list")
        self.what = what or (f"{size} of {_plural(item.what)}" if max_len != min_len
                             else f"a list of {size} {_plural(item.what)}")

    def check(self, value, path, at):
        kinds = (list, tuple, np.ndarray) if self.sequences else list
        if not isinstance(value, kinds) or (isinstance(value, np.ndarray) and value.ndim != 1) or \
                len(value) < self.min_len or (self.max_len is not None and len(value) > self.max_len):
            at.fail(path, value, self.what)
        if self.whole and not all(self.item.fits(v) for v in value):
            at.fail(path, value, self.what)
        return [self.item.check(v, _join(path, i), at) for i, v in enumerate(value)]


def _plural(what: str) -> str:
    for article in ("a ", "an "):
        if what.startswith(article):
            return what[len(article):].replace("number", "numbers", 1).replace("string", "strings", 1) \
                .replace("integer", "integers", 1).replace("table", "tables", 1)
    return what


def Vec(n: int, unit: str = "", bound: float | None = None) -> List:  # noqa: N802 - a schema type
    """``n`` finite numbers, e.g. ``[x, y, z]``, each within [-bound, bound] when given."""
    item = Number() if bound is None else Number(-bound, bound)
    within = f" within [-{bound:g}, {bound:g}]" if bound is not None else ""
    return List(item, n, n, what=f"{n} finite numbers{within}{f' ({unit})' if unit else ''}")


class Table(Field):
    """A TOML table with known keys: ``fields`` (key -> Field), the ``required``
    ones, ``defaults`` filled in when absent. ``values`` (a Field) instead
    accepts any string key whose value fits it (``{ right_foot = 0.005 }``)."""

    def __init__(self, fields: dict | None = None, required=(), defaults=None, values: Field | None = None,
                 what=""):
        self.fields, self.required, self.defaults = dict(fields or {}), tuple(required), dict(defaults or {})
        self.values = values
        self.what = what or "a table"

    def check(self, value, path, at):
        if not isinstance(value, dict):
            at.fail(path, value, self.what)
        for key in self.required:
            if key not in value:
                at.say(f"{path + ': ' if path else ''}missing key {key!r} ({self.fields[key].what})")
        out = dict(self.defaults)
        for key, v in value.items():
            field = self.fields.get(key, self.values)
            if field is None:
                self._unknown(key, path, at)
            out[key] = field.check(v, _join(path, key), at)
        return out

    def _unknown(self, key, path, at):
        near = difflib.get_close_matches(str(key), list(self.fields), n=3)
        hint = f" (did you mean {' or '.join(map(repr, near))}?)" if near else ""
        at.say(f"unknown key {_join(path, key)}{hint}; expected some of: {', '.join(self.fields)}")


def read_toml(path, error: type[HikbenchError], what: str) -> dict:
    """The TOML file ``path`` parsed; one-line ``error`` naming the file when it
    cannot be read, is not UTF-8 text, or is not TOML (``what``: "a scenario
    TOML file", said in the error)."""
    p = Path(path)
    try:
        raw = p.read_bytes()
    except OSError as err:
        raise error(f"{p}: cannot read the file: {err.strerror or err}; expected {what}") from err
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as err:
        raise error(f"{p}: not UTF-8 text ({err.reason} at byte {err.start}); expected {what}") from err
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise error(f"{p}: invalid TOML ({' '.join(str(err).split())}); expected {what}") from err
    except RecursionError as err:  # arrays or inline tables nested thousands deep
        raise error(f"{p}: invalid TOML (nested too deeply); expected {what}") from err
