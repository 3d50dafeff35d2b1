"""The dual active-set cascades (daqp, quadprog) at their default settings on a 7-joint arm
stack with joint and velocity limits at level 0, tip position, tip orientation, posture: they
solve what the other backends solve (docs/solvers.md, "Fair settings")."""

from __future__ import annotations

import pytest
from urdf_robots import write_robots

from hikbench.problems.generators import generate
from hikbench.problems.verify import verify
from hikbench.solvers import registry
from hikbench.solvers.base import OPTIMAL

SEEDS = range(6)
#: joint and velocity limits of each joint are two parallel rows of level 0
STACK = """name = "arm_stack"
description = "7-joint arm: joint and velocity limits > tip position > tip orientation > posture"
robot = "{urdf}"
dt = 0.02

[[levels]]
name = "limits"
tasks = [{{ type = "joint_limits" }}, {{ type = "velocity_limits" }}]

[[levels]]
tasks = [{{ type = "position", frame = "ee", name = "tip_position", gain = 5.0 }}]

[[levels]]
tasks = [{{ type = "orientation", frame = "ee", name = "tip_orientation", gain = 5.0 }}]

[[levels]]
tasks = [{{ type = "posture", gain = 1.0 }}]
"""


@pytest.fixture(scope="module")
def arm_problems(tmp_path_factory):
    pytest.importorskip("pinocchio")
    folder = tmp_path_factory.mktemp("arm")
    urdf = write_robots(folder)["arm.urdf"]
    stack = folder / "arm_stack.toml"
    stack.write_text(STACK.format(urdf=urdf))
    return [generate("robot-stack", seed=s, stack=str(stack), robot=str(urdf)) for s in SEEDS]


@pytest.mark.parametrize("backend", ["daqp", "quadprog"])
def test_cascade_solves_the_arm_stack_at_default_settings(arm_problems, backend):
    for seed, h in zip(SEEDS, arm_problems):
        assert h.rows_per_level.tolist() == [14, 3, 3, 7]
        x_ref = registry.create("hcod").solve(h).x
        res = registry.create(f"cascade-{backend}").solve(h)
        assert res.status == OPTIMAL, (seed, res.reason)
        assert verify(h, res.x, x_ref, rtol=1e-6, atol=1e-7).equal, seed


def test_quadprog_with_shifted_frozen_rows_fails_where_relaxed_ones_succeed(arm_problems):
    # the failure the default freeze mode of the dual active-set backends avoids: a level whose
    # frozen rows leave a zero-width feasible set, more rows active than variables
    res = [registry.create("cascade-quadprog", freeze="shift").solve(h) for h in arm_problems]
    failed = [r for r in res if r.status != OPTIMAL]
    assert failed, "quadprog solved every arm problem with freeze=shift: the default needs a new reason"
    assert all(r.status == "infeasible_level" and "of a feasible QP" in r.reason for r in failed)
