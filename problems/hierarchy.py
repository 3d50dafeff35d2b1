"""The hierarchy model: levels of rows ``lower_k <= A_k x <= upper_k``.

A hierarchy has levels ``0 .. depth-1``, level 0 the highest priority. Row i is

* an **equality** row when ``lower[i] == upper[i]``,
* **one-sided** when exactly one bound is infinite,
* **two-sided** when both bounds are finite and ``lower[i] < upper[i]``,
* **free** when ``lower[i] == -inf`` and ``upper[i] == +inf``.

Levels may be empty. The solution is defined by the sequence of least-squares
problems with inequalities of Escande, Mansard, Wieber (ICRA 2010), eqs.
(33)-(36); see ``hikbench.problems.verify`` for the solver-independent yardstick.

A :class:`Hierarchy` is immutable: its arrays are private read-only copies,
validated once at construction. Every validation error is an
:class:`~hikbench.problems.errors.InvalidHierarchyError` naming the level and the row.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import psutil

from hikbench.problems.errors import InvalidHierarchyError, ProblemTooLargeError

__all__ = ["MEMORY_BYTES", "Hierarchy", "Level", "check_fits_in_memory", "check_sizes_fit", "row_normalised"]

#: bytes of this machine's memory; a problem whose one n x n matrix of doubles
#: needs more is refused (:func:`check_fits_in_memory`)
MEMORY_BYTES = psutil.virtual_memory().total


def check_fits_in_memory(n: int, who: str, matrices: int = 1) -> None:
    """ProblemTooLargeError (``who`` first in the message) when ``matrices``
    ``n x n`` matrices of doubles are larger than this machine's memory: every
    solver here keeps one (a null-space basis, a Hessian), the yardstick and the
    rank analysis of ``inspect`` three at once (the basis Z, the full SVD's V^T
    and their product), as do the generators' random orthogonal factors;
    allocating them would end in a MemoryError, or in hours of swapping. Called
    before the first of them is made."""
    one = 8 * int(n) ** 2
    need = int(matrices) * one
    if need > MEMORY_BYTES:
        held = "" if matrices == 1 else f", and this work holds {int(matrices)} at once ({_gib(need)} GiB)"
        raise ProblemTooLargeError(
            f"{who}: n = {_big(int(n))} variables: one n x n matrix of doubles needs {_gib(one)} GiB{held}, "
            f"more than this machine's {MEMORY_BYTES / 2**30:.3g} GiB of memory")


def _big(k: int) -> str:
    """An integer as written, or ``1.23e+300`` past 15 digits (an n read from ``1e300``)."""
    digits = str(abs(k))
    return str(k) if len(digits) <= 15 else f"{'-' if k < 0 else ''}{digits[0]}.{digits[1:3]}e+{len(digits) - 1}"


def _gib(nbytes: int) -> str:
    """``nbytes`` in GiB, 3 significant digits (no float overflow for any integer)."""
    return _big(nbytes // 2**30) if nbytes >= 2**1000 else f"{nbytes / 2**30:.3g}"


#: bytes a level costs beyond its rows' numbers (its Level object, name and index entries), an estimate
LEVEL_BYTES = 2048


def check_sizes_fit(n: int, depth: int, rows: int, who: str) -> None:
    """ProblemTooLargeError (``who`` first) when a hierarchy of ``depth`` levels holding ``rows``
    rows in all, of ``n`` variables each, needs more than half this machine's memory (the bound
    of a problem file's arrays, problems/files.py): ``8 (n + 3)`` bytes a row (its row of A,
    lower, upper, level) and :data:`LEVEL_BYTES` a level. Called from the sizes, before the
    first level is made: a suite asking for a depth of 10**9 is refused, not grown to swapping."""
    need = 8 * (int(n) + 3) * int(rows) + LEVEL_BYTES * int(depth)
    if need > MEMORY_BYTES // 2:
        raise ProblemTooLargeError(
            f"{who}: depth = {int(depth)} levels, {int(rows)} rows of n = {int(n)} variables need "
            f"{need / 2**30:.3g} GiB, more than half of this machine's {MEMORY_BYTES / 2**30:.3g} GiB of memory")


def _real(value, what: str, level: int | None = None) -> np.ndarray:
    """``value`` as a float64 array; InvalidHierarchyError naming ``what`` (of
    ``level``, when given) for anything but real numbers (strings, a ragged
    list, complex numbers: numpy would raise its own ValueError, or drop the
    imaginary part with a warning)."""
    if type(value) is np.ndarray and value.dtype == np.float64:  # (the usual case, ~4x faster)
        return value
    if level is not None:
        what = f"level {level}: {what}"
    try:
        arr = np.asarray(value)
    except ValueError as err:  # a ragged nested list
        raise InvalidHierarchyError(f"{what} is not a rectangular array of numbers ({err})", level=level) from None
    if arr.dtype.kind == "O":  # numbers of Python types numpy keeps as objects (Fraction, Decimal), or junk
        try:
            arr = arr.astype(np.float64)
        except (TypeError, ValueError):  # (an empty array always converts)
            i, v = next((i, v) for i, v in enumerate(arr.flat) if not _is_number(v))
            raise InvalidHierarchyError(f"{what} must hold real numbers; element {i} (flat) is of type "
                                        f"{type(v).__name__}", level=level) from None
    if arr.dtype.kind not in "biuf":
        raise InvalidHierarchyError(f"{what} must hold real numbers; got dtype {arr.dtype}", level=level)
    return arr.astype(np.float64, copy=False)


def _is_number(v) -> bool:
    try:
        float(v)
    except (TypeError, ValueError):
        return False
    return True


def _check_rows(m: int, **arrays: np.ndarray) -> None:
    """Each array has shape (m,), one entry per row of A."""
    for label, arr in arrays.items():
        if arr.shape != (m,):
            raise InvalidHierarchyError(
                f"{label} has shape {arr.shape} but A has {m} rows: expected {label} of shape ({m},)")


def _frozen(a: np.ndarray) -> np.ndarray:
    """A read-only copy of ``a``."""
    return _read_only(np.array(a, copy=True))


def _read_only(a: np.ndarray) -> np.ndarray:
    """``a`` itself, made read-only (an array no one else holds)."""
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class Level:
    """One level: rows ``lower <= A x <= upper``.

    Attributes
    ----------
    A : ndarray, shape (m_k, n)
    lower, upper : ndarray, shape (m_k,)
        ``-inf`` / ``+inf`` for a missing bound.
    name : str
    """

    A: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    name: str = ""

    @classmethod
    def equality(cls, A, b, name: str = "") -> Level:
        """Equality rows ``A x = b``."""
        b = _real(b, "b")
        return cls(_real(A, "A"), b, b.copy(), name)

    @property
    def rows(self) -> int:
        return int(np.shape(self.A)[0])


class Hierarchy:
    """A lexicographic stack of levels ``lower_k <= A_k x <= upper_k``.

    Parameters
    ----------
    A : array_like, shape (m, n)
        All rows, level by level.
    lower, upper : array_like, shape (m,)
        Bounds; ``-inf`` / ``+inf`` where a side is free.
    level : array_like of int, shape (m,)
        Level of each row; nondecreasing, 0 = highest priority.
    n : int, optional
        Number of variables; required when ``m == 0``.
    depth : int, optional
        Number of levels (allows empty trailing levels). Defaults to
        ``len(names)`` if names are given, else ``max(level) + 1``.
    names : sequence of str, optional
        One name per level.
    x0 : array_like, shape (n,), optional
        A starting point (e.g. the configuration a robot problem came from).

    Raises
    ------
    InvalidHierarchyError
        Wrong shapes; NaN anywhere; inf in A; ``lower > upper``;
        ``lower == +inf``; ``upper == -inf``; levels not nondecreasing or out
        of ``[0, depth)``. The message names the level and the row.
    """

    __slots__ = ("A", "__dict__", "depth", "level", "lower", "n", "names", "upper", "x0")

    def __init__(self, A, lower, upper, level, n: int | None = None, depth: int | None = None,
                 names: Sequence[str] | None = None, x0=None):
        self._init(A, lower, upper, level, n, depth, names, x0, copy=True)

    def _init(self, A, lower, upper, level, n, depth, names, x0, copy: bool) -> None:
        """The constructor's checks and assignments; ``copy=False`` when A,
        lower and upper are float64 arrays no one else holds (made by
        :meth:`from_levels`): they are frozen in place, not copied."""
        A = _real(A, "A")
        lower = _real(lower, "lower")
        upper = _real(upper, "upper")
        level_arr = np.asarray(level)
        if A.ndim != 2:
            if A.size == 0 and n is not None:
                A = A.reshape(0, int(n))
            else:
                raise InvalidHierarchyError(f"A must be a 2-D array (rows, n); got shape {A.shape}")
        m, ncols = A.shape
        if n is None:
            n = ncols
        n = _as_int(n, "n")
        if n < 0:
            raise InvalidHierarchyError(f"n must be >= 0; got {n}")
        if ncols != n:
            raise InvalidHierarchyError(f"A has {ncols} columns but n = {n}: expected A of shape (rows, {n})")
        _check_rows(m, lower=lower, upper=upper, level=level_arr)
        if level_arr.dtype.kind not in "iub" and not (level_arr.dtype.kind == "f" or m == 0):
            raise InvalidHierarchyError(f"level must hold integers; got dtype {level_arr.dtype}")
        if m and level_arr.dtype.kind == "f" and (not np.all(np.isfinite(level_arr))
                                                  or np.any(level_arr != np.round(level_arr))):
            raise InvalidHierarchyError(f"level must hold integers; got dtype {level_arr.dtype}")
        level_arr = level_arr.astype(np.int64)  # (a new array)
        # nondecreasing: then its first and last entries are its extremes (one pass, not three)
        nondecreasing = m < 2 or bool((level_arr[1:] >= level_arr[:-1]).all())
        if names is not None:
            names = tuple(str(s) for s in names)
        depth_of_names = depth is None and names is not None
        if depth is None:
            depth = len(names) if names is not None else (
                0 if m == 0 else int(level_arr[-1] if nondecreasing else level_arr.max()) + 1)
        depth = _as_int(depth, "depth")
        if depth < 0:
            raise InvalidHierarchyError(f"depth must be >= 0; got {depth}")
        if names is None:
            names = tuple(f"level {k}" for k in range(depth))
        if len(names) != depth:
            raise InvalidHierarchyError(f"names has {len(names)} entries but the hierarchy has {depth} levels")
        if m and not (nondecreasing and level_arr[0] >= 0 and level_arr[-1] < depth):
            self._raise_level_error(level_arr, depth, depth_of_names)
        starts = np.searchsorted(level_arr, np.arange(depth + 1), side="left").astype(np.int64, copy=False)
        self._check_values(A, lower, upper, level_arr, starts)
        if x0 is not None:
            x0 = _real(x0, "x0")
            if x0.shape != (n,):
                raise InvalidHierarchyError(f"x0 has shape {x0.shape}: expected ({n},)")
            if not np.all(np.isfinite(x0)):
                raise InvalidHierarchyError("x0 holds NaN or inf: expected finite values")
            x0 = _frozen(x0)
        freeze = _frozen if copy else _read_only
        init = object.__setattr__  # __setattr__ below refuses any later assignment
        init(self, "A", freeze(A))
        init(self, "lower", freeze(lower))
        init(self, "upper", freeze(upper))
        init(self, "level", _read_only(level_arr))  # (new arrays, made above)
        init(self, "n", n)
        init(self, "depth", depth)
        init(self, "names", names)
        init(self, "x0", x0)
        self.__dict__["starts"] = _read_only(starts)

    def __setattr__(self, name, value):
        raise AttributeError(f"Hierarchy is immutable: cannot set {name!r}; build a new one "
                             "(e.g. with_bounds())")

    def __delattr__(self, name):
        raise AttributeError(f"Hierarchy is immutable: cannot delete {name!r}")

    def __reduce__(self):  # pickling (process pools) rebuilds through __init__
        return (Hierarchy, (self.A, self.lower, self.upper, self.level, self.n, self.depth, self.names,
                            self.x0))

    # -- construction helpers -------------------------------------------------
    @classmethod
    def from_levels(cls, levels: Iterable[Level], n: int | None = None, x0=None) -> Hierarchy:
        """Stack :class:`Level` objects, the first one the highest priority."""
        levels = list(levels)
        As = [_real(L.A, "A", k) for k, L in enumerate(levels)]
        for k, Ak in enumerate(As):
            if Ak.ndim != 2 and Ak.size:
                raise InvalidHierarchyError(f"level {k}: A has shape {Ak.shape}: expected a 2-D array (rows, n)",
                                            level=k)
        origin = "given"
        if n is None:
            if not levels:
                raise InvalidHierarchyError("n is required for a hierarchy without levels")
            # from the first level with rows (an empty level's A may be np.zeros(0))
            k0 = next((k for k, Ak in enumerate(As) if Ak.size), None)
            k0 = k0 if k0 is not None else next((k for k, Ak in enumerate(As) if Ak.ndim == 2), None)
            n, origin = (As[k0].shape[1], f"from level {k0}'s A") if k0 is not None else (0, "no level has rows")
        blocks, lo, up, sizes = [], [], [], []
        for k, (L, Ak) in enumerate(zip(levels, As)):
            if Ak.size == 0:
                Ak = Ak.reshape(0, n)
            if Ak.shape[1] != n:
                raise InvalidHierarchyError(
                    f"level {k}: A has shape {Ak.shape}: expected (rows, {n}) (n = {n}, {origin})", level=k)
            m_k = Ak.shape[0]
            lower, upper = _real(L.lower, "lower", k), _real(L.upper, "upper", k)
            for label, b in (("lower", lower), ("upper", upper)):
                if b.shape != (m_k,):
                    raise InvalidHierarchyError(
                        f"level {k}: {label} has shape {b.shape}: expected ({m_k},)", level=k)
            blocks.append(Ak)
            lo.append(lower)
            up.append(upper)
            sizes.append(m_k)
        A = np.concatenate(blocks) if blocks else np.zeros((0, n))  # (blocks of shape (m_k, n))
        names = [L.name or f"level {k}" for k, L in enumerate(levels)]
        level = np.repeat(np.arange(len(levels), dtype=np.int64), sizes)
        h = object.__new__(cls)  # (the arrays above are new: frozen in place, not copied again)
        h._init(A, _cat(lo), _cat(up), level, n, len(levels), names, x0, copy=False)
        return h

    @staticmethod
    def _raise_level_error(level, depth: int, depth_of_names: bool) -> None:
        """InvalidHierarchyError naming the first row whose level is outside
        ``[0, depth)``, else the first row whose level drops (one of them is:
        the caller found the levels not nondecreasing within ``[0, depth)``)."""
        if level.min() < 0 or level.max() >= depth:
            i = int(np.argmax((level < 0) | (level >= depth)))
            why = f" (names has {depth} entries, one per level)" if depth_of_names else ""
            raise InvalidHierarchyError(
                f"row {i}: level {level[i]} is outside [0, {depth}){why}", level=int(level[i]))
        drops = np.flatnonzero(np.diff(level) < 0)
        if drops.size:
            i = int(drops[0]) + 1
            raise InvalidHierarchyError(
                f"row {i}: level {level[i]} follows level {level[i - 1]}: "
                "levels must be nondecreasing (level 0 first)", level=int(level[i]))

    @staticmethod
    def _where(level, starts, i: int) -> tuple[str, int, int]:
        """("level k, row r", k, r) of the row i of the whole stack."""
        k = int(level[i])
        return f"level {k}, row {i - int(starts[k])}", k, i - int(starts[k])

    @staticmethod
    def _check_values(A, lower, upper, level, starts) -> None:
        """No NaN or inf in A (:meth:`_check_bounds` for the bounds). One
        pass when A is clean; the row-by-row search only to name a bad row."""
        if A.size and not np.isfinite(A).all():
            for bad, what in ((np.isnan(A).any(axis=1), "A holds NaN"),
                              (np.isinf(A).any(axis=1), "A holds inf: coefficients must be finite")):
                if bad.any():
                    loc, k, r = Hierarchy._where(level, starts, int(np.argmax(bad)))
                    raise InvalidHierarchyError(f"{loc}: {what}", level=k, row=r)
        Hierarchy._check_bounds(lower, upper, level, starts)

    @staticmethod
    def _check_bounds(lower, upper, level, starts) -> None:
        """Bounds of shape (m,) hold no NaN, no ``lower == +inf`` or
        ``upper == -inf``, and ``lower <= upper``; the first bad row is named.
        Three reductions when they are clean (a NaN fails ``lower <=
        upper``), the search for the row only when they are not."""
        if lower.size == 0 or ((lower <= upper).all() and lower.max() < np.inf and upper.min() > -np.inf):
            return
        checks = (
            (np.isnan(lower), "lower is NaN (use -inf for no lower bound)"),
            (np.isnan(upper), "upper is NaN (use +inf for no upper bound)"),
            (lower == np.inf, "lower is +inf: no x can satisfy it"),
            (upper == -np.inf, "upper is -inf: no x can satisfy it"),
        )
        for bad, what in checks:
            if bad.any():
                loc, k, r = Hierarchy._where(level, starts, int(np.argmax(bad)))
                raise InvalidHierarchyError(f"{loc}: {what}", level=k, row=r)
        i = int(np.argmax(lower > upper))
        loc, k, r = Hierarchy._where(level, starts, i)
        raise InvalidHierarchyError(
            f"{loc}: lower ({float(lower[i])!r}) > upper ({float(upper[i])!r}): expected lower <= upper",
            level=k, row=r)

    # -- views -----------------------------------------------------------------
    @property
    def rows(self) -> int:
        """Total number of rows m."""
        return int(self.A.shape[0])

    @property
    def starts(self) -> np.ndarray:
        """Row offsets of the levels, shape (depth + 1,): level k is rows
        ``starts[k]:starts[k+1]``."""
        return self.__dict__["starts"]

    def level_rows(self, k: int) -> slice:
        """Slice of the rows of level k."""
        if not 0 <= k < self.depth:
            raise IndexError(f"level {k} is outside [0, {self.depth})")
        return slice(int(self.starts[k]), int(self.starts[k + 1]))

    def __getitem__(self, k: int) -> Level:
        s = self.level_rows(k)
        return Level(self.A[s], self.lower[s], self.upper[s], self.names[k])

    def __iter__(self):
        return (self[k] for k in range(self.depth))

    def __len__(self) -> int:
        return self.depth

    @cached_property
    def is_equality(self) -> np.ndarray:
        """Mask of equality rows (lower == upper), shape (m,)."""
        return _frozen(self.lower == self.upper)

    @cached_property
    def is_free(self) -> np.ndarray:
        """Mask of free rows (both bounds infinite), shape (m,)."""
        return _frozen(np.isneginf(self.lower) & np.isposinf(self.upper))

    @cached_property
    def has_inequalities(self) -> bool:
        """True when some row is not an equality (free rows count). Computed
        once per hierarchy (solvers ask it on every solve)."""
        return not np.array_equal(self.lower, self.upper)

    @property
    def rows_per_level(self) -> np.ndarray:
        return np.diff(self.starts)

    def with_bounds(self, lower, upper) -> Hierarchy:
        """The same rows with new bounds (a new time step of a trajectory).
        Only the bounds are checked, as the constructor checks them: the rows,
        levels and names are this hierarchy's, checked when it was built and
        shared (read-only), not copied."""
        m = self.rows
        lower = _real(lower, "lower")
        upper = _real(upper, "upper")
        _check_rows(m, lower=lower, upper=upper)
        self._check_bounds(lower, upper, self.level, self.starts)
        new = object.__new__(Hierarchy)
        init = object.__setattr__
        for name in ("A", "level", "n", "depth", "names", "x0"):
            init(new, name, getattr(self, name))
        init(new, "lower", _frozen(lower))
        init(new, "upper", _frozen(upper))
        new.__dict__["starts"] = self.starts
        return new

    def __repr__(self) -> str:
        return (f"Hierarchy(n={self.n}, depth={self.depth}, rows={self.rows_per_level.tolist()}, "
                f"inequality_rows={int((~self.is_equality).sum())})")

    def __eq__(self, other) -> bool:
        if not isinstance(other, Hierarchy):
            return NotImplemented
        same_x0 = (self.x0 is None and other.x0 is None) or (
            self.x0 is not None and other.x0 is not None and np.array_equal(self.x0, other.x0))
        return (self.n == other.n and self.depth == other.depth and self.names == other.names
                and np.array_equal(self.A, other.A) and np.array_equal(self.lower, other.lower)
                and np.array_equal(self.upper, other.upper) and np.array_equal(self.level, other.level)
                and same_x0)

    __hash__ = None  # arrays: equality by value, not hashable


def row_normalised(h: Hierarchy) -> Hierarchy:
    """h with each row and its bounds divided by the row's 2-norm:
    ``lower_i / ||a_i|| <= a_i^T x / ||a_i|| <= upper_i / ||a_i||`` (a zero row
    kept as it is). The feasible set of every row is the same, so the
    minimisers agree wherever every level can be met; a level whose rows
    conflict weighs each row's violation by ``1 / ||a_i||``, what a solver
    that scales its rows minimises (DAQP's hierarchical QP). Names and x0 are kept."""
    norms = np.linalg.norm(h.A, axis=1)
    norms[norms == 0.0] = 1.0
    return Hierarchy(h.A / norms[:, None], h.lower / norms, h.upper / norms, h.level, n=h.n, depth=h.depth,
                     names=h.names, x0=h.x0)


def _as_int(v, label: str) -> int:
    try:
        iv = int(v)
    except (TypeError, ValueError) as err:
        raise InvalidHierarchyError(f"{label} must be an integer; got {v!r}") from err
    if iv != v:
        raise InvalidHierarchyError(f"{label} must be an integer; got {v!r}")
    return iv


def _cat(parts) -> np.ndarray:
    return np.concatenate(parts) if parts else np.zeros(0)
