"""bench.worker.execute: the untimed start of a solve job."""

from __future__ import annotations

import numpy as np

from bench.worker import execute
from problems import generators as G
from solvers.reference import ReferenceSolver

CALLS: list[str] = []


class RecordingSolver(ReferenceSolver):
    """The reference solver, recording warmup() and solve() calls (module:Class spec)."""

    def warmup(self) -> None:
        CALLS.append("warmup")

    def solve(self, hierarchy):
        CALLS.append("solve")
        return super().solve(hierarchy)


def test_warmup_comes_before_the_first_solve_and_the_notice():
    """A solver's warmup() runs before the job's untimed first solve, all of it inside
    the first-solve allowance (before notify): hcod's inequality kernel used to compile
    inside the job timeout of the first ik-like job after an equality one."""
    CALLS.clear()
    h = G.random_hierarchy(4, 2, 2, seed=0)
    job = {"kind": "solve", "hierarchy": h, "solver": f"{__name__}:RecordingSolver", "options": {},
           "mode": "cold", "repeat": 2, "warmup": 1}
    out = execute(job, notify=lambda: CALLS.append("notify"))
    assert out["status"] == "optimal", out["reason"]
    assert CALLS[:3] == ["warmup", "solve", "notify"]
    assert CALLS.count("warmup") == 1 and CALLS.count("solve") == 1 + 2
    assert np.all(np.isfinite(out["x"]))
