"""Problem files: .npz (exact round-trip) and SOTH text (import/export)."""

import os

import numpy as np
import pytest
from hik_strategies import hierarchies
from hypothesis import given

from hikbench.problems import Hierarchy, InvalidHierarchyError, Level, ProblemFileError
from hikbench.problems.files import load, load_npz, save, save_npz
from hikbench.problems.soth import from_soth_text, load_soth, soth_order, to_soth_text

INF = np.inf


def bits_equal(a, b) -> bool:
    """Exact equality of float arrays, bit for bit (so -0.0 != 0.0)."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    return a.shape == b.shape and a.tobytes() == b.tobytes()


def assert_same(g: Hierarchy, h: Hierarchy, names=True, x0=True):
    assert (g.n, g.depth) == (h.n, h.depth)
    assert bits_equal(g.A, h.A) and bits_equal(g.lower, h.lower) and bits_equal(g.upper, h.upper)
    np.testing.assert_array_equal(g.level, h.level)
    if names:
        assert g.names == h.names
    if x0:
        assert (g.x0 is None and h.x0 is None) or bits_equal(g.x0, h.x0)


CASES = {
    "names and x0": Hierarchy.from_levels([Level.equality([[1.0, 2.0]], [3.0], "reach"),
                                           Level([[0.1, -0.0]], [-INF], [1e-300], "limit")],
                                          x0=[0.25, -1e300]),
    "empty levels": Hierarchy.from_levels([Level(np.zeros((0, 2)), [], []), Level.equality(np.eye(2), [1, 2]),
                                           Level(np.zeros((0, 2)), [], []), Level(np.zeros((0, 2)), [], [])]),
    "free and one-sided rows": Hierarchy(np.arange(8.0).reshape(4, 2) / 3, [-INF, -INF, 0.5, -1.0],
                                         [INF, 2.0, INF, 1.0], [0, 0, 1, 1]),
    "no levels": Hierarchy.from_levels([], n=3),
    "no variables": Hierarchy(np.zeros((2, 0)), [-1.0, 0.0], [1.0, 0.0], [0, 1]),
}


@pytest.mark.parametrize("h", CASES.values(), ids=CASES.keys())
def test_npz_round_trip_cases(h, tmp_path):
    path = tmp_path / "p.npz"
    save_npz(h, path)
    g = load_npz(path)
    assert g == h
    assert_same(g, h)


@given(hierarchies())
def test_npz_round_trip_exact(h):
    import tempfile
    with tempfile.TemporaryDirectory() as d:
        path = os.path.join(d, "p.npz")
        save(h, path)
        assert_same(load(path), h)


def _write_npz(path, **arrays):
    with open(path, "wb") as f:
        np.savez(f, **arrays)


GOOD = {"A": np.eye(2), "lower": np.zeros(2), "upper": np.ones(2), "level": np.array([0, 0]),
        "n": np.int64(2)}


@pytest.mark.parametrize("arrays, error, message", [
    ({k: v for k, v in GOOD.items() if k != "upper"}, ProblemFileError, r"missing array\(s\) \['upper'\]"),
    ({**GOOD, "n": np.array([2])}, ProblemFileError, r"n must be a scalar integer"),
    ({**GOOD, "n": np.float64(2.0)}, ProblemFileError, r"n must be a scalar integer"),
    ({**GOOD, "lower": np.array([0.0, 2.0])}, InvalidHierarchyError,
     r"p\.npz: level 0, row 1: lower \(2.0\) > upper \(1.0\)"),
    ({**GOOD, "level": np.array([0, 1]), "names": np.array(["only one"])}, InvalidHierarchyError,
     r"p\.npz: row 1: level 1 is outside \[0, 1\) \(names has 1 entries, one per level\)"),
], ids=["missing key", "n not scalar", "n float", "invalid content", "names vs levels"])
def test_npz_bad_files(tmp_path, arrays, error, message):
    path = tmp_path / "p.npz"
    _write_npz(path, **arrays)
    with pytest.raises(error, match=message):
        load_npz(path)


@pytest.mark.parametrize("content, message", [
    (b"not a zip file", r"p\.npz: not a valid \.npz file \(expected a zip archive"),
    (b"", r"p\.npz: not a valid \.npz file \(expected a zip archive"),
], ids=["garbage", "empty"])
def test_npz_unreadable(tmp_path, content, message):
    path = tmp_path / "p.npz"
    path.write_bytes(content)
    with pytest.raises(ProblemFileError, match=message):
        load(path)


def test_load_missing_file_and_directory(tmp_path):
    with pytest.raises(ProblemFileError, match=r"nope\.npz: no such file"):
        load(tmp_path / "nope.npz")
    with pytest.raises(ProblemFileError, match=r": not a file"):
        load(tmp_path)


@pytest.mark.parametrize("name", ["p.npz", "p.soth"])
def test_save_into_missing_directory(tmp_path, name):
    with pytest.raises(ProblemFileError, match=r"cannot write"):
        save(CASES["names and x0"], tmp_path / "missing" / name)


# ---------------------------------------------------------------- SOTH text
@given(hierarchies())
def test_soth_round_trip_reorders_equalities_first(h):
    """Export then import gives the same rows, each level's equality rows
    first (soth_order); names and x0 are not part of the format."""
    g = from_soth_text(to_soth_text(h))
    assert_same(g, soth_order(h), names=False, x0=False)
    assert g.names == tuple(f"level {k}" for k in range(h.depth))
    assert g.x0 is None


@given(hierarchies(equalities_first=True, names=False, x0=False))
def test_soth_round_trip_exact_when_equalities_come_first(h):
    assert from_soth_text(to_soth_text(h)) == h
    assert_same(from_soth_text(to_soth_text(h)), h)


def test_soth_order_moves_equalities_first_stably():
    h = Hierarchy(np.arange(10.0).reshape(5, 2), [-INF, 1.0, 0.0, 2.0, 5.0], [0.0, 1.0, INF, 2.0, 5.0],
                  [0, 0, 0, 0, 1])
    np.testing.assert_array_equal(soth_order(h).A[:, 0], [2.0, 6.0, 0.0, 4.0, 8.0])


def test_soth_text_layout():
    """The layout of SOTH's writer: header, 'level', 'equalities k' rows
    'a_1 .. a_n b', 'inequalities m' rows 'a_1 .. a_n lo hi' with +-1e25 for a
    missing side, 'end'."""
    h = Hierarchy([[1.0, 0.5], [0.0, -2.0], [3.0, 0.1]], [-INF, 4.0, -1.0], [2.0, 4.0, INF], [0, 0, 1])
    assert to_soth_text(h) == (
        "variable size 2\n\n"
        "level\n\nequalities 1\n0.0 -2.0   4.0\n\ninequalities 1\n1.0 0.5   -1e+25 2.0\n\n"
        "level\n\nequalities 0\n\ninequalities 1\n3.0 0.1   -1.0 1e+25\n\n"
        "end\n")


# Written as SOTH's writeProblemToFile does (C++ ostream: 6 significant digits,
# "1e+25", rows spread by spaces); a row may span lines in SOTH's token stream.
SOTH_WRITTEN = """variable size 3

