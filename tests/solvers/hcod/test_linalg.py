"""The level COD (19) of the HCOD inequality kernel (solvers/hcod/_linalg.py):
from scratch (:func:`cod`) and updated row by row (:func:`cod_append`, the
update the kernel makes when a level's own row enters its objective). Each
test checks the factors against the rows they decompose, the rank against
numpy's, and the least-squares step against ``numpy.linalg.lstsq``. Also the
reflectors applied four at a time and the workspaces as unowned arrays."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hikbench.solvers.hcod._linalg import (
    ROW_RANK_RTOL,
    WEAK_PIVOT,
    apply_reflectors,
    cod,
    cod_append,
    solve_lower,
    solve_upper,
)

pytestmark = pytest.mark.usefixtures("hcod_kernels_loaded_first")

ATOL = 1e-11
THR = 1e-10


def _rows(nO: int, nf: int, rank: int, seed: int) -> np.ndarray:
    """nO rows of length nf and the given rank (random mixtures of rank rows)."""
    rng = np.random.default_rng(seed)
    return rng.standard_normal((nO, rank)) @ rng.standard_normal((rank, nf))


class Cod:
    """The kernel's arrays of one level COD. ``rnorm`` (nO,): the rows' norms before their
    projection on Z, read by the row-by-row rank test when ``rrt > 0`` (a wide level); the
    objective list is the identity."""

    def __init__(self, M: np.ndarray, rrt: float = 0.0, rnorm: np.ndarray | None = None):
        self.M = M
        self.nO, self.nf = M.shape
        self.Mr = np.zeros((self.nO, self.nf))
        self.piv = np.arange(self.nO)
        self.diag = np.zeros(self.nO)
        self.beta = np.zeros(self.nO)
        self.r = 0
        self.rrt = rrt
        self.Olist = np.arange(self.nO)
        self.rnorm = np.linalg.norm(M, axis=1) if rnorm is None else rnorm

    def scratch(self, k: int) -> None:
        """cod() of the first k rows."""
        self.Mr[:k] = self.M[:k]
        self.r, _ = cod(self.Mr, k, self.nf, THR, self.piv, self.diag, self.beta, self.rrt, self.Olist,
                        self.rnorm)

    def append(self, j: int) -> bool:
        """cod_append() of row j (rows before it decomposed); returns its ``weak`` flag."""
        self.Mr[j] = self.M[j]
        self.piv[j] = j
        self.r, _, weak = cod_append(self.Mr, j, self.nf, THR, self.r, self.piv, self.diag, self.beta,
                                     self.rrt, self.Olist, self.rnorm)
        return weak

    def row(self, j: int) -> np.ndarray:
        """Row j of Mr rebuilt from the factors: H [L[j], remainder]."""
        z = self.Mr[j].copy()
        if j < self.r:
            z[j] = self.diag[j]
            z[j + 1:] = 0.0
        apply_reflectors(self.Mr, self.beta, self.r, self.nf, z)
        return z

    def step(self, b: np.ndarray) -> np.ndarray:
        """The least-squares step x = H [y; 0] of eq. (28) for right-hand side b (M's order)."""
        bvec = b[self.piv].copy()
        y = np.zeros(self.nf)
        Lb = np.zeros((max(self.r, 1), self.nO))
        solve_lower(self.Mr, self.diag, self.nO, self.r, bvec, Lb, y)
        z = np.zeros(self.nf)
        z[:self.r] = y[:self.r]
        apply_reflectors(self.Mr, self.beta, self.r, self.nf, z)
        return z


CASES = [
    pytest.param(4, 9, 4, id="full-row-rank"),
    pytest.param(9, 4, 4, id="more-rows-than-columns"),
    pytest.param(8, 10, 3, id="rank-deficient"),
    pytest.param(6, 6, 6, id="square"),
    pytest.param(1, 5, 1, id="one-row"),
]


@pytest.mark.parametrize("nO, nf, rank", CASES)
@pytest.mark.parametrize("k0", [0, 1, 3], ids=["all-appended", "1-then-appended", "3-then-appended"])
def test_appended_rows_give_a_decomposition_of_the_rows(nO, nf, rank, k0):
    M = _rows(nO, nf, rank, seed=nO * 100 + nf * 10 + rank)
    c = Cod(M)
    k0 = min(k0, nO)
    c.scratch(k0)
    for j in range(k0, nO):
        c.append(j)
    assert c.r == np.linalg.matrix_rank(M)
    assert sorted(c.piv) == list(range(nO))
    for j in range(nO):
        np.testing.assert_allclose(c.row(j), M[c.piv[j]], rtol=0, atol=ATOL)
    b = np.random.default_rng(7).standard_normal(nO)
    np.testing.assert_allclose(c.step(b), np.linalg.lstsq(M, b, rcond=None)[0], rtol=0, atol=1e-9)


def test_a_dependent_row_then_an_independent_one_swaps_the_pivot_in():
    """The independent row becomes pivot r in front of the dependent one; the
    dependent row meets its reflector too."""
    rng = np.random.default_rng(3)
    top = rng.standard_normal((2, 6))
    M = np.vstack([top, top[0] - 2.0 * top[1], rng.standard_normal(6)])
    c = Cod(M)
    c.scratch(2)
    c.append(2)
    assert c.r == 2
    c.append(3)
    assert c.r == 3
    assert list(c.piv[2:]) == [3, 2]
    for j in range(4):
        np.testing.assert_allclose(c.row(j), M[c.piv[j]], rtol=0, atol=ATOL)
    assert np.linalg.norm(c.Mr[3, 3:]) < THR  # the dependent row: nothing left beyond the pivots


def test_a_nearly_dependent_pivot_is_flagged_weak():
    """[1, 1e-4] after [1, 0] is independent (1e-4 > THR) but becomes a pivot with
    diagonal 1e-4, where pivoting, once [0, 1] is in, takes [0, 1] and leaves
    diagonals of 1: the kernel refactors (cod) before the freeze when a pivot
    was weak."""
    M = np.array([[1.0, 0.0], [1.0, 0.1 * WEAK_PIVOT], [0.0, 1.0]])
    c = Cod(M)
    c.scratch(1)
    assert c.append(1)  # weak pivot
    assert not c.append(2)  # (r == nf: dependent)
    assert c.r == 2 and abs(c.diag[1]) < WEAK_PIVOT
    for j in range(3):
        np.testing.assert_allclose(c.row(j), M[c.piv[j]], rtol=0, atol=ATOL)
    c.piv[:] = np.arange(3)
    c.scratch(3)
    assert c.r == 2 and 2 in c.piv[:2]  # [0, 1] is a pivot, beside [1, 0] or [1, 1e-4]
    np.testing.assert_allclose(np.abs(c.diag[:2]), [1.0, 1.0], rtol=1e-7)
    assert not _appended(M[[0, 2]])[1]  # orthogonal rows: no weak pivot


#: a wide level's rows (projected on Z): a row of norm 1, one of norm 1e-8 whose part outside
#: the first is 5e-11 (under THR, 5e-3 of its own norm), and one of norm 2e-8 whose part outside
#: the first is 1e-27 (rounding at its own norm: dependent)
WIDE = np.array([[1.0, 0.0, 0.0], [1e-8, 5e-11, 0.0], [2e-8, 0.0, 1e-27]])


@pytest.mark.parametrize("appended", [False, True], ids=["from-scratch", "appended"])
def test_a_wide_levels_small_row_is_a_pivot_at_its_own_norm(appended):
    """On a wide level (``rrt = ROW_RANK_RTOL``) the rank test goes on row by row once the level's
    threshold THR is passed: the small row with 5e-3 of its norm outside the large one is a pivot
    (diagonal 5e-11), the row left with 1e-27 of its 2e-8 (5e-20) is not. With ``rrt = 0``
    both are cut at THR. The least-squares step of the targets of x = (1, 1, 0) reaches that x at
    ``rrt > 0`` (the one direction the small row sees beyond the large one is descended); at
    ``rrt = 0`` it stays at (1, 0, 0)."""
    b = WIDE @ np.array([1.0, 1.0, 0.0])
    for rrt, rank, x in ((0.0, 1, [1.0, 0.0, 0.0]), (ROW_RANK_RTOL, 2, [1.0, 1.0, 0.0])):
        c = Cod(WIDE, rrt=rrt)
        if appended:
            for j in range(3):
                c.append(j)
        else:
            c.scratch(3)
        assert c.r == rank, rrt
        assert list(c.piv[:rank]) == list(range(rank))
        for j in range(3):
            np.testing.assert_allclose(c.row(j), WIDE[c.piv[j]], rtol=0, atol=1e-20)
        np.testing.assert_allclose(c.step(b), x, rtol=0, atol=1e-9)
    np.testing.assert_allclose(abs(c.diag[1]), 5e-11, rtol=1e-12)


def test_the_row_by_row_pivot_is_the_largest_fraction_of_its_own_norm():
    """Past the level's threshold the next pivot is the row whose part outside the pivots is
    the largest fraction of its own norm, not the largest in absolute: here the row of norm
    1e-6 with 4e-11 left (4e-5 of it) loses to the row of norm 1e-9 with 2e-11 left (2e-2)."""
    M = np.array([[1.0, 0.0, 0.0], [1e-6, 4e-11, 0.0], [1e-9, 0.0, 2e-11]])
    c = Cod(M, rrt=ROW_RANK_RTOL)
    c.scratch(3)
    assert c.r == 3
    assert list(c.piv) == [0, 2, 1]
    for j in range(3):
        np.testing.assert_allclose(c.row(j), M[c.piv[j]], rtol=0, atol=1e-20)


def _appended(M: np.ndarray) -> tuple[Cod, bool]:
    """Every row of M appended in turn; (the decomposition, whether a pivot was weak)."""
    c = Cod(M)
    weak = False
    for j in range(M.shape[0]):
        weak |= c.append(j)
    return c, weak


def test_a_row_appended_when_the_rank_is_full_is_dependent():
    M = _rows(5, 3, 3, seed=11)
    c = Cod(M)
    c.scratch(3)
    assert c.r == 3
    c.append(3)
    c.append(4)
    assert c.r == 3
    for j in range(5):
        np.testing.assert_allclose(c.row(j), M[c.piv[j]], rtol=0, atol=ATOL)


@settings(max_examples=40, deadline=None)
@given(nO=st.integers(1, 10), nf=st.integers(1, 10), data=st.data())
def test_appending_matches_the_decomposition_from_scratch(nO, nf, data):
    """Same rank and same least-squares step as cod() of all the rows."""
    rank = data.draw(st.integers(1, min(nO, nf)), label="rank")
    k0 = data.draw(st.integers(0, nO), label="rows before appending")
    M = _rows(nO, nf, rank, seed=data.draw(st.integers(0, 2**31), label="seed"))
    inc, ref = Cod(M), Cod(M)
    inc.scratch(k0)
    for j in range(k0, nO):
        inc.append(j)
    ref.scratch(nO)
    assert inc.r == ref.r == rank
    b = np.random.default_rng(0).standard_normal(nO)
    scale = 1.0 + np.abs(ref.step(b)).max()
    np.testing.assert_allclose(inc.step(b), ref.step(b), rtol=0, atol=1e-8 * scale)


@pytest.mark.parametrize("p, n", [(1, 1), (2, 5), (7, 7), (12, 20)], ids=["1x1", "2-of-5", "7x7", "12-of-20"])
def test_solve_upper_solves_the_leading_triangle(p, n):
    """solve_upper (the multipliers' back substitution, eq. 39) solves ``R[:p, :p] x = h``
    and reads nothing outside the upper triangle of ``R[:p, :p]`` (the rest of R holds NaN here)."""
    rng = np.random.default_rng(p * n)
    R = np.full((n, n), np.nan)
    T = np.triu(rng.standard_normal((p, p)))
    T[np.diag_indices(p)] = rng.uniform(0.5, 2.0, p) * rng.choice([-1.0, 1.0], p)
    R[:p, :p] = np.where(np.triu(np.ones((p, p))) > 0, T, np.nan)
    h = np.full(n, np.nan)
    h[:p] = rng.standard_normal(p)
    x = np.full(n, np.nan)
    expected = np.linalg.solve(T, h[:p])
    solve_upper(R, p, h, x)
    np.testing.assert_allclose(x[:p], expected, rtol=1e-12, atol=1e-12)
    assert np.isnan(x[p:]).all()


# -- four reflectors of a level applied at once (the equality recursion, _equality.py) -----------

def _level_reflectors(L: int, seed: int):
    """Four consecutive Householder reflectors ``I - b_i v_i v_i^T`` of a QR,
    v_i starting i columns after v_0 (as they sit in a level's rows), as full
    vectors of length L and as the views the kernels take."""
    rng = np.random.default_rng(seed)
    V = np.zeros((4, L))
    b = np.zeros(4)
    for i in range(4):
        v = rng.standard_normal(L - i)
        V[i, i:] = v
        b[i] = 2.0 / (v @ v)
    return V, b


@pytest.mark.parametrize("L", [4, 5, 11, 40, 97], ids=lambda L: f"L{L}")
@pytest.mark.parametrize("rows", [1, 2], ids=lambda r: f"{r}-rows")
def test_four_reflectors_at_once_equal_four_in_turn(L, rows):
    """reflect_quad / reflect_quad2 give H4 H3 H2 H1 x of each row, with the
    coupling products of quad_gram (the products of the reflectors' tails)."""
    from hikbench.solvers.hcod._linalg import quad_gram, reflect_quad, reflect_quad2

    V, b = _level_reflectors(L, seed=L * rows)
    X = np.random.default_rng(rows).standard_normal((rows, L))
    expected = X.copy()
    for i in range(4):
        expected -= b[i] * np.outer(expected @ V[i], V[i])
    views = [V[i, i:].copy() for i in range(4)]
    g = quad_gram(*views)
    np.testing.assert_allclose(g, [V[1] @ V[0], V[2] @ V[0], V[2] @ V[1], V[3] @ V[0], V[3] @ V[1], V[3] @ V[2]],
                               rtol=1e-13, atol=1e-13)
    Y = X.copy()
    fn = {1: reflect_quad, 2: reflect_quad2}[rows]
    fn(tuple(b), g, *views, *Y)
    np.testing.assert_allclose(Y, expected, rtol=0, atol=ATOL)


# -- the workspaces as unowned arrays -------------------------------------------------------------

@pytest.mark.parametrize("shape", [(7,), (3, 5)], ids=["1d", "2d"])
def test_unowned_array_is_the_same_data(shape):
    """The kernels' workspaces enter as unowned arrays (no reference
    counting): same shape, same memory; writes through a view land in the
    caller's array."""
    from numba import njit

    from hikbench.solvers.hcod._linalg import unowned

    @njit
    def fill(a):
        u = unowned(a)
        v = u.reshape(-1)
        for c in range(v.shape[0]):
            v[c] = c + 0.5
        return u.shape, u.ctypes.data

    a = np.zeros(shape)
    got_shape, addr = fill(a)
    assert got_shape == shape and addr == a.ctypes.data
    np.testing.assert_array_equal(a.reshape(-1), np.arange(a.size) + 0.5)
