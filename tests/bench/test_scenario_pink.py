"""The scenario controller pink (bench/scenarios/pink_ik.py): the stack's levels as pin-pink
tasks (costs per level, gains, limits), their rows against the stack's, unsupported tasks, the
closed loop and the CLI."""

import numpy as np
import pandas as pd
import pinocchio as pin
import pytest

from hikbench.bench.cli import main
from hikbench.bench.scenarios.controllers import ControllerError, build_controller
from hikbench.bench.scenarios.pink_ik import LEVEL_FACTOR, PinkController, level_costs
from hikbench.bench.scenarios.checks import check_run
from hikbench.bench.scenarios.runner import NO_WARM_START, run_scenario
from hikbench.problems.robots.kinematics import KinematicState
from hikbench.problems.robots.scenarios import load_scenario
from hikbench.problems.robots.stacks import Stack, StackSpec, build_stack
from hikbench.solvers.errors import SolverOptionError

#: a talos stack with every task type pink takes (position and orientation: FrameTask with one cost 0)
FRAME_TASKS = {"name": "frame_tasks", "robot": "talos", "dt": 0.01, "levels": [
    {"name": "limits", "tasks": [{"type": "joint_limits"}, {"type": "velocity_limits", "scale": 0.5}]},
    {"tasks": [{"type": "com", "axes": "xy", "gain": 4.0}]},
    {"tasks": [{"type": "pose", "frame": "left_foot", "gain": 5.0},
               {"type": "orientation", "name": "torso_orientation", "frame": "torso", "gain": 3.0}]},
    {"tasks": [{"type": "position", "frame": "right_hand", "gain": 2.0}]},
    {"tasks": [{"type": "posture", "gain": 1.0}]},
    {"tasks": [{"type": "velocity"}]}]}


def _moved(stack: Stack, seed: int = 0) -> np.ndarray:
    """A configuration away from every target (q0 (+) a seeded perturbation of the joints)."""
    rng = np.random.default_rng(seed)
    v = np.zeros(stack.robot.nv)
    v[stack.robot.actuated] = rng.normal(scale=0.05, size=int(stack.robot.actuated.sum()))
    return pin.integrate(stack.robot.model, stack.robot.q0, v)


@pytest.fixture(scope="module")
def frame_stack():
    return Stack(StackSpec.from_dict(FRAME_TASKS))


@pytest.mark.parametrize("factor, costs", [(10.0, [None, 1.0, 0.1, 0.01, 1e-3, 1e-4]),
                                           (3.0, [None, 1.0, 1 / 3, 1 / 9, 1 / 27, 1 / 81]),
                                           (1.0, [None, 1.0, 1.0, 1.0, 1.0, 1.0])],
                         ids=["factor-10", "factor-3", "factor-1"])
def test_each_level_weighs_level_factor_times_the_next(frame_stack, factor, costs):
    """Levels of limits only get no cost (they are constraints); the first weighted level costs 1."""
    got = level_costs(frame_stack, factor)
    assert got[0] is None
    np.testing.assert_allclose(got[1:], costs[1:], rtol=1e-15)
    ctl = PinkController(frame_stack, level_factor=factor)
    com, foot, torso, hand, posture, damping = ctl.pink_tasks
    np.testing.assert_allclose(com.cost, [costs[1], costs[1], 0.0], rtol=1e-15)  # axes "xy": z not weighted
    np.testing.assert_allclose(foot.cost, np.full(6, costs[2]), rtol=1e-15)
    np.testing.assert_allclose(torso.cost, [0, 0, 0, costs[2], costs[2], costs[2]], rtol=1e-15)
    np.testing.assert_allclose(hand.cost, [costs[3]] * 3 + [0, 0, 0], rtol=1e-15)
    assert posture.cost == pytest.approx(costs[4], rel=1e-15)
    assert damping.cost == pytest.approx(costs[5], rel=1e-15)


def test_the_default_level_factor_is_ten():
    """(the reach sweep of docs/robots.md: 10 is where every reach check passes with daqp)"""
    assert LEVEL_FACTOR == 10.0


def test_gains_are_lambda_dt_and_limits_are_the_stacks(frame_stack):
    ctl = PinkController(frame_stack)
    dt = frame_stack.dt
    for task, pt in ctl.pairs:
        assert pt.gain == pytest.approx(task.gain * dt, rel=1e-15), task.name
    conf_limit, vel_limit = ctl.limits
    assert conf_limit.config_limit_gain == 1.0  # lambda = 1/dt of eq. (48)
    ctl.prepare(frame_stack.robot.q0)
    vl = frame_stack.levels[0][1]
    G, h = vel_limit.compute_qp_inequalities(ctl.configuration, dt)
    np.testing.assert_allclose(h, dt * np.concatenate([vl.vmax, vl.vmax]), rtol=1e-15)
    np.testing.assert_array_equal(vel_limit.indices, np.flatnonzero(vl.select))