level

equalities 1

1 0 0   0.5

inequalities 2

0 1 0   -1e+25 2
0 0
1   -1 1e+25

level

equalities 0


inequalities 1

1 1 1   -0.5 0.5


end

"""


def test_soth_reads_soth_writer_output(tmp_path):
    path = tmp_path / "problem.txt"
    path.write_text(SOTH_WRITTEN)
    h = load(path)  # by extension: anything but .npz is SOTH text
    expected = Hierarchy([[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]], [0.5, -INF, -1.0, -0.5],
                         [0.5, 2.0, INF, 0.5], [0, 0, 0, 1])
    assert h == expected


@pytest.mark.parametrize("bound, read_as", [("1e25", INF), ("1e+26", INF), ("inf", INF), ("9.9e24", 9.9e24)],
                         ids=["1e25", "above", "inf token", "below threshold"])
def test_soth_no_bound_threshold(bound, read_as):
    h = from_soth_text(f"variable size 1 level equalities 0 inequalities 1 1 0 {bound} end")
    assert h.upper[0] == read_as


@pytest.mark.parametrize("text, message", [
    ("", r"line 1: expected 'variable', got end of file"),
    ("variable length 2", r"line 1: expected 'size', got 'length'"),
    ("variable size two", r"line 1: expected the number of variables n \(a nonnegative integer\), got 'two'"),
    ("variable size -2", r"expected the number of variables n \(a nonnegative integer\), got '-2'"),
    ("variable size 2\n\nlevel\nequalities 1\n1 2\n", (r"line 5: expected level 0, equality row 0: "
                                                        r"the target b after 2 coefficients, "
                                                        r"got end of file")),
    ("variable size 2\nlevel\nequalities 1\n1 x 3\n", (r"line 4: expected level 0, equality row 0: "
                                                       r"coefficient a_2 of 2 \(a number\), got 'x'")),
    ("variable size 2\nlevel\nequalities 0\ninequalities 1\n1 2 nan 3\nend",
     (r"line 5: expected level 0, inequality row 0: the lower bound after 2 coefficients "
      r"\(a number, not NaN\)")),
    ("variable size 2\nlevel\nequalities 1\n1 0 1e400\ninequalities 0\nend",
     (r"line 4: expected level 0, equality row 0: the target b after 2 coefficients \(a number within a "
      r"double's range, \|v\| < 1.8e308; \+-1e25 means no bound\), got '1e400'")),
    ("variable size 1\nlevel\nequalities 0\nineq 0\nend", r"line 4: expected 'inequalities', got 'ineq'"),
    ("variable size 1\nlevel\nequalities 1.5", r"line 3: expected level 0: the number of equality rows"),
    ("variable size 1\nlevel\nequalities 0\ninequalities 0\n",
     r"line 4: expected 'level' or 'end', got end of file"),
    ("variable size 1\nlevels\n", r"line 2: expected 'level' or 'end', got 'levels'"),
    ("variable size 1\nend\nlevel", r"line 3: expected end of file after 'end', got 'level'"),
    # Python's float() reads 1_0 as 10; SOTH's C++ reader does not
    ("variable size 2\nlevel\nequalities 1\n1 1_0 3\n", (r"line 4: expected level 0, equality row 0: "
                                                         r"coefficient a_2 of 2 \(a number\), got '1_0'")),
], ids=["empty", "size", "n word", "n negative", "short row", "bad number", "NaN bound", "overflow", "keyword",
        "count not integer", "no end", "bad level keyword", "text after end", "underscore"])
def test_soth_parse_errors(text, message):
    with pytest.raises(ProblemFileError, match=message):
        from_soth_text(text)


def test_soth_invalid_numbers_name_the_file_line_and_row(tmp_path):
    """lo > hi is named as the file counts rows (the inequality block's own
    index), with its line; ``row`` counts the level's rows."""
    path = tmp_path / "bad.soth"
    path.write_text("variable size 1\nlevel\nequalities 1\n1 0\ninequalities 2\n1 0 1\n1 3 2\nend\n")
    message = r"^.*bad\.soth: line 7: level 0, inequality row 1: lower \(3.0\) > upper \(2.0\): expected"
    with pytest.raises(InvalidHierarchyError, match=message) as err:
        load_soth(path)
    assert (err.value.level, err.value.row) == (0, 2)
    # an upper bound of 1e25 is no bound: 2e25 <= +inf
    h = from_soth_text("variable size 1 level equalities 0 inequalities 1 1 2e25 1e25 end")
    assert (h.lower[0], h.upper[0]) == (2e25, np.inf)


@pytest.mark.parametrize("lower, upper, message", [
    (-1e25, 1.0, r"level 0, row 0: finite lower bound -1e\+25 has magnitude >= 1e\+25"),
    (0.0, 3e30, r"level 0, row 0: finite upper bound 3e\+30 has magnitude >= 1e\+25"),
], ids=["lower", "upper"])
def test_soth_export_refuses_bounds_it_cannot_hold(lower, upper, message):
    with pytest.raises(ProblemFileError, match=message):
        to_soth_text(Hierarchy([[1.0]], [lower], [upper], [0]))


def test_soth_equality_targets_are_not_thresholded():
    h = Hierarchy([[1.0]], [3e30], [3e30], [0])  # an equality: no "missing side" to encode
    assert from_soth_text(to_soth_text(h)) == h


def test_soth_unreadable_file(tmp_path):
    path = tmp_path / "p.soth"
    path.write_bytes(b"\xff\xfe binary")
    with pytest.raises(ProblemFileError, match=r"p\.soth: cannot read as a SOTH text problem file"):
        load_soth(path)
