"""The hierarchy model: construction, views, and every documented bad input."""

import copy
import pickle

import numpy as np
import pytest

from hikbench.problems import Hierarchy, InvalidHierarchyError, Level
from hikbench.problems.verify import level_norms

INF = np.inf


def two_levels():
    """Level 0: one equality and one one-sided row; level 1: a two-sided and a free row."""
    A = np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0], [1.0, -1.0]])
    return Hierarchy(A, [1.0, -INF, -1.0, -INF], [1.0, 2.0, 1.0, INF], [0, 0, 1, 1], names=["top", "bottom"])


def test_views():
    h = two_levels()
    assert (h.n, h.depth, h.rows) == (2, 2, 4)
    np.testing.assert_array_equal(h.starts, [0, 2, 4])
    np.testing.assert_array_equal(h.is_equality, [True, False, False, False])
    np.testing.assert_array_equal(h.is_free, [False, False, False, True])
    assert h.has_inequalities
    assert h[1].name == "bottom"
    np.testing.assert_array_equal(h[1].A, [[1.0, 1.0], [1.0, -1.0]])
    assert [L.rows for L in h] == [2, 2]


def test_from_levels_with_empty_levels_and_names():
    h = Hierarchy.from_levels([Level(np.zeros((0, 3)), [], [], "empty top"),
                               Level.equality(np.eye(3), [1, 2, 3]),
                               Level(np.zeros((0, 3)), [], [])], n=3)
    assert h.depth == 3
    np.testing.assert_array_equal(h.rows_per_level, [0, 3, 0])
    assert h.names == ("empty top", "level 1", "level 2")
    assert not h.has_inequalities


def test_immutable():
    h = two_levels()
    with pytest.raises(ValueError, match="read-only"):
        h.A[0, 0] = 5.0
    with pytest.raises(AttributeError, match="immutable"):
        h.A = np.zeros((4, 2))
    with pytest.raises(AttributeError, match="immutable"):
        del h.n


def test_arrays_are_copies():
    A = np.eye(2)
    h = Hierarchy(A, [0, 0], [1, 1], [0, 0])
    A[0, 0] = 7.0
    assert h.A[0, 0] == 1.0


@pytest.mark.parametrize("depth", [1, 3], ids=["one_level", "three_levels"])
def test_from_levels_arrays_are_its_own(depth):
    """from_levels freezes the arrays it stacks in place (no second copy): they are new arrays, so
    changing the levels' arrays afterwards changes nothing, and they are read-only."""
    levels = [Level(np.full((2, 3), float(k)), np.full(2, -1.0 - k), np.full(2, 1.0 + k)) for k in range(depth)]
    h = Hierarchy.from_levels(levels)
    before = (h.A.copy(), h.lower.copy(), h.upper.copy())
    for L in levels:
        L.A[:] = 9.0
        L.lower[:] = -9.0
        L.upper[:] = 9.0
    for got, was in zip((h.A, h.lower, h.upper), before):
        np.testing.assert_array_equal(got, was)
        assert not got.flags.writeable
    assert not h.level.flags.writeable and not h.starts.flags.writeable
    np.testing.assert_array_equal(h.level, np.repeat(np.arange(depth), 2))


def test_constructor_copies_every_array():
    A, lower, upper, level = np.eye(2), np.zeros(2), np.ones(2), np.zeros(2, dtype=np.int64)
    h = Hierarchy(A, lower, upper, level)
    A[:] = lower[:] = upper[:] = 5.0
    level[:] = 1
    np.testing.assert_array_equal(h.A, np.eye(2))
    np.testing.assert_array_equal(h.lower, [0.0, 0.0])
    np.testing.assert_array_equal(h.upper, [1.0, 1.0])
    np.testing.assert_array_equal(h.level, [0, 0])


def _pickled(h):
    return pickle.loads(pickle.dumps(h))


@pytest.mark.parametrize("dup", [_pickled, copy.deepcopy, copy.copy], ids=["pickle", "deepcopy", "copy"])
def test_pickle_and_copy(dup):
    h = Hierarchy.from_levels([Level.equality(np.eye(2), [1, 2], "a"), Level(np.zeros((0, 2)), [], [])],
                              x0=[0.5, 0.25])
    _ = h.is_equality  # a cached property (filled here) must not break pickling
    g = dup(h)
    assert g == h
    assert not g.A.flags.writeable