@pytest.mark.parametrize("seed", [0, 1, 2], ids=["q-0", "q-1", "q-2"])
def test_pink_rows_are_the_stacks_rows_times_minus_dt(frame_stack, seed):
    """J_pink dq + alpha e_pink = -dt (J u - b) (pose, orientation; +dt for com and posture, whose
    errors have our sign) at dq = u dt, for a random u: pink weights the stack's own rows."""
    q = _moved(frame_stack, seed)
    state = KinematicState(frame_stack.robot, q)
    ctl = PinkController(frame_stack)
    ctl.prepare(q)
    u = np.random.default_rng(seed).normal(size=frame_stack.robot.nv)
    dt = frame_stack.dt
    for task, pt in ctl.pairs:
        J, b, _ = task.rows(state, dt)
        ours = dt * (J @ u - b)
        pink = pt.compute_jacobian(ctl.configuration) @ (u * dt) + pt.gain * pt.compute_error(ctl.configuration)
        if task.name == "com":
            pink = pink[task.axes]
        elif task.name == "torso_orientation":
            pink = pink[3:]  # (its position rows cost 0)
        elif task.name == "right_hand":
            continue  # below
        sign = -1.0 if task.name in ("left_foot", "torso_orientation") else 1.0
        np.testing.assert_allclose(pink, sign * ours, rtol=0, atol=1e-12 * (1 + np.abs(ours).max()),
                                   err_msg=task.name)


def test_position_rows_differ_by_the_log6_coupling_only(frame_stack):
    """The position task (FrameTask, orientation cost 0): the same error norm; its rows, in
    the frame's axes, are ours up to a term of order ||e|| ||J_angular||."""
    q = _moved(frame_stack, 3)
    state = KinematicState(frame_stack.robot, q)
    ctl = PinkController(frame_stack)
    ctl.prepare(q)
    task, pt = next((t, p) for t, p in ctl.pairs if t.name == "right_hand")
    e = task.value(state)
    e_pink = pt.compute_error(ctl.configuration)[:3]
    assert np.linalg.norm(e_pink) == pytest.approx(np.linalg.norm(e), rel=1e-12)
    R = state.placement(task.frame_id).rotation
    np.testing.assert_allclose(e_pink, -R.T @ e, rtol=0, atol=1e-12)
    J_pink = pt.compute_jacobian(ctl.configuration)[:3]
    J_ang = state.jacobian(task.frame_id, pin.LOCAL)[3:]
    gap = np.abs(J_pink + R.T @ task.jacobian(state)).max()
    assert gap <= np.linalg.norm(e) * np.abs(J_ang).max()


@pytest.mark.parametrize("stack, task, kind", [("humanoid_tasks", "distance_right_hand_left_hand", "distance")],
                         ids=["distance"])
def test_a_task_pink_has_no_counterpart_for_is_named(stack, task, kind):
    with pytest.raises(ControllerError) as err:
        PinkController(build_stack(stack))
    msg = str(err.value)
    assert f"task {task!r} of type {kind!r} has no counterpart in pink" in msg and "\n" not in msg


@pytest.mark.parametrize("level", [{"type": "direction", "name": "gaze", "frame": "head"},
                                   {"type": "alignment", "name": "upright", "frame": "torso"},
                                   {"type": "position", "name": "hand_z", "frame": "right_hand", "axes": "z"},
                                   {"type": "posture", "joints": "all"}],
                         ids=["direction", "alignment", "position-axes", "posture-all"])
def test_tasks_without_a_pink_counterpart(level):
    spec = StackSpec.from_dict({"name": "s", "robot": "talos", "levels": [{"tasks": [level]}]})
    with pytest.raises(ControllerError, match=r"^pink: .*task '\w+'") as err:
        PinkController(Stack(spec))
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("options, match", [({"level_factor": 0.5}, "level_factor=0.5"),
                                            ({"qp_solver": "nope"}, "qp_solver='nope'"),
                                            ({"damping": -1.0}, "damping=-1.0")],
                         ids=["factor-below-1", "unknown-qp-solver", "negative-damping"])
def test_bad_options(frame_stack, options, match):
    with pytest.raises(SolverOptionError, match=match):
        build_controller("pink", frame_stack, **options)


def test_an_unknown_option_is_named(frame_stack):
    with pytest.raises(ControllerError, match="unknown option.*'gain'.*allowed options: level_factor, qp_solver"):
        build_controller("pink", frame_stack, gain=1.0)


