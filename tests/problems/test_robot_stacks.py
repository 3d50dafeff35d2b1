"""Stacks from TOML -> hierarchies; one-shot test sets saved as npz."""

import numpy as np
import pytest

from hikbench.problems.files import load_npz
from hikbench.problems.robots.stacks import StackError, StackSpec, build_stack, load_stack_spec, make_task, stack_names
from hikbench.problems.robots.testsets import save_test_set, stack_problem
from hikbench.solvers.yardstick import yardstick_solution
from hikbench.problems.verify import level_norms


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
    x = yardstick_solution(h)
    assert np.all(level_norms(h, x)[:1] <= 1e-8)  # joint limits respected


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


def _stack_file(tmp_path, tasks: str, extra: str = "") -> object:
    f = tmp_path / "s.toml"
    f.write_text(f'name = "s"\nrobot = "panda"\n{extra}[[levels]]\ntasks = [{{ type = "joint_limits" }}]\n'
                 f'[[levels]]\ntasks = [{tasks}]\n')
    return f


@pytest.mark.parametrize("tasks, extra, match", [
    ('{ type = "position", frame = "ee", gain = "5" }', "",
     r"level 1, task 0 \(type 'position'\): task 'ee': gain must be a finite number >= 0; got '5'"),
    ('{ type = "orientation", frame = "ee", target = [1, 0, 0] }', "",
     r"level 1, task 0 \(type 'orientation'\): task 'ee' target \(a 3x3 rotation matrix"),
    ('{ type = "orientation", frame = "ee", target = [[1, 0, 0], [0, 1, 0], [0, 0, 2]] }', "",
     "must be a rotation matrix"),
    ('{ type = "pose", frame = "ee", target = [0.4, 0.1, 0.3] }', "", r"target must be a table \{ position"),
    ('{ type = "pose", frame = "ee", target = { position = [0.4, 0.1], rpy = [0, 0, 0] } }', "",
     "target position must be 3 finite numbers"),
    ('{ type = "pose", frame = "ee", target = { position = [0.4, 0.1, 0.3], rpy = [0, 0] } }', "",
     "target rpy must be 3 finite numbers"),
    ('{ type = "velocity_limits", scale = "1" }', "", "scale must be a finite number > 0; got '1'"),
    ('{ type = "positon", frame = "ee" }', "", r"level 1, task 0 \(type 'positon'\): unknown task type"),
    ('{ type = "com" }', 'dt = "fast"\n', "dt = 'fast': expected a finite number > 0 and <= 1"),
], ids=["gain-string", "orientation-3-numbers", "orientation-not-a-rotation", "pose-list", "pose-position-2",
        "pose-rpy-2", "scale-string", "type-typo", "dt-string"])
def test_bad_values_in_a_stack_file_are_one_line_errors_naming_file_level_and_task(tmp_path, tasks, extra, match):
    """Each was a ValueError / TypeError / Boost.Python traceback, or named neither file nor level."""
    f = _stack_file(tmp_path, tasks, extra)
    with pytest.raises(StackError, match=match) as err:
        build_stack(f)
    assert str(f) in str(err.value)


def test_level_keys_and_an_empty_stack_are_checked(tmp_path):
    f = tmp_path / "s.toml"
    f.write_text('name = "s"\nrobot = "panda"\n[[levels]]\npriority = 2\ntasks = [{ type = "com" }]\n')
    with pytest.raises(StackError, match=r"unknown key levels\[0\].priority; expected some of: tasks, name"):
        build_stack(f)
    f.write_text('name = "s"\nrobot = "panda"\nlevels = []\n')
    with pytest.raises(StackError, match=r"levels = \[\]: expected a non-empty list of \[\[levels\]\] tables"):
        build_stack(f)


def test_targets_given_in_the_file_are_kept(tmp_path, panda):
    """A `target` in the stack file was replaced by the value at q0 (the robot never moved); it is
    kept, also by set_targets_from (stack_problem's random targets move the others only)."""
    import pinocchio as pin

    from hikbench.problems.robots.kinematics import KinematicState

    f = _stack_file(tmp_path, '{ type = "position", frame = "ee", target = [0.3, 0.3, 0.3] }, '
                              '{ type = "orientation", name = "ee_rot", frame = "ee", target = { rpy = [3.0, 0.1, 0.2] } },'
                              '{ type = "com" }')
    stack = build_stack(f)
    assert stack.given_targets == {"ee", "ee_rot"}
    ee, rot, com = (stack.task(n) for n in ("ee", "ee_rot", "com"))
    np.testing.assert_array_equal(ee.target, [0.3, 0.3, 0.3])
    np.testing.assert_allclose(rot.target, pin.rpy.rpyToMatrix(3.0, 0.1, 0.2), rtol=0, atol=1e-15)
    np.testing.assert_allclose(com.target, KinematicState(panda, panda.q0).com, rtol=0, atol=1e-15)
    stack.set_targets_from(panda.random_configuration(np.random.default_rng(0)))
    np.testing.assert_array_equal(ee.target, [0.3, 0.3, 0.3])
    assert np.linalg.norm(com.target - KinematicState(panda, panda.q0).com) > 1e-3
    # the rows drive the end effector towards the given point: J u = -gain (p - p*)
    h = stack.hierarchy(panda.q0)
    p0 = KinematicState(panda, panda.q0).position(ee.frame_id)
    np.testing.assert_allclose(h.lower[h.level_rows(1)][:3], -(p0 - [0.3, 0.3, 0.3]), rtol=1e-14)


def test_robot_family_for_the_harness():
    from hikbench.problems.robots.testsets import ROBOT_FAMILIES, SHIPPED_STACKS

    assert list(SHIPPED_STACKS) == stack_names()
    fam = ROBOT_FAMILIES["robot-stack"]
    assert fam.generate(seed=2, stack="arm_reach") == stack_problem("arm_reach", 2)
    assert fam.generate(seed=0).n == 38  # talos, the paper's stack


def test_an_unknown_frame_suggests_the_closest_names(panda):
    from hikbench.problems.robots.models import FrameNotFoundError, load_robot

    with pytest.raises(FrameNotFoundError, match="did you mean 'tool0'"):
        load_robot("ur5").frame_name("tool_0")
    with pytest.raises(FrameNotFoundError, match="frame names: universe, "):
        load_robot("ur5").frame_name("zzz")  # (22 frames: all listed)


def test_errors_of_the_velocity_are_measured_at_u_and_none_without_it():
    """``stack.errors(q)`` gives the tasks of q their error and the tasks of the velocity None
    (not nan); with u, velocity_limits is the total excess of |u_i| over the URDF limits."""
    stack = build_stack("arm_reach")
    q = stack.robot.q0
    at_q = stack.errors(q)
    assert at_q["velocity_limits"] is None
    assert all(isinstance(at_q[t], float) and np.isfinite(at_q[t]) for t in ("joint_limits", "ee", "posture"))
    u = np.linspace(-4.0, 4.0, stack.robot.nv)
    vmax = np.asarray(stack.robot.model.velocityLimit)  # (panda: 2.175, 2.61 rad/s, fingers 0.2 m/s)
    expected = float(np.sum(np.maximum(np.abs(u) - vmax, 0.0)))
    assert expected > 0
    np.testing.assert_allclose(stack.errors(q, u)["velocity_limits"], expected, rtol=1e-12, atol=0)
    assert stack.errors(q, np.zeros(stack.robot.nv))["velocity_limits"] == 0.0