# Each bad input: constructor kwargs, the pinned message, and the .level/.row fields.
A2 = np.eye(2)
BAD = [
    ("A 1-D", {"A": [1.0, 2.0], "lower": [0], "upper": [1], "level": [0]},
     r"A must be a 2-D array \(rows, n\); got shape \(2,\)", None, None),
    ("A columns != n", {"A": A2, "lower": [0, 0], "upper": [1, 1], "level": [0, 0], "n": 3},
     r"A has 2 columns but n = 3: expected A of shape \(rows, 3\)", None, None),
    ("lower shape", {"A": A2, "lower": [0], "upper": [1, 1], "level": [0, 0]},
     r"lower has shape \(1,\) but A has 2 rows: expected lower of shape \(2,\)", None, None),
    ("upper shape", {"A": A2, "lower": [0, 0], "upper": [[1, 1]], "level": [0, 0]},
     r"upper has shape \(1, 2\) but A has 2 rows", None, None),
    ("level shape", {"A": A2, "lower": [0, 0], "upper": [1, 1], "level": [0]},
     r"level has shape \(1,\) but A has 2 rows", None, None),
    ("NaN in A", {"A": [[1, 0], [0, np.nan]], "lower": [0, 0], "upper": [1, 1], "level": [0, 1]},
     r"^level 1, row 0: A holds NaN$", 1, 0),
    ("inf in A", {"A": [[1, 0], [0, 1], [INF, 0]], "lower": [0, 0, 0], "upper": [1, 1, 1],
                  "level": [0, 0, 0]},
     r"^level 0, row 2: A holds inf: coefficients must be finite$", 0, 2),
    ("NaN lower", {"A": A2, "lower": [0, np.nan], "upper": [1, 1], "level": [0, 0]},
     r"^level 0, row 1: lower is NaN \(use -inf for no lower bound\)$", 0, 1),
    ("NaN upper", {"A": A2, "lower": [0, 0], "upper": [np.nan, 1], "level": [0, 1]},
     r"^level 0, row 0: upper is NaN \(use \+inf for no upper bound\)$", 0, 0),
    ("lower > upper", {"A": A2, "lower": [0, 2.5], "upper": [1, 1], "level": [0, 1]},
     r"^level 1, row 0: lower \(2.5\) > upper \(1.0\): expected lower <= upper$", 1, 0),
    ("lower = +inf", {"A": A2, "lower": [0, INF], "upper": [1, INF], "level": [0, 0]},
     r"^level 0, row 1: lower is \+inf: no x can satisfy it$", 0, 1),
    ("upper = -inf", {"A": A2, "lower": [-INF, 0], "upper": [-INF, 1], "level": [0, 0]},
     r"^level 0, row 0: upper is -inf: no x can satisfy it$", 0, 0),
    ("levels decrease", {"A": np.eye(3), "lower": [0] * 3, "upper": [1] * 3, "level": [0, 1, 0]},
     r"row 2: level 0 follows level 1: levels must be nondecreasing \(level 0 first\)", 0, None),
    ("negative level", {"A": A2, "lower": [0, 0], "upper": [1, 1], "level": [-1, 0]},
     r"row 0: level -1 is outside \[0, 1\)", -1, None),
    ("level >= depth", {"A": A2, "lower": [0, 0], "upper": [1, 1], "level": [0, 2], "depth": 2},
     r"row 1: level 2 is outside \[0, 2\)", 2, None),
    ("fractional level", {"A": A2, "lower": [0, 0], "upper": [1, 1], "level": [0, 0.5]},
     r"level must hold integers; got dtype float64", None, None),
    ("string level", {"A": A2, "lower": [0, 0], "upper": [1, 1], "level": ["a", "b"]},
     r"level must hold integers; got dtype <U1", None, None),
    ("names count", {"A": A2, "lower": [0, 0], "upper": [1, 1], "level": [0, 1], "names": ["only one"],
                     "depth": 2},
     r"names has 1 entries but the hierarchy has 2 levels", None, None),
    ("negative depth", {"A": np.zeros((0, 2)), "lower": [], "upper": [], "level": [], "depth": -1},
     r"depth must be >= 0; got -1", None, None),
    ("n not integer", {"A": np.zeros((0, 2)), "lower": [], "upper": [], "level": [], "n": 2.5},
     r"n must be an integer; got 2.5", None, None),
    ("x0 shape", {"A": A2, "lower": [0, 0], "upper": [1, 1], "level": [0, 0], "x0": [1.0]},
     r"x0 has shape \(1,\): expected \(2,\)", None, None),
    ("x0 NaN", {"A": A2, "lower": [0, 0], "upper": [1, 1], "level": [0, 0], "x0": [1.0, np.nan]},
     r"x0 holds NaN or inf: expected finite values", None, None),
    # numpy's own ValueError (strings, ragged), or the imaginary part dropped with a warning (complex)
    ("strings in A", {"A": [["a", "b"]], "lower": [0], "upper": [1], "level": [0]},
     r"^A must hold real numbers; got dtype <U1$", None, None),
    ("ragged A", {"A": [[1, 2], [3]], "lower": [0, 0], "upper": [1, 1], "level": [0, 0]},
     r"^A is not a rectangular array of numbers \(setting an array element with a sequence", None, None),
    ("complex A", {"A": np.array([[1 + 1j, 2]]), "lower": [0], "upper": [1], "level": [0]},
     r"^A must hold real numbers; got dtype complex128$", None, None),
    ("string lower", {"A": A2, "lower": ["x", "y"], "upper": [1, 1], "level": [0, 0]},
     r"^lower must hold real numbers; got dtype <U1$", None, None),
    ("object upper", {"A": A2, "lower": [0, 0], "upper": [1, object()], "level": [0, 0]},
     r"^upper must hold real numbers; element 1 \(flat\) is of type object$", None, None),
    ("complex x0", {"A": A2, "lower": [0, 0], "upper": [1, 1], "level": [0, 0], "x0": [1j, 0]},
     r"^x0 must hold real numbers; got dtype complex128$", None, None),
]