def test_pink_runs_a_few_steps_of_reach_on_talos():
    sc = load_scenario("reach")
    run = run_scenario(sc, "pink", steps=5, repeat=2)
    df = run.records
    assert run.warm_start == NO_WARM_START and run.label == "pink"
    assert (df["status"] == "optimal").all() and df["repeats_agree"].all()
    assert (df["iterations"] == 0).all()
    assert [c for c in df if c.startswith("level_norm_")] == [
        f"level_norm_{n}" for n in ("joint_limits", "com", "feet", "right_hand", "velocity")]
    assert (df["level_norm_joint_limits"] <= 1e-6).all()  # (daqp's tolerance on dq, docs/robots.md)
    assert df["err_right_hand"].iloc[-1] < df["err_right_hand"].iloc[0]
    assert (df["solve_time_min_s"] > 0).all()
    assert run.q.shape == (6, sc.robot.nq)


@pytest.mark.slow
def test_pink_passes_the_reach_checks_on_talos():
    """With level_factor 10 the weights hold the CoM and the feet while the hand reaches."""
    run = run_scenario(load_scenario("reach"), "pink", repeat=1)
    checks = check_run(run)
    assert checks and all(c.passed for c in checks), [c for c in checks if not c.passed]


def test_cli_pink_beside_a_solver(tmp_path, capsys):
    rc = main(["scenario", "reach", "--solver", "yardstick", "--solver", "pink", "--steps", "3", "--repeat", "1",
               "--option", "pink.level_factor=3", "--out", str(tmp_path)])
    out = capsys.readouterr().out
    assert rc == 0, out
    assert "pink: 3 steps" in out and "L3 right_hand" in out and "checks passed" in out
    df = pd.read_csv(tmp_path / "reach_talos_pink.csv", keep_default_na=False)
    assert len(df) == 3 and (df["warm_start"] == "n/a").all()
    summary = pd.read_csv(tmp_path / "summary.csv")
    assert list(summary["solver"]) == ["yardstick", "pink"]
    assert list(summary["strict"]) == [True, False]
    assert {"final_err_L3_right_hand", "max_err_L1_com", "time_median_s", "checks_failed", "failed_checks"} <= set(summary)
    pink = summary.set_index("solver").loc["pink"]  # (the columns of a suite's scenarios.csv, computed alike)
    np.testing.assert_allclose(pink[["time_median_s", "time_max_s", "iterations_mean"]].to_numpy(float),
                               [np.median(df["solve_time_min_s"]), df["solve_time_min_s"].max(),
                                df["iterations"].mean()], rtol=1e-12)
    # claims (d)-(e) given the directory read the per-step CSVs, not summary.csv
    from hikbench.bench.analysis.claims import find_scenario_csvs

    assert sorted(p.name for p in find_scenario_csvs(None, tmp_path)) == ["reach_talos_pink.csv",
                                                                          "reach_talos_yardstick.csv"]


def test_cli_a_scoped_option_reaches_its_solver_only(tmp_path, capsys):
    """pink.level_factor=0.5 is pink's (refused there), not the yardstick's."""
    rc = main(["scenario", "reach", "--solver", "yardstick", "--solver", "pink", "--steps", "1",
               "--option", "pink.level_factor=0.5", "--out", str(tmp_path)])
    err = capsys.readouterr().err
    assert rc == 2 and "pink: option level_factor=0.5 is not allowed" in err and len(err.strip().splitlines()) == 1


def test_cli_an_option_for_a_solver_not_given(tmp_path, capsys):
    rc = main(["scenario", "reach", "--solver", "pink", "--steps", "1", "--option", "hcod.warm_start=time",
               "--out", str(tmp_path)])
    assert rc == 2 and "'hcod' is not one of the --solver names (pink)" in capsys.readouterr().err


def test_cli_unsupported_task_is_one_line(tmp_path, capsys):
    f = tmp_path / "tasks.toml"
    f.write_text('name = "tasks"\nstack = "humanoid_tasks"\nsteps = 2\n')
    rc = main(["scenario", str(f), "--solver", "pink", "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert rc == 2 and "of type 'distance' has no counterpart in pink" in err and len(err.strip().splitlines()) == 1


def test_cli_list_shows_the_controllers(capsys):
    assert main(["scenario", "--list"]) == 0
    assert "controllers (--solver): pink" in capsys.readouterr().out


def test_pink_has_its_own_colour_dashed():
    """Not a registry solver: the colour after every solver's (the report's colours stay), dashed."""
    from doubles import still_run

    from hikbench.bench.scenarios.plots import run_styles

    sc = load_scenario("reach")
    runs = [still_run(sc, 2), still_run(sc, 2)]
    runs[1].solver, runs[1].warm_start = "pink", "n/a"
    styles = run_styles(runs)
    assert styles["pink"]["linestyle"] == "--"
    assert styles["pink"]["color"] != styles["hcod (time)"]["color"]
