"""SOTH's text problem format: import and export (docs/problem-files.md).

The format, as read by ``readProblemFromFile`` and written by
``writeProblemToFile`` in SOTH's ``unitTesting/RandomGenerator.cpp``
(github stack-of-tasks/soth)::

    variable size n

    level

    equalities k
    a_1 ... a_n   b          (k rows)

    inequalities m
    a_1 ... a_n   lo hi      (m rows)

    level
    ...

    end

Facts taken from SOTH's reader and writer (no code copied):

* The reader is a whitespace-token stream (``std::ifstream >>``): line breaks
  and blank lines carry no meaning and a row may span lines. There are no
  comments. This module reads the same token stream.
* After each level, the next token decides: ``level`` starts another level,
  anything else ends the problem (the writer writes ``end``). Here the closing
  token must be ``end`` and nothing may follow it.
* In a level, the equality rows come first, then the inequality rows: the
  level's matrix is ``[J_eq; J_ineq]``.
* An inequality row ``lo hi`` with ``lo < -1e10`` is read by SOTH as upper
  bound only, with ``hi > 1e10`` as lower bound only, else as a double bound.
  The writer puts ``-1e25`` / ``1e25`` for a missing side.
* SOTH's reader asserts that every level has at least one row and refuses a
  row with both sides missing (a free row).

What this module does (the hikbench side):

* **Infinite bounds.** On export a missing side is written ``-1e+25`` /
  ``1e+25``. On import ``lo <= -1e25`` reads as ``-inf`` and ``hi >= 1e25`` as
  ``+inf``: **a bound of magnitude >= 1e25 on its missing side means "no
  bound"**. (SOTH itself already treats ``|bound| > 1e10`` as missing: a finite
  bound between 1e10 and 1e25 survives a hikbench round-trip but SOTH would
  drop it.) A finite ``lower <= -1e25`` or ``upper >= 1e25`` cannot be written
  without changing its meaning and raises :class:`ProblemFileError`.
* **Row order.** Equality rows (``lower == upper``) of a level are written in
  the ``equalities`` block, all other rows (one-sided, two-sided and free) in
  the ``inequalities`` block, each block in the original row order. This
  *reorders* the rows of a level whose equality rows are not already first;
  :func:`soth_order` gives the hierarchy in the order a round-trip returns.
  An inequality row read with ``lo == hi`` becomes an equality row.
* **Free rows** are written as inequalities ``-1e+25 1e+25``; **empty levels**
  as ``equalities 0`` / ``inequalities 0``. Both survive a hikbench
  round-trip, but SOTH's own reader asserts on them (see above).
* **Numbers** are written with Python's ``repr`` of a float, the shortest
  decimal string that reads back to the same double, so ``A`` and the bounds
  round-trip exactly (``-0.0`` included). Subnormal numbers (``|v| < 2.2e-308``)
  round-trip here but some C++ standard libraries refuse to read them.
* **Lost on the way:** level names and ``x0`` (the format has no place for
  them); a loaded hierarchy has the default names ``"level k"``.

Parse errors raise :class:`ProblemFileError` with the line number and what was
expected; a well-formed file whose numbers do not make a valid hierarchy
(``lo > hi``) raises :class:`InvalidHierarchyError`, with the line and the
row counted as the file counts it ("level 0, inequality row 0"; the error's
``row`` attribute counts the level's rows, equalities first).
"""

from __future__ import annotations

import math
import os
import re

import numpy as np

from hikbench.problems.errors import InvalidHierarchyError, ProblemFileError
from hikbench.problems.hierarchy import Hierarchy

__all__ = ["NO_BOUND", "SOTH_NO_BOUND", "from_soth_text", "load_soth", "save_soth", "soth_order", "to_soth_text"]

NO_BOUND = 1e25  #: magnitude written for a missing side; |bound| >= NO_BOUND reads as no bound
SOTH_NO_BOUND = 1e10  #: SOTH's own reader takes an inequality bound beyond +-1e10 as no bound


def _num(v: float) -> str:
    return repr(float(v))


def _row(a: np.ndarray, *tail: float) -> str:
    return " ".join(_num(v) for v in a) + "   " + " ".join(_num(v) for v in tail)