@pytest.mark.parametrize("kwargs, message, level, row", [b[1:] for b in BAD], ids=[b[0] for b in BAD])
def test_bad_input_raises(kwargs, message, level, row):
    with pytest.raises(InvalidHierarchyError, match=message) as info:
        Hierarchy(**kwargs)
    assert (info.value.level, info.value.row) == (level, row)


@pytest.mark.parametrize("levels, message", [
    ([Level(np.ones((2, 3)), [0, 0], [1, 1]), Level(np.ones((1, 2)), [0], [1])],
     r"level 1: A has shape \(1, 2\): expected \(rows, 3\)"),
    ([Level(np.ones((2, 3)), [0], [1, 1])], r"level 0: lower has shape \(1,\): expected \(2,\)"),
    ([], r"n is required for a hierarchy without levels"),
    # n was taken as 0 from a 1-D or empty first A, and the message asked for (rows, 0)
    ([Level(np.array([1.0, 2.0]), [1.0], [1.0])], r"^level 0: A has shape \(2,\): expected a 2-D array \(rows, n\)$"),
    ([Level(np.ones((2, 3)), [0, 0], [1, 1]), Level(np.array([1.0, 2.0]), [1.0], [1.0])],
     r"^level 1: A has shape \(2,\): expected a 2-D array \(rows, n\)$"),
    ([Level(np.ones((1, 3)), [0], [1]), Level(np.ones((1, 2)), [0], [1])],
     r"^level 1: A has shape \(1, 2\): expected \(rows, 3\) \(n = 3, from level 0's A\)$"),
    ([Level([["a"]], [0], [1])], r"^level 0: A must hold real numbers; got dtype <U1$"),
    ([Level(np.ones((1, 2)), ["low"], [1])], r"^level 0: lower must hold real numbers; got dtype <U3$"),
], ids=["columns", "bound shape", "no levels without n", "1-D first A", "1-D later A", "n from level 0",
        "strings in A", "strings in lower"])
