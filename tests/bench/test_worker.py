"""hikbench.bench.harness.worker.execute: the untimed start of a solve job."""

from __future__ import annotations

import numpy as np
import pytest

from hikbench.bench.harness.worker import execute
from hikbench.problems import generators as G
from hikbench.solvers.yardstick import YardstickSolver

CALLS: list[str] = []


class RecordingSolver(YardstickSolver):
    """The reference solver, recording warmup() and solve() calls (module:Class spec)."""

    def warmup(self) -> None:
        CALLS.append("warmup")

    def solve(self, hierarchy):
        CALLS.append("solve")
        return super().solve(hierarchy)


def test_warmup_comes_before_the_first_solve_and_the_notice():
    """A solver's warmup() runs before the job's untimed first solve, all of it inside
    the first-solve allowance (before notify): otherwise hcod's inequality kernel would load
    inside the job timeout of the first ik-like job after an equality one."""
    CALLS.clear()
    h = G.random_hierarchy(4, 2, 2, seed=0)
    job = {"kind": "solve", "hierarchy": h, "solver": f"{__name__}:RecordingSolver", "options": {},
           "mode": "cold", "repeat": 2, "warmup": 1}
    out = execute(job, notify=lambda: CALLS.append("notify"))
    assert out["status"] == "optimal", out["reason"]
    assert CALLS[:3] == ["warmup", "solve", "notify"]
    assert CALLS.count("warmup") == 1 and CALLS.count("solve") == 1 + 1 + 2  # first, warm-up, timed
    assert np.all(np.isfinite(out["x"]))


class GcRecordingSolver(YardstickSolver):
    """The reference solver, recording for each solve whether the collector was on."""

    def solve(self, hierarchy):
        import gc

        CALLS.append("gc on" if gc.isenabled() else "gc off")
        return super().solve(hierarchy)


@pytest.mark.parametrize("mode", ["cold", "warm"])
@pytest.mark.parametrize("warmup", [0, 1, 3], ids=["warmup-0", "warmup-1", "warmup-3"])
def test_every_warmup_solve_runs_right_before_the_timed_ones(mode, warmup):
    """The job's warm-up solves run after the collector's pass and the BLAS limit (GC off), as the
    timed ones do; the untimed first solve is not one of them. It was counted as one: with the
    suites' warmup = 1 no solve came between the collector's pass and the first timed one, which
    took 2-7x the median of the others."""
    CALLS.clear()
    h = G.random_hierarchy(4, 2, 2, seed=0)
    job = {"kind": "solve", "hierarchy": h, "solver": f"{__name__}:GcRecordingSolver", "options": {},
           "mode": mode, "repeat": 2, "warmup": warmup}
    assert execute(job)["status"] == "optimal"
    warm_extra = 1 if mode == "warm" else 0  # warm: the object's own first solve, then warm-ups
    assert CALLS == ["gc on"] + ["gc off"] * (max(warmup, warm_extra) + 2)