def soth_order(h: Hierarchy) -> Hierarchy:
    """h with, inside each level, the equality rows first (stable order), as
    :func:`from_soth_text` returns ``to_soth_text(h)``; names and x0 are kept."""
    order = np.lexsort((~h.is_equality, h.level))  # by level, then equalities first; stable
    return Hierarchy(h.A[order], h.lower[order], h.upper[order], h.level[order], n=h.n,
                     depth=h.depth, names=h.names, x0=h.x0)


def to_soth_text(h: Hierarchy) -> str:
    """The SOTH text of h (see the module docstring for row order and bounds).

    Raises
    ------
    ProblemFileError
        A finite ``lower <= -1e25`` or ``upper >= 1e25`` (it would read back as
        no bound).
    """
    lines = [f"variable size {h.n}", ""]
    for k in range(h.depth):
        s = h.level_rows(k)
        A, lo, up = h.A[s], h.lower[s], h.upper[s]
        eq = lo == up
        for i in np.flatnonzero(~eq):
            for side, value, bad in (("lower", lo[i], lo[i] <= -NO_BOUND),
                                     ("upper", up[i], up[i] >= NO_BOUND)):
                if bad and math.isfinite(value):
                    raise ProblemFileError(
                        f"level {k}, row {i}: finite {side} bound {float(value)!r} "
                        f"has magnitude >= {NO_BOUND:g}, "
                        f"which the SOTH format reads as no bound; rescale the row")
        lines += ["level", "", f"equalities {int(eq.sum())}"]
        lines += [_row(A[i], lo[i]) for i in np.flatnonzero(eq)]
        lines += ["", f"inequalities {int((~eq).sum())}"]
        lines += [_row(A[i], max(lo[i], -NO_BOUND), min(up[i], NO_BOUND)) for i in np.flatnonzero(~eq)]
        lines.append("")
    lines += ["end", ""]
    return "\n".join(lines)


_TOKEN = re.compile(r"\S+")
_BREAKS = "\n\r\x0b\x0c\x1c\x1d\x1e"  # (str.splitlines' line breaks in ASCII text)
_LINE = re.compile(f"[^{_BREAKS}]*(?:\r\n|[{_BREAKS}])?")
_LONG_LINE = 1 << 16  # characters: a longer line is split one token at a time


def _tokens(text: str):
    """(line number, token) of each whitespace token of ``text``, one at a time: no list of
    every token (nor of every line) is made, so a file refused at its third token costs
    nothing for the rest (a 40 MB line would be 10 million strings)."""
    line = 0
    for m in _LINE.finditer(text):
        a, b = m.span()
        if a == len(text):
            break
        line += 1
        toks = text[a:b].split() if b - a <= _LONG_LINE else (t.group() for t in _TOKEN.finditer(text, a, b))
        for tok in toks:
            yield line, tok


class _Tokens:
    """Whitespace tokens with their line numbers (:func:`_tokens`), and parse helpers that
    raise ProblemFileError naming the line and what was expected."""

    def __init__(self, text: str, source: str):
        self.source = source
        self._text = text
        self._it = _tokens(text)
        self._ahead = next(self._it, None)
        self.line = 1  # line of the last token read

    @property
    def _eof_line(self) -> int:
        return max(1, sum(1 for m in _LINE.finditer(self._text) if m.start() < len(self._text)))

    @property
    def at_end(self) -> bool:
        return self._ahead is None

    def next(self, expected: str) -> str:
        if self.at_end:
            raise ProblemFileError(
                f"{self.source}: line {self._eof_line}: expected {expected}, got end of file")
        self.line, tok = self._ahead
        self._ahead = next(self._it, None)
        return tok

    def fail(self, expected: str, tok: str) -> ProblemFileError:
        return ProblemFileError(f"{self.source}: line {self.line}: expected {expected}, got {tok!r}")

    def keyword(self, word: str) -> None:
        tok = self.next(f"'{word}'")
        if tok != word:
            raise self.fail(f"'{word}'", tok)

    def count(self, what: str) -> int:
        tok = self.next(what)
        if not (tok.isascii() and tok.isdigit()):
            raise self.fail(what + " (a nonnegative integer)", tok)
        return int(tok)

    def number(self, what: str) -> float:
        tok = self.next(what)
        try:
            if "_" in tok:  # Python's float() reads 1_0 as 10; C++'s >> (SOTH) stops at the "_"
                raise ValueError(tok)
            v = float(tok)
        except ValueError:
            raise self.fail(what + " (a number)", tok) from None
        if math.isnan(v):
            raise self.fail(what + " (a number, not NaN)", tok)
        if math.isinf(v) and tok.lstrip("+-").lower() not in ("inf", "infinity"):  # overflowed, e.g. 1e400
            raise self.fail(what + " (a number within a double's range, |v| < 1.8e308; "
                                   "+-1e25 means no bound)", tok)
        return v


