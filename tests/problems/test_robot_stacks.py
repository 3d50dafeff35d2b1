"""Stacks from TOML -> hierarchies; one-shot test sets saved as npz."""

import numpy as np
import pytest

from problems.files import load_npz
from problems.robots.stacks import StackError, StackSpec, build_stack, load_stack_spec, make_task, stack_names
from problems.robots.testsets import save_test_set, stack_problem
from solvers.reference import reference_solution


@pytest.mark.parametrize("name", stack_names())
def test_shipped_stack_builds_a_hierarchy_in_u(name):
    stack = build_stack(name)
    h = stack.hierarchy(stack.robot.q0)
    assert h.n == stack.robot.nv
    assert h.names == tuple(stack.level_names)
    # at q0 every target is met (alignment has a fixed world reference instead)
    for task, err in stack.errors(stack.robot.q0, u=np.zeros(h.n)).items():
        if not task.startswith("torso_upright"):
            assert err <= 1e-12, task


def test_paper_stack_shape(talos):
    """ICRA 2010 sec. XII: limits (32 + velocity) > CoM 3 > feet 6 + 6 > hand 6 > velocity 32."""
    h = build_stack("humanoid_reach").hierarchy(talos.q0)
    assert h.names == ("joint_limits", "com", "feet", "right_hand", "velocity")
    assert list(h.rows_per_level) == [64, 3, 12, 6, 32]
    assert not h.is_equality[h.level_rows(0)].any()


def test_stack_problem_is_seeded_and_reachable(talos):
    h1, h2 = stack_problem("humanoid_reach", seed=3), stack_problem("humanoid_reach", seed=3)
    assert h1 == h2
    assert h1 != stack_problem("humanoid_reach", seed=4)
    # the current configuration is within its limits: the joint-limit box contains u = 0
    s = h1.level_rows(0)
    assert np.all(h1.lower[s] < 0) and np.all(h1.upper[s] > 0)


def test_stack_problem_on_another_robot():
    h = stack_problem("arm_reach", seed=0, robot="ur5")
    assert h.n == 6


def test_saved_test_set_round_trips_and_solves(tmp_path):
    paths = save_test_set(tmp_path, stacks=["arm_reach"], seeds=[0, 1])
    assert [p.name for p in paths] == ["arm_reach-seed0.npz", "arm_reach-seed1.npz"]
    h = load_npz(paths[0])
    assert h == stack_problem("arm_reach", 0)
    x = reference_solution(h)
    assert np.all(h.level_norms(x)[:1] <= 1e-8)  # joint limits respected


def test_toml_errors_name_the_problem(tmp_path, panda):
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "x"\nrobot = "panda"\n[[levels]]\ntasks = [{ type = "teleport" }]\n')
    with pytest.raises(StackError, match="unknown task type 'teleport'"):
        build_stack(bad)
    with pytest.raises(StackError, match=r"unknown key\(s\) \['colour'\]"):
        make_task(panda, {"type": "com", "colour": "red"})
    with pytest.raises(StackError, match="missing key 'robot'"):
        StackSpec.from_dict({"name": "x", "levels": []})
    with pytest.raises(StackError, match="unknown stack 'nope'"):
        load_stack_spec("nope")


def test_robot_family_for_the_harness():
    from problems.robots.testsets import ROBOT_FAMILIES, SHIPPED_STACKS

    assert list(SHIPPED_STACKS) == stack_names()
    fam = ROBOT_FAMILIES["robot-stack"]
    assert fam.generate(seed=2, stack="arm_reach") == stack_problem("arm_reach", 2)
    assert fam.generate(seed=0).n == 38  # talos, the paper's stack
