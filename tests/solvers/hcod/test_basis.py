"""The basis W of the HCOD inequality kernel (solvers/hcod/_basis.py) in its
two representations: explicit (_explicit.py), and factored (_factored.py: an
explicit W0 times a queue of pending reflectors and rotations). Each test
checks the products against the invariants of the decomposition (W
orthonormal, W[:, :p] R = C^T for the working rows C) and, factored, against
the flushed, explicit W0."""

from __future__ import annotations

import numpy as np
import pytest

from hikbench.solvers.hcod._basis import (
    LAZY_MIN_N,
    basis_head,
    basis_n,
    basis_permuted,
    basis_reset,
    basis_rows,
    basis_t,
    delete_row,
    insert_row,
    insert_rows,
    multipliers,
    push_reflectors,
)
from hikbench.solvers.hcod._explicit import W_PERMUTED
from hikbench.solvers.hcod._factored import Q_ID, Q_M, QH, basis_row, flush, queue_sizes

pytestmark = pytest.mark.usefixtures("hcod_kernels_loaded_first")

ATOL = 1e-11


class Basis:
    """Arrays of one basis (W = I at the start) with the working rows kept
    beside it for the invariants."""

    def __init__(self, n: int, m: int, rng, lazy: bool = True):
        self.n = n
        self.lazy = lazy
        self.A = rng.standard_normal((m, n))
        self.bcol = np.full(m, -1, dtype=np.int64)
        self.bval = np.zeros(m)
        for i in range(0, m, 5):  # every fifth row a bound row
            c = int(rng.integers(n))
            self.A[i] = 0.0
            self.A[i, c] = self.bval[i] = rng.choice([-2.0, 1.0, 0.5])
            self.bcol[i] = c
        self.Wt = np.full((n, n), np.nan)  # not read while W0 is flagged the identity
        nq, ni = queue_sizes(n)
        self.qv, self.qi = np.zeros(nq), np.zeros(ni, dtype=np.int64)
        basis_reset(lazy, self.Wt, self.qi)
        self.R = np.zeros((n, n))
        self.q, self.sv, self.sv2 = np.zeros(n), np.zeros(n), np.zeros(n)
        self.widx = np.zeros(n, dtype=np.int64)
        self.wside = np.zeros(n, dtype=np.int64)
        self.p = 0

    def args(self):
        return self.Wt, self.qv, self.qi, self.sv, self.sv2

    def wq(self):
        return self.lazy, self.Wt, self.qv, self.qi

    def insert(self, i) -> bool:
        ok, _, _ = insert_row(self.lazy, self.A, i, self.bcol, self.bval, self.R, self.p, 1e-10, self.q,
                              *self.args())
        if ok:
            self.widx[self.p] = i
            self.p += 1
        return ok

    def delete(self, j):
        delete_row(self.lazy, j, self.R, self.p, self.widx, self.wside, np.zeros((1, self.n)), 0, *self.args())
        self.p -= 1

    def push(self, Mr, beta, r):
        """The reflectors of a COD on the free columns (eq. 23)."""
        push_reflectors(*self.wq(), self.p, Mr, beta, r, np.zeros(self.n * self.n), self.sv, self.sv2)

    def W(self) -> np.ndarray:
        """W column by column, by products (W e_c; through the queue when factored)."""
        n = self.n
        W = np.empty((n, n))
        for c in range(n):
            x = np.zeros(n)
            x[c] = 1.0
            basis_n(*self.wq(), x, 0, n, self.sv, self.sv2)
            W[:, c] = x
        return W

    def check(self):
        W = self.W()
        n, p = self.n, self.p
        np.testing.assert_allclose(W.T @ W, np.eye(n), rtol=0, atol=ATOL)
        C = self.A[self.widx[:p]]
        np.testing.assert_allclose(W[:, :p] @ np.triu(self.R[:p, :p]), C.T, rtol=0, atol=ATOL)
        x = np.arange(1.0, n + 1.0)
        y = x.copy()
        basis_t(*self.wq(), y, 0, n, self.sv, self.sv2)
        np.testing.assert_allclose(y, W.T @ x, rtol=0, atol=ATOL * n)
        y = x.copy()
        basis_t(*self.wq(), y, p, n, self.sv, self.sv2)  # Z^T x
        np.testing.assert_allclose(y[p:], W[:, p:].T @ x, rtol=0, atol=ATOL * n)
        rows = np.arange(len(self.A), dtype=np.int64)
        M = np.zeros((len(self.A), n))
        basis_rows(*self.wq()[:1], self.A, rows, 0, len(rows), self.bcol, self.bval, *self.wq()[1:], M, p, self.sv,
                   self.sv2)
        c0 = 0 if self.lazy else p  # (whole rows when factored, their projection on Z when explicit)
        np.testing.assert_allclose(M[:, c0:], (self.A @ W)[:, c0:], rtol=0, atol=ATOL * n)
        if self.lazy:
            out = np.zeros(n)
            basis_row(self.A, 0, self.bcol, self.bval, *self.args()[:3], out, self.sv, self.sv2)
            np.testing.assert_allclose(out, self.A[0] @ W, rtol=0, atol=ATOL * n)
        return W