def from_soth_text(text: str, source: str = "<soth text>") -> Hierarchy:
    """Parse SOTH text into a Hierarchy (equality rows first in each level).

    Raises ProblemFileError (with ``source`` and the line number) on a syntax
    error, InvalidHierarchyError when the numbers are not a valid hierarchy."""
    t = _Tokens(text, source)
    t.keyword("variable")
    t.keyword("size")
    n = t.count("the number of variables n")
    rows: list[list[float]] = []
    lower: list[float] = []
    upper: list[float] = []
    level: list[int] = []
    k = 0
    while True:
        tok = t.next("'level' or 'end'")
        if tok == "end":
            break
        if tok != "level":
            raise t.fail("'level' or 'end'", tok)
        t.keyword("equalities")
        m_eq = t.count(f"level {k}: the number of equality rows")
        for r in range(m_eq):
            where = f"level {k}, equality row {r}"
            rows.append([t.number(f"{where}: coefficient a_{j + 1} of {n}") for j in range(n)])
            b = t.number(f"{where}: the target b after {n} coefficients")
            lower.append(b)
            upper.append(b)
            level.append(k)
        t.keyword("inequalities")
        m_in = t.count(f"level {k}: the number of inequality rows")
        for r in range(m_in):
            where = f"level {k}, inequality row {r}"
            rows.append([t.number(f"{where}: coefficient a_{j + 1} of {n}") for j in range(n)])
            lo = t.number(f"{where}: the lower bound after {n} coefficients")
            hi = t.number(f"{where}: the upper bound")
            lo_k = -math.inf if lo <= -NO_BOUND else lo
            hi_k = math.inf if hi >= NO_BOUND else hi
            if lo_k > hi_k:  # named here, in the file's own row count, with its line
                raise InvalidHierarchyError(
                    f"{source}: line {t.line}: {where}: lower ({lo!r}) > upper ({hi!r}): expected lower <= upper",
                    level=k, row=m_eq + r)
            lower.append(lo_k)
            upper.append(hi_k)
            level.append(k)
        k += 1
    if not t.at_end:
        raise t.fail("end of file after 'end'", t.next("end of file"))
    A = np.array(rows, dtype=np.float64).reshape(len(rows), n)
    try:
        return Hierarchy(A, lower, upper, np.array(level, dtype=np.int64), n=n, depth=k)
    except InvalidHierarchyError as err:
        raise InvalidHierarchyError(f"{source}: {err}", level=err.level, row=err.row) from err


def save_soth(h: Hierarchy, path: str | os.PathLike) -> None:
    """Write h as SOTH text to ``path``; raises ProblemFileError when the file
    cannot be written."""
    write_soth_text(to_soth_text(h), path)


def write_soth_text(text: str, path: str | os.PathLike) -> None:
    """Write the text of :func:`to_soth_text` to ``path`` (ProblemFileError
    when the file cannot be written)."""
    try:
        with open(path, "w", encoding="ascii") as f:
            f.write(text)
    except OSError as err:
        raise ProblemFileError(f"{os.fspath(path)}: cannot write ({err.strerror or err})") from err


def load_soth(path: str | os.PathLike) -> Hierarchy:
    """Read a SOTH text file; raises ProblemFileError when it cannot be read or
    parsed (message with the line number)."""
    p = os.fspath(path)
    try:
        with open(p, encoding="ascii") as f:
            text = f.read()
    except (OSError, UnicodeDecodeError) as err:
        why = err.strerror if isinstance(err, OSError) and err.strerror else str(err)
        raise ProblemFileError(f"{p}: cannot read as a SOTH text problem file ({why})") from err
    return from_soth_text(text, source=p)
