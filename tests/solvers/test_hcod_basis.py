"""The basis W of the HCOD inequality kernel (solvers/hcod/_basis.py): an
explicit W0 times a queue of pending reflectors and rotations. Each test
checks the products through the queue against the invariants of the
decomposition (W orthonormal, W[:, :p] R = C^T for the working rows C) and
against the flushed, explicit W."""

from __future__ import annotations

import numpy as np
import pytest

from solvers.hcod._basis import (
    LAZY_MIN_N,
    Q_ID,
    Q_M,
    QH,
    basis_n,
    basis_reset,
    basis_row,
    basis_rows,
    basis_t,
    delete_row,
    flush,
    insert_row,
    insert_rows,
    push_reflector,
    queue_sizes,
)

ATOL = 1e-11


class Basis:
    """Arrays of one basis (W = I at the start) with the working rows kept
    beside it for the invariants."""

    def __init__(self, n: int, m: int, rng):
        self.n = n
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
        basis_reset(self.qi)
        self.R = np.zeros((n, n))
        self.q, self.sv, self.sv2 = np.zeros(n), np.zeros(n), np.zeros(n)
        self.widx = np.zeros(n, dtype=np.int64)
        self.wside = np.zeros(n, dtype=np.int64)
        self.p = 0

    def args(self):
        return self.Wt, self.qv, self.qi, self.sv, self.sv2

    def insert(self, i) -> bool:
        ok, _, _ = insert_row(self.A, i, self.bcol, self.bval, self.R, self.p, 1e-10, self.q, *self.args())
        if ok:
            self.widx[self.p] = i
            self.p += 1
        return ok

    def delete(self, j):
        delete_row(j, self.R, self.p, self.widx, self.wside, np.zeros((1, self.n)), 0, *self.args())
        self.p -= 1

    def W(self) -> np.ndarray:
        """W column by column, by products through the queue (W e_c)."""
        n = self.n
        W = np.empty((n, n))
        for c in range(n):
            x = np.zeros(n)
            x[c] = 1.0
            basis_n(*self.args()[:3], x, 0, n, self.sv, self.sv2)
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
        basis_t(*self.args()[:3], y, 0, n, self.sv, self.sv2)
        np.testing.assert_allclose(y, W.T @ x, rtol=0, atol=ATOL * n)
        rows = np.arange(len(self.A), dtype=np.int64)
        M = np.zeros((len(self.A), n))
        basis_rows(self.A, rows, 0, len(rows), self.bcol, self.bval, self.Wt, self.qv, self.qi, M, 0, self.sv,
                   self.sv2)
        np.testing.assert_allclose(M, self.A @ W, rtol=0, atol=ATOL * n)
        out = np.zeros(n)
        basis_row(self.A, 0, self.bcol, self.bval, *self.args()[:3], out, self.sv, self.sv2)
        np.testing.assert_allclose(out, self.A[0] @ W, rtol=0, atol=ATOL * n)
        return W


@pytest.mark.parametrize("n, explicit", [(6, False), (6, True), (80, False), (80, True)],
                         ids=["n6-identity", "n6-flushed", "n80-identity", "n80-flushed"])
def test_updates_keep_the_decomposition(n, explicit):
    """Rows enter (one Householder reflector each) and leave (a sequence of
    Givens rotations), a level's COD pushes consecutive reflectors (the pair
    kernels): the products through the queue are W (orthonormal, W R = C^T),
    before and after the flush into W0."""
    rng = np.random.default_rng(n)
    b = Basis(n, 3 * n, rng)
    for i in range(n // 2):
        assert b.insert(i)
    if explicit:
        flush(*b.args())
        assert b.qi[Q_ID] == 0 and b.qi[Q_M] == 0
    b.check()
    for j in (b.p - 2, 0, 1):  # a row from the end, the first, a middle one
        b.delete(j)
    b.check()
    # the reflectors of a COD on the free columns, consecutive (pairs), then one row more
    p, nf = b.p, n - b.p
    H = np.linalg.qr(rng.standard_normal((nf, nf)))[0]
    for t in range(min(3, nf - 1)):
        v = H[t:, t].copy()
        v[0] += 1.0
        push_reflector(*b.args()[:3], p + t, v, 2.0 / (v @ v), b.sv, b.sv2)
    W_before = b.W()
    # (the columns p.. changed by an orthogonal factor: W R = C^T still holds on :p)
    np.testing.assert_allclose(W_before[:, :p] @ np.triu(b.R[:p, :p]), b.A[b.widx[:p]].T, rtol=0, atol=ATOL)
    assert b.insert(n // 2 + 1)
    W = b.check()
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
        basis_t(*b.args()[:3], x.copy(), 0, n, b.sv, b.sv2)
    assert b.qi[Q_ID] == 1 and b.qi[Q_M] == 3
    for k in range(40):  # a long queue: 40 deletions and insertions, dearer than n^2 per product
        b.delete(0)
        b.insert(4 + k)
    b.W()  # n products more
    assert b.qi[Q_ID] == 0  # the products paid for a flush
    b.check()


@pytest.mark.parametrize("n, p, m", [(12, 3, 5), (80, 10, 30)], ids=["small", "large"])
def test_blocked_insertion_matches_one_row_at_a_time(n, p, m):
    """insert_rows (the warm start's Delta+ A) = m calls of insert_row: same
    refusals (a dependent row), same R, same basis."""
    rng = np.random.default_rng(n)
    b1 = Basis(n, p + m, rng)
    b1.A[p + 1] = 2.0 * b1.A[p] - b1.A[1]  # dependent on a working row and an earlier candidate
    b1.bcol[p + 1] = -1
    for i in range(p):
        assert b1.insert(i)
    b2 = Basis(n, p + m, rng)
    for name in ("A", "bcol", "bval", "R", "widx"):
        setattr(b2, name, getattr(b1, name).copy())
    b2.Wt, b2.qv, b2.qi, b2.p = b1.Wt.copy(), b1.qv.copy(), b1.qi.copy(), b1.p
    ok1 = [int(b1.insert(i)) for i in range(p, p + m)]
    cand = np.arange(p, p + m, dtype=np.int64)
    cok = np.zeros(m, dtype=np.int64)
    t, _ = insert_rows(b2.A, cand, m, b2.bcol, b2.bval, b2.R, p, 1e-10, np.ones(1), np.zeros(p + m, dtype=np.int64),
                       np.zeros((m, n)), cok, *b2.args())
    assert cok.tolist() == ok1 and ok1[1] == 0 and t == b1.p - p
    b2.widx[p:p + t] = cand[cok == 1]
    b2.p = p + t
    np.testing.assert_allclose(np.triu(b2.R[:b2.p, :b2.p]), np.triu(b1.R[:b1.p, :b1.p]), rtol=0, atol=1e-10)
    np.testing.assert_allclose(b2.check(), b1.check(), rtol=0, atol=1e-10)


def test_insert_row_refuses_without_room():
    """With p = n working rows there is no Z left: insert_row refuses the row
    at once and leaves the queue and R as they were."""
    n = 4
    b = Basis(n, 1, np.random.default_rng(0))
    b.R[:] = np.triu(np.ones((n, n)))
    qi0 = b.qi.copy()
    ok, flops, _ = insert_row(b.A, 0, b.bcol, b.bval, b.R, n, 1e-10, b.q, *b.args())
    assert not ok and flops == 0
    np.testing.assert_array_equal(b.qi, qi0)
    np.testing.assert_array_equal(b.R, np.triu(np.ones((n, n))))