def test_from_levels_bad_input(levels, message):
    with pytest.raises(InvalidHierarchyError, match=message):
        Hierarchy.from_levels(levels)


def test_from_levels_takes_n_from_the_first_level_with_rows():
    """An empty first level (np.zeros(0)) made n = 0, then level 1's A of 2 columns was refused."""
    h = Hierarchy.from_levels([Level.equality(np.zeros(0), []), Level.equality(np.ones((1, 2)), [0.5])])
    assert (h.n, h.rows_per_level.tolist()) == (2, [0, 1])


@pytest.mark.parametrize("A, b, message", [
    ([["a", "b"]], [3], r"^A must hold real numbers; got dtype <U1$"),
    ([[1, 2], [3]], [3, 4], r"^A is not a rectangular array of numbers"),
    ([[1, 2]], ["x"], r"^b must hold real numbers; got dtype <U1$"),
], ids=["strings", "ragged", "string b"])
def test_level_equality_bad_input(A, b, message):
    with pytest.raises(InvalidHierarchyError, match=message):
        Level.equality(A, b)


def test_numbers_of_other_python_types_are_read_as_floats():
    from fractions import Fraction

    h = Hierarchy.from_levels([Level.equality([[Fraction(1, 2), 1]], [Fraction(1, 4)])])
    np.testing.assert_array_equal(h.A, [[0.5, 1.0]])
    np.testing.assert_array_equal(h.lower, [0.25])


def test_empty_hierarchy_needs_nothing_but_n():
    h = Hierarchy.from_levels([], n=4)
    assert (h.n, h.depth, h.rows) == (4, 0, 0)
    np.testing.assert_array_equal(level_norms(h, np.zeros(4)), np.zeros(0))


def test_with_bounds_keeps_rows_and_validates():
    h = two_levels()
    g = h.with_bounds(h.lower - 1, h.upper)
    np.testing.assert_array_equal(g.A, h.A)
    assert g.names == h.names
    with pytest.raises(InvalidHierarchyError, match=r"level 0, row 0: lower \(3.0\) > upper \(1.0\)"):
        h.with_bounds(h.lower + 2, h.upper)


def test_with_bounds_is_the_hierarchy_the_constructor_builds():
    h = Hierarchy.from_levels([Level(np.eye(2), [-1, 0], [1, 0], "box"), Level.equality(np.ones((1, 2)), [3])],
                              x0=[0.5, 0.25])
    lower, upper = np.array([-2.0, 0.0, 1.0]), np.array([2.0, 0.5, 1.0])
    g = h.with_bounds(lower, upper)
    built = Hierarchy(h.A, lower, upper, h.level, n=h.n, depth=h.depth, names=h.names, x0=h.x0)
    assert g == built
    np.testing.assert_array_equal(g.starts, built.starts)
    np.testing.assert_array_equal(g.is_equality, [False, False, True])
    assert g.has_inequalities and not h.with_bounds(upper, upper).has_inequalities
    assert not (g.lower.flags.writeable or g.upper.flags.writeable)
    lower[0] = 9.0  # (the caller's array is copied)
    assert g.lower[0] == -2.0
    assert g.A is h.A  # (checked and read-only: shared)


# the bad bounds of BAD, given to with_bounds of a valid hierarchy with the same rows: the same errors
BAD_BOUNDS = [b for b in BAD if set(b[1]) == {"A", "lower", "upper", "level"}
              and ("lower" in b[0] or "upper" in b[0])]


@pytest.mark.parametrize("kwargs, message, level, row", [b[1:] for b in BAD_BOUNDS],
                         ids=[b[0] for b in BAD_BOUNDS])
def test_with_bounds_raises_as_the_constructor_does(kwargs, message, level, row):
    m = len(kwargs["level"])
    h = Hierarchy(kwargs["A"], np.zeros(m), np.ones(m), kwargs["level"])
    with pytest.raises(InvalidHierarchyError, match=message) as info:
        h.with_bounds(kwargs["lower"], kwargs["upper"])
    assert (info.value.level, info.value.row) == (level, row)