@pytest.mark.parametrize(
    "n, lazy, flushed",
    [(6, False, False), (6, True, False), (6, True, True), (80, False, False), (80, True, False), (80, True, True)],
    ids=["n6-explicit", "n6-factored", "n6-flushed", "n80-explicit", "n80-factored", "n80-flushed"])
def test_updates_keep_the_decomposition(n, lazy, flushed):
    """Rows enter (one Householder reflector each) and leave (a sequence of
    Givens rotations), a level's COD pushes consecutive reflectors (the pair
    kernels): the products are W (orthonormal, W R = C^T); factored, before
    and after the flush into W0."""
    rng = np.random.default_rng(n)
    b = Basis(n, 3 * n, rng, lazy)
    for i in range(n // 2):
        assert b.insert(i)
    if flushed:
        flush(*b.args())
        assert b.qi[Q_ID] == 0 and b.qi[Q_M] == 0
    b.check()
    for j in (b.p - 2, 0, 1):  # a row from the end, the first, a middle one
        b.delete(j)
    b.check()
    # the reflectors of a COD on the free columns, consecutive (pairs), then one row more
    p, nf = b.p, n - b.p
    H = np.linalg.qr(rng.standard_normal((nf, nf)))[0]
    r = min(3, nf - 1)
    Mr, beta = np.zeros((r, nf)), np.zeros(r)
    for t in range(r):
        v = H[t:, t].copy()
        v[0] += 1.0
        Mr[t, t:], beta[t] = v, 2.0 / (v @ v)
    b.push(Mr, beta, r)
    W_before = b.W()
    # (the columns p.. changed by an orthogonal factor: W R = C^T still holds on :p)
    np.testing.assert_allclose(W_before[:, :p] @ np.triu(b.R[:p, :p]), b.A[b.widx[:p]].T, rtol=0, atol=ATOL)
    assert b.insert(n // 2 + 1)
    W = b.check()
    if lazy:
        flush(*b.args())
    np.testing.assert_allclose(b.Wt.T, W, rtol=0, atol=ATOL * n)
    b.check()


def test_storage_full_flushes_and_keeps_w():
    """More entries than the queue holds: it is flushed on the way, W stays
    right."""
    n = LAZY_MIN_N
    rng = np.random.default_rng(3)
    b = Basis(n, 1200, rng)
    flushed = 0
    i = 0
    for _ in range(300):
        while b.p < n - 1 and i < len(b.A):
            b.insert(i)
            i += 1
        b.delete(0)
        flushed += b.qi[Q_ID] == 0
    assert (len(b.qi) - QH) // 3 < 300 * 2
    assert flushed > 0
    b.check()


def test_products_flush_a_long_queue_only():
    """The rent-or-buy rule: products through a queue dearer than an explicit
    W end in a flush; through a cheap queue (a few reflectors) never."""
    n = LAZY_MIN_N
    rng = np.random.default_rng(5)
    b = Basis(n, 3 * n, rng)
    for i in range(3):
        b.insert(i + 1)
    x = rng.standard_normal(n)
    for _ in range(100):
        basis_t(*b.wq(), x.copy(), 0, n, b.sv, b.sv2)
    assert b.qi[Q_ID] == 1 and b.qi[Q_M] == 3
    for k in range(40):  # a long queue: 40 deletions and insertions, dearer than n^2 per product
        b.delete(0)
        b.insert(4 + k)
    b.W()  # n products more
    assert b.qi[Q_ID] == 0  # the products paid for a flush
    b.check()


@pytest.mark.parametrize("lazy", [False, True], ids=["explicit", "factored"])
@pytest.mark.parametrize("n, p, m", [(12, 3, 5), (80, 10, 30)], ids=["small", "large"])
def test_blocked_insertion_matches_one_row_at_a_time(n, p, m, lazy):
    """insert_rows (the warm start's Delta+ A) = m calls of insert_row: same
    refusals (a dependent row), same R, same basis."""
    rng = np.random.default_rng(n)
    b1 = Basis(n, p + m, rng, lazy)
    b1.A[p + 1] = 2.0 * b1.A[p] - b1.A[1]  # dependent on a working row and an earlier candidate
    b1.bcol[p + 1] = -1
    for i in range(p):
        assert b1.insert(i)
    b2 = Basis(n, p + m, rng, lazy)
    for name in ("A", "bcol", "bval", "R", "widx"):
        setattr(b2, name, getattr(b1, name).copy())
    b2.Wt, b2.qv, b2.qi, b2.p = b1.Wt.copy(), b1.qv.copy(), b1.qi.copy(), b1.p
    ok1 = [int(b1.insert(i)) for i in range(p, p + m)]
    cand = np.arange(p, p + m, dtype=np.int64)
    cok = np.zeros(m, dtype=np.int64)
    t, _ = insert_rows(lazy, b2.A, cand, m, b2.bcol, b2.bval, b2.R, p, 1e-10, np.ones(p + m),
                       np.zeros((m, n)), np.zeros(m), cok, *b2.args())
    assert cok.tolist() == ok1 and ok1[1] == 0 and t == b1.p - p
    b2.widx[p:p + t] = cand[cok == 1]
    b2.p = p + t
    np.testing.assert_allclose(np.triu(b2.R[:b2.p, :b2.p]), np.triu(b1.R[:b1.p, :b1.p]), rtol=0, atol=1e-10)
    np.testing.assert_allclose(b2.check(), b1.check(), rtol=0, atol=1e-10)


@pytest.mark.parametrize("lazy", [False, True], ids=["explicit", "factored"])
def test_insert_row_refuses_without_room(lazy):
    """With p = n working rows there is no Z left: insert_row refuses the row
    at once and leaves the basis, the queue and R as they were."""
    n = 4
    b = Basis(n, 1, np.random.default_rng(0), lazy)
    b.R[:] = np.triu(np.ones((n, n)))
    qi0, Wt0 = b.qi.copy(), b.Wt.copy()
    ok, flops, _ = insert_row(lazy, b.A, 0, b.bcol, b.bval, b.R, n, 1e-10, b.q, *b.args())
    assert not ok and flops == 0
    np.testing.assert_array_equal(b.qi, qi0)
    np.testing.assert_array_equal(b.Wt, Wt0)
    np.testing.assert_array_equal(b.R, np.triu(np.ones((n, n))))


def _projections(b: Basis, rows: np.ndarray) -> tuple[np.ndarray, int]:
    M = np.zeros((len(rows), b.n))
    fl = basis_rows(b.lazy, b.A, rows, 0, len(rows), b.bcol, b.bval, b.Wt, b.qv, b.qi, M, b.p, b.sv, b.sv2)
    return M, fl


@pytest.mark.parametrize("update", ["push", "insert", "insert_rows"])
def test_explicit_identity_flag(update):
    """An explicit W starts as the identity, flagged a permutation (of the identity's
    columns): the projections (eq. 19) are copies of the rows (no multiply-adds); a
    refused row leaves the flag, the first general update clears it and the products
    read W again."""
    n = 8
    rng = np.random.default_rng(11)
    b = Basis(n, 12, rng, lazy=False)
    rows = np.arange(12, dtype=np.int64)  # general rows and bound rows (every fifth)
    assert b.qi[Q_ID] == W_PERMUTED
    M, fl = _projections(b, rows)
    assert fl == 0
    np.testing.assert_array_equal(M, b.A)
    ok, _, _ = insert_row(False, b.A, 1, b.bcol, b.bval, b.R, b.p, 1e30, b.q, *b.args())  # refused
    assert not ok and b.qi[Q_ID] == W_PERMUTED
    if update == "push":
        Mr = rng.standard_normal((2, n))
        beta = 2.0 / np.array([Mr[0] @ Mr[0], Mr[1, 1:] @ Mr[1, 1:]])
        b.push(Mr, beta, 2)
    elif update == "insert":
        assert b.insert(1)
    else:
        cok = np.zeros(2, dtype=np.int64)
        t, _ = insert_rows(False, b.A, np.array([1, 5], dtype=np.int64), 2, b.bcol, b.bval, b.R, 0, 1e-10,
                           np.ones(12), np.zeros((2, n)), np.zeros(2), cok, *b.args())
        assert t == 2
        b.widx[:2] = [1, 5]
        b.p = 2
    assert b.qi[Q_ID] == 0
    W = b.check()
    assert np.abs(W - np.eye(n)).max() > 0.1
    M, fl = _projections(b, rows)
    assert fl > 0
    np.testing.assert_allclose(M[:, b.p:], (b.A @ W)[:, b.p:], rtol=0, atol=ATOL * n)


def _bound_rows(b: Basis) -> list[int]:
    """The bound rows of b on distinct variables, in row order."""
    seen, rows = set(), []
    for i in np.flatnonzero(b.bcol >= 0):
        if b.bcol[i] not in seen:
            seen.add(int(b.bcol[i]))
            rows.append(int(i))
    return rows


def _dense_copy(b: Basis) -> Basis:
    """The same basis with the permutation flag cleared: every product reads W."""
    d = Basis(b.n, 1, np.random.default_rng(0), lazy=False)
    for name in ("A", "bcol", "bval", "R", "widx", "Wt", "qi"):
        setattr(d, name, getattr(b, name).copy())
    d.qi[Q_ID] = 0
    d.p = b.p
    return d


@pytest.mark.parametrize("blocked", [False, True], ids=["one-at-a-time", "insert_rows"])
def test_bound_rows_enter_an_identity_basis_by_swaps(blocked):
    """Bound rows entering an explicit W = I: the Householder reflector that maps
    W^T e_c = e_pos to e_p can be the swap of W's columns p and pos, so W stays a
    permutation (flag W_PERMUTED), R's column is (0, bval) and no multiply-add is
    spent; a second bound row on a variable already working is refused (W^T e_c
    has nothing left on Z). The products gather and scatter, equal to the dense
    ones; the first general update leaves the permutation."""
    n = 10
    rng = np.random.default_rng(7)
    b = Basis(n, 40, rng, lazy=False)
    rows = _bound_rows(b)[:4]
    dup, c = 3, b.bcol[rows[1]]  # (row 3: a bound row on the variable of rows[1])
    b.A[dup] = 0.0
    b.A[dup, c] = b.bval[dup] = -1.5
    b.bcol[dup] = c
    assert b.qi[Q_ID] == W_PERMUTED and basis_permuted(False, b.qi) and not basis_permuted(True, b.qi)
    if blocked:
        cand = np.array([*rows[:2], dup, *rows[2:]], dtype=np.int64)
        cok = np.zeros(len(cand), dtype=np.int64)
        t, fl = insert_rows(False, b.A, cand, len(cand), b.bcol, b.bval, b.R, 0, 1e-10, np.ones(len(b.A)),
                            np.zeros((len(cand), n)), np.zeros(len(cand)), cok,
                            *b.args())
        assert cok.tolist() == [1, 1, 0, 1, 1] and t == 4 and fl == 0
        b.widx[:4] = rows
        b.p = 4
    else:
        for i in rows[:2]:
            assert b.insert(i)
        ok, fl, _ = insert_row(False, b.A, dup, b.bcol, b.bval, b.R, b.p, 1e-10, b.q, *b.args())
        assert not ok and fl == 0
        for i in rows[2:]:
            # the returned reflector (q[p:], beta) carries a projected row W^T a on to the new W
            # (the kernel's mf_reflect on its objective rows): the swap of entries p and pos
            m_old = b.A[1] @ b.W()
            p0 = b.p
            ok, fl, bt = insert_row(False, b.A, i, b.bcol, b.bval, b.R, p0, 1e-10, b.q, *b.args())
            assert ok and fl == 0
            b.widx[p0] = i
            b.p += 1
            v = b.q[p0:]
            np.testing.assert_allclose(m_old[p0:] - bt * v * (v @ m_old[p0:]), (b.A[1] @ b.W())[p0:], rtol=0,
                                       atol=1e-15)
    assert b.qi[Q_ID] == W_PERMUTED
    W = b.check()  # (orthonormal, W R = C^T, products and projections: gathers and scatters)
    assert set(np.abs(W).ravel().tolist()) == {0.0, 1.0}
    np.testing.assert_array_equal(np.triu(b.R[:4, :4]), np.diag(b.bval[rows]))
    M, fl = _projections(b, np.arange(len(b.A), dtype=np.int64))
    assert fl == 0
    np.testing.assert_array_equal(M[:, b.p:], (b.A @ W)[:, b.p:])
    d = _dense_copy(b)
    g = rng.standard_normal(n)
    nu, nu_d = np.zeros(n), np.zeros(n)
    multipliers(False, b.R, b.p, g.copy(), nu, np.zeros(n), *b.args())
    multipliers(False, d.R, d.p, g.copy(), nu_d, np.zeros(n), *d.args())
    np.testing.assert_allclose(nu[:b.p], nu_d[:b.p], rtol=1e-14, atol=0)
    for i in (0, 1, rows[0]):  # a bound row, a general row, a working bound row
        h, h_d = np.zeros(n), np.zeros(n)
        assert basis_head(False, b.A, i, b.bcol, b.bval, b.Wt, b.qi, b.p, h) == 0
        basis_head(False, d.A, i, d.bcol, d.bval, d.Wt, d.qi, d.p, h_d)
        np.testing.assert_allclose(h[:b.p], h_d[:b.p], rtol=0, atol=1e-15)
        np.testing.assert_allclose(h[:b.p], (b.A[i] @ W)[:b.p], rtol=0, atol=1e-15)
    b.delete(1)  # Givens rotations of W's columns: no longer a permutation
    assert b.qi[Q_ID] == 0
    b.check()
    assert b.insert(1)  # a general row: a dense reflector
    b.check()


@pytest.mark.parametrize("r", [1, 2, 3], ids=["one", "a-pair", "a-pair-and-one"])
def test_push_onto_a_permuted_basis(r):
    """A level's COD reflectors pushed onto W[:, p:] while W is a permutation: H
    accumulated on the identity of order n - p and scattered equals the dense
    product W[:, p:] H (the flag is cleared; fewer multiply-adds)."""
    n = 9
    rng = np.random.default_rng(r)
    b = Basis(n, 40, rng, lazy=False)
    for i in _bound_rows(b)[:3]:
        assert b.insert(i)
    assert b.qi[Q_ID] == W_PERMUTED
    d = _dense_copy(b)
    p, nf = b.p, n - b.p
    Mr, beta = np.full((r, n), np.nan), np.zeros(r)  # (rows of width n, as the kernel's: read to nf only)
    for t in range(r):
        v = rng.standard_normal(nf - t)
        Mr[t, t:nf], beta[t] = v, 2.0 / (v @ v)
    b.sv[:] = b.sv2[:] = np.nan  # (scratch: nothing read from it)
    fl = push_reflectors(False, b.Wt, b.qv, b.qi, p, Mr, beta, r, np.full(n * n, np.nan), b.sv, b.sv2)
    fl_d = push_reflectors(False, d.Wt, d.qv, d.qi, p, Mr, beta, r, np.zeros(n * n), d.sv, d.sv2)
    assert b.qi[Q_ID] == 0 and fl == 2 * nf * nf * r < fl_d
    np.testing.assert_allclose(b.Wt, d.Wt, rtol=0, atol=1e-15)
    b.check()
