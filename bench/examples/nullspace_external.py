#!/usr/bin/env python3
"""A tiny external solver for ``--solvers external:NAME=CMD`` (docs/adding-a-solver.md,
"External solvers"). It uses numpy only (no hikbench), like a C++ program would
use its own reader:

    python bench/examples/nullspace_external.py PROBLEM.npz OUT.json

reads the problem (.npz: A, lower, upper, level, n), solves its equality rows
(lower == upper) with the SVD null-space recursion (ICRA 2010 eq. 2; inequality
rows are ignored), and writes ``{"x": [...], "solve_time_s": t, "status": "optimal"}``.

``solve_time_s`` is the time of the solve alone: reading the file, writing the
answer and the process start-up are left out. numpy's first SVD in a process
pays a one-off start-up (LAPACK workspace, lazy imports: milliseconds, however
small the problem), so the problem is solved once untimed before the timed
solve, as the harness does with in-process solvers (warm-up, then timing).
"""

import json
import sys
import time

import numpy as np


def solve(A, lower, upper, level, n, rtol=1e-10):
    """x of the equality rows, level by level in the null space of the levels above
    (rank: the singular values above ``rtol`` times the level's norm)."""
    x, Z = np.zeros(n), np.eye(n)
    for k in np.unique(level):
        rows = (level == k) & (lower == upper)
        if not rows.any() or Z.shape[1] == 0:
            continue
        Ak, bk = A[rows], lower[rows]
        U, s, Vt = np.linalg.svd(Ak @ Z)
        r = int(np.sum(s > rtol * max(np.linalg.norm(Ak, 2), 1e-300)))
        if r:
            x = x + Z @ (Vt[:r].T @ ((U[:, :r].T @ (bk - Ak @ x)) / s[:r]))
        Z = Z @ Vt[r:].T
    return x


def main(problem: str, out: str) -> int:
    with np.load(problem) as z:
        A, lower, upper, level, n = z["A"], z["lower"], z["upper"], z["level"], int(z["n"])
    solve(A, lower, upper, level, n)  # warm-up, untimed: numpy's first-call start-up
    t0 = time.perf_counter()
    x = solve(A, lower, upper, level, n)
    elapsed = time.perf_counter() - t0
    with open(out, "w") as f:
        json.dump({"x": x.tolist(), "solve_time_s": elapsed, "status": "optimal"}, f)
    return 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:3]))
