"""Closed-loop scenarios: runner, CSV columns, checks, CLI, figures."""

import numpy as np
import pandas as pd
import pytest
from doubles import WarmReference, spec, still_run

from hikbench.bench.cli import main
from hikbench.bench.scenarios.checks import BLAME, check_run
from hikbench.bench.scenarios.runner import COLUMNS, NO_WARM_START, run_scenario
from hikbench.problems.robots.dimensions import robot_length
from hikbench.problems.robots.scenarios import ScenarioError, load_scenario, scenario_names


def test_shipped_scenarios():
    assert {"arm_reach", "reach", "step"} <= set(scenario_names())


def test_reach_runs_a_few_steps_with_the_yardstick():
    sc = load_scenario("reach")
    run = run_scenario(sc, "yardstick", steps=4)
    df = run.records
    assert list(df.columns[:len(COLUMNS)]) == list(COLUMNS)
    for task in ("com", "left_foot", "right_foot", "right_hand", "velocity"):
        assert f"err_{task}" in df
    assert (df["warm_start"] == NO_WARM_START).all() and (df["status"] == "optimal").all()
    assert run.q.shape == (5, sc.robot.nq)
    assert df["min_joint_limit_margin"].min() > 0
    # one recomputed level norm per level; joint limits hold exactly at every step
    assert [c for c in df if c.startswith("level_norm_")] == [
        f"level_norm_{n}" for n in ("joint_limits", "com", "feet", "right_hand", "velocity")]
    assert (df["level_norm_joint_limits"] < 1e-9).all()
    assert sc.event_times() == [3.0]
    # the hand error decreases from the first step
    assert df["err_right_hand"].iloc[-1] < df["err_right_hand"].iloc[0]


def test_step_targets_follow_the_schedule():
    """At t = 0 the swing foot target is its nominal placement; during the swing it lifts."""
    from hikbench.problems.robots.kinematics import KinematicState

    sc = load_scenario("step")
    sc.reset()
    state = KinematicState(sc.robot, sc.q_init)
    foot = sc.stack.task("right_foot")
    z0 = foot.target.translation[2]
    for t in np.arange(0.0, 2.11, sc.dt):  # targets are fixed at each segment's start, in order
        sc.targets_at(t, state)
    apex = 0.0616 * robot_length(sc.robot, "leg_length")  # (0.0616 leg lengths: 5 cm on talos)
    assert foot.target.translation[2] == pytest.approx(z0 + apex, abs=1e-9)  # apex at mid-swing
    assert foot.target_velocity is not None


def test_scenario_file_errors(tmp_path):
    bad = tmp_path / "s.toml"
    bad.write_text('name = "s"\nstack = "arm_reach"\n[[events]]\ntask = "gripper"\n')
    with pytest.raises(ScenarioError, match=r"events\[0\].task = 'gripper': expected a task of stack 'arm_reach'"):
        load_scenario(bad)
    with pytest.raises(ScenarioError, match="unknown scenario 'dance'"):
        load_scenario("dance")


def test_a_directory_named_like_a_shipped_scenario_does_not_hide_it(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "reach").mkdir()  # e.g. the output directory of an earlier `hikbench scenario reach`
    (tmp_path / "dance").mkdir()
    assert load_scenario("reach").name == "reach"
    with pytest.raises(ScenarioError, match="unknown scenario 'dance'"):
        load_scenario("dance")


def test_user_scenario_on_an_arm(tmp_path):
    """A user TOML: panda end effector moved by a polynomial; tracked within 5 mm."""
    f = tmp_path / "arm.toml"
    f.write_text('name = "arm"\nstack = "arm_reach"\nsteps = 30\n'
                 '[[trajectories]]\ntask = "ee"\nstart = 0.0\nduration = 0.5\noffset = [0.05, 0.0, -0.05]\n'
                 '[checks]\nlimits = true\ntracked = { ee = 5e-3 }\n')
    run = run_scenario(load_scenario(f), "yardstick")
    checks = check_run(run)
    assert checks and all(c.passed for c in checks), checks


def test_cli_writes_csv_and_figures(tmp_path, capsys):
    rc = main(["scenario", "step", "--steps", "3", "--out", str(tmp_path), "--plot"])
    out = capsys.readouterr().out
    assert "hcod (time): 3 steps" in out  # (the default solver)
    csv = tmp_path / "step_talos_hcod_time.csv"
    df = pd.read_csv(csv)
    assert len(df) == 3 and "err_right_foot" in df
    for fig in ("fig1_solve_time.png", "fig2_time_activations.png", "fig3_joints_hcod_time.png",
                "fig4_task_errors.png"):
        assert (tmp_path / fig).stat().st_size > 10_000
    assert rc == 0  # (3 steps: not judged on final errors; the checks of these steps hold)


def test_cli_list(capsys):
    assert main(["scenario", "x", "--list"]) == 0
    out = capsys.readouterr().out
    assert "reach" in out and "humanoid_reach" in out


def test_cli_unknown_robot(tmp_path, capsys):
    assert main(["scenario", "reach", "--robot", "r2d2", "--steps", "1", "--out", str(tmp_path)]) == 2
    assert "robot 'r2d2' is not in the installed example-robot-data" in capsys.readouterr().err


def test_cli_unknown_solver(tmp_path, capsys):
    assert main(["scenario", "reach", "--solver", "nope", "--steps", "1", "--out", str(tmp_path)]) == 2
    assert "unknown solver 'nope'" in capsys.readouterr().err


def _solver_params(names):
    """Every solver is a dependency of the project (a missing one fails its test at
    run_scenario, and test_registry's install check): none is skipped."""
    return [pytest.param(n, id=n) for n in names]


@pytest.mark.slow
@pytest.mark.parametrize("solver", _solver_params(["hcod", "cascade-daqp", "cascade-quadprog", "yardstick"]))
def test_reach_checks_pass(solver):
    """ICRA 2010 sec. XII: limits respected, CoM/feet regulated, reach error to its lowest value
    while out of reach, then to 0 (700 steps; ~1 s with a cascade, ~10 s with the yardstick)."""
    run = run_scenario(load_scenario("reach"), solver, repeat=1)  # (the checks, not the timing)
    checks = check_run(run)
    failed = [c for c in checks if not c.passed]
    assert not failed, failed


@pytest.mark.slow
@pytest.mark.parametrize("solver", _solver_params(["hcod", "cascade-daqp", "yardstick"]))
def test_step_checks_pass(solver):
    run = run_scenario(load_scenario("step"), solver, repeat=1)
    checks = check_run(run)
    assert all(c.passed for c in checks), [c for c in checks if not c.passed]


@pytest.mark.slow
@pytest.mark.parametrize("name, robot", [("reach", "talos"), ("reach", "romeo"), ("reach", "g1"), ("step", "talos"),
                                         ("step", "romeo"), ("step", "g1"), ("arm_reach", "panda")],
                         ids=lambda v: v)
def test_the_shipped_scenarios_hold_on_every_robot_with_hcod(name, robot):
    """Offsets in the robot's arm and leg lengths: the full schedules pass every check with
    hcod (time warm start) on three humanoids of 0.45 to 0.78 m arms and on an arm
    (700, 225 and 300 steps; ~10 s each)."""
    run = run_scenario(load_scenario(name, robot=robot), "hcod", repeat=1)
    checks = check_run(run)
    assert len(checks) >= 4 and all(c.passed for c in checks), [c for c in checks if not c.passed]


@pytest.mark.slow
def test_step_with_dls_liegeois_shows_its_posture_fighting_the_feet():
    """dls-liegeois stacks every level but its box at one weight: the step's posture task (32
    rows) pulls against the feet and the CoM, and the tracking checks fail. (Taking the posture
    task, unit equality rows, for its joint-limit box and dropping it from the task would make
    them pass; the real box, level 0, has two rows per joint, intersected.)"""
    run = run_scenario(load_scenario("step"), "dls-liegeois", repeat=1)
    checks = {c.name: c for c in check_run(run)}
    assert checks["run completed"].passed
    assert not checks["com_xy tracked"].passed and not checks["right_foot tracked"].passed
    reasons = run.records["reason"].dropna()
    assert reasons.str.contains("level 0 (box level)", regex=False).any(), reasons.head()  # the joint limits
    assert not reasons.str.contains("level 4 (box level)", regex=False).any()  # (not the posture)


@pytest.fixture
def warm_solver(monkeypatch):
    from hikbench.solvers import registry
    from hikbench.solvers.registry import SolverInfo

    reg = dict(registry._load())
    reg["fake-warm"] = SolverInfo("fake-warm", "test double", WarmReference, supports_inequalities=True,
                                  supports_warm_start=True, options={"warm_start": "time"})
    monkeypatch.setattr(registry, "_registry", reg)
    return "fake-warm"


def test_warm_start_modes_reach_the_solver(warm_solver, tmp_path, capsys):
    sc = load_scenario("reach")
    assert (run_scenario(sc, warm_solver, steps=2).records["warm_start"] == "time").all()
    run = run_scenario(sc, warm_solver, warm_start="none", steps=2)
    assert (run.records["warm_start"] == "none").all() and (run.records["activations"] == 1).all()
    rc = main(["scenario", "reach", "--solver", warm_solver, "--warm-start", "none", "stage", "time",
               "--steps", "2", "--out", str(tmp_path), "--plot"])
    assert rc == 0
    for mode in ("none", "stage", "time"):
        df = pd.read_csv(tmp_path / f"reach_talos_fake-warm_{mode}.csv")
        assert (df["warm_start"] == mode).all()
    assert (tmp_path / "fig1_solve_time.png").exists()


@pytest.mark.parametrize("last_status, passed, final", [
    ("optimal", None, "final 1.00e-03 not judged: the run was cut to 5 of the scenario's 700 steps (--steps)"),
    ("diverged", False, "final 1.00e-03 (tol 1e-05)"),
], ids=["cut-by-steps", "stopped-by-a-failure"])
def test_a_run_cut_by_steps_is_not_judged_on_final_errors(last_status, passed, final):
    # 5 steps cannot bring a regulated error to 1e-5: a run the user shortened says so and leaves
    # the check unjudged (neither pass nor FAIL); a run that stopped on a failure is judged in full (and fails)
    sc = load_scenario("reach")
    assert sc.steps == 700 and sc.checks["regulated"] == ["com", "left_foot", "right_foot"]
    checks = {c.name: c for c in check_run(still_run(sc, 5, ["optimal"] * 4 + [last_status]))}
    for task in ("com", "left_foot", "right_foot"):
        c = checks[f"{task} regulated"]
        assert c.passed is passed, c
        assert c.verdict == {None: "not judged", False: "FAIL"}[passed]
        assert f"max 1.00e-03 at step 0 (tol e0 + 0.002), {final}; decay per step" in c.detail, c.detail
    assert checks["run completed"].passed is (passed is None)
    assert "back in reach: converges to 0" not in checks
    # an error of 1e-3 from the first step: the target was within reach, whatever the steps run
    # (the scenario's assumption, not the solver, failed), and the solver is not judged on reaching
    # the lowest value of an unreachable target
    unreachable = checks["out of reach: target unreachable"]
    assert not unreachable.passed and unreachable.judges == "scenario", unreachable
    assert unreachable.detail == ("lowest error 1.000e-03 (expected > 0.01): the target is within this robot's reach; "
                                  f"give the scenario a longer offset (e.g. in arm lengths) -> {BLAME['scenario']}")
    lowest = checks["out of reach: lowest value"]
    assert lowest.passed is None and lowest.detail.endswith(
        "not judged: the target is within reach (out of reach: target unreachable)"), lowest


def test_an_unreachable_target_on_a_cut_run_is_not_judged_on_its_end():
    """The out-of-reach phase (until t = 3 s) did not end in 5 steps: its last value is no
    "lowest value"; a run that covers the phase is judged on it."""
    sc = load_scenario("reach")
    lowest = {c.name: c for c in check_run(still_run(sc, 5, err=0.5))}["out of reach: lowest value"]
    assert lowest.passed is None and lowest.detail.endswith(
        "; not judged: the run was cut to 5 of the scenario's 700 steps (--steps)"), lowest
    checks = {c.name: c for c in check_run(still_run(sc, 310, err=0.5))}  # (past 3 s: the phase ended)
    assert checks["out of reach: target unreachable"].passed
    lowest = checks["out of reach: lowest value"]  # (a constant error never came down)
    assert lowest.passed is False and lowest.detail.endswith(f" -> {BLAME['solver']}"), lowest
    assert checks["back in reach: converges to 0"].passed is None


def test_no_check_line_contradicts_itself(capsys):
    """A passing line says no "not judged" and no nan; "run completed" says the statuses are
    recorded, not judged, and counts them by status."""
    sc = load_scenario("reach")
    status = ["optimal", "infeasible_level", "optimal", "max_iterations"] + ["optimal"] * 56
    checks = check_run(still_run(sc, 60, status, err=0.0))  # (every error 0 from the first step)
    for c in checks:
        assert "nan" not in c.detail, c
        assert c.passed is not True or "not judged:" not in c.detail, c
    by_name = {c.name: c for c in checks}
    assert "decay per step not measured (e0 0.0e+00: at most 1e-9, nothing to decay)" in by_name["com regulated"].detail
    done = by_name["run completed"]
    assert done.passed and done.detail == (
        "60 steps; the solver's statuses, recorded (the checks judge the task errors, not the statuses): 58 optimal, "
        "1 infeasible_level, 1 max_iterations (first not optimal: step 1, infeasible_level)"), done
    assert check_run(still_run(sc, 3))[0].detail == "3 steps; every status optimal"


def test_a_check_not_judged_is_counted_apart():
    from hikbench.bench.scenarios.rows import check_counts

    assert check_counts([("a", True), ("b", None), ("c", False), ("d", None)]) == {
        "checks_passed": 1, "checks_failed": 1, "checks_not_judged": 2, "failed_checks": "c"}


def test_a_failed_check_names_what_failed():
    """A check that fails ends its detail with the solver or the scenario's assumption;
    one that passes keeps its detail as given."""
    from hikbench.bench.scenarios.checks import Check

    assert Check("x", False, "d").detail == "d -> the solver failed"
    assert Check("x", False, "d", judges="scenario").detail == (
        "d -> the scenario's assumption failed on this robot, not the solver")
    assert Check("x", True, "d", judges="scenario").detail == "d"
    with pytest.raises(ValueError, match="judges must be one of solver, scenario; got 'user'"):
        Check("x", False, "d", judges="user")


def test_without_solver_a_scenario_runs_hcod(tmp_path, capsys):
    """The default is the strict hierarchy solver a controller runs (time warm start), not the
    yardstick (23 ms a step of g1's step scenario)."""
    rc = main(["scenario", "reach", "--steps", "2", "--repeat", "1", "--out", str(tmp_path)])
    out = capsys.readouterr().out
    assert rc == 0 and "\nhcod (time): 2 steps" in out, out
    assert [p.name for p in tmp_path.glob("*.csv") if p.name != "summary.csv"] == ["reach_talos_hcod_time.csv"]


def test_a_solver_given_as_file_and_class(tmp_path, capsys):
    """`scenario --solver file.py:Class` runs like `solve` and `run` take it; a factory with a
    warm_start parameter gets the modes, its default labels the run without --warm-start."""
    rc = main(["scenario", "reach", "--solver", spec("WarmReference"), "--solver", "hikbench.solvers.yardstick:YardstickSolver",
               "--steps", "2", "--out", str(tmp_path)])
    out = capsys.readouterr().out
    assert rc == 0, out
    assert f"{spec('WarmReference')} (time): 2 steps" in out and "hikbench.solvers.yardstick:YardstickSolver: 2 steps" in out
    csvs = sorted(p.name for p in tmp_path.glob("*.csv") if p.name != "summary.csv")  # (one per run)
    assert len(csvs) == 2 and any(c.endswith("doubles.py_WarmReference_time.csv") for c in csvs), csvs
    run = run_scenario(load_scenario("reach"), spec("WarmReference"), warm_start="none", steps=2)
    assert (run.records["warm_start"] == "none").all() and (run.records["activations"] == 1).all()


def test_warm_start_modes_are_the_solvers_own(tmp_path, capsys):
    """--warm-start takes the values of the solver's warm_start parameter, not only hcod's;
    a mode that a solver refuses fails before any run, naming the value."""
    rc = main(["scenario", "reach", "--solver", spec("WarmOnOff"), "--warm-start", "on", "off",
               "--steps", "2", "--out", str(tmp_path)])
    assert rc == 0, capsys.readouterr()
    for mode in ("on", "off"):
        assert (pd.read_csv(next(tmp_path.glob(f"*WarmOnOff_{mode}.csv")))["warm_start"] == mode).all()
    capsys.readouterr()
    out = tmp_path / "bad"
    rc = main(["scenario", "reach", "--solver", "yardstick", "--solver", "hcod", "--warm-start", "time", "tme",
               "--steps", "2", "--out", str(out)])
    _, err = capsys.readouterr()
    assert rc == 2 and "'tme'" in err and "warm_start" in err, err
    assert not list(out.glob("*.csv"))  # the yardstick ran no step first


def test_a_solver_that_raises_costs_its_run_not_the_command(tmp_path, capsys):
    """The exception is the step's status and reason, the run stops there and fails its check."""
    rc = main(["scenario", "reach", "--solver", spec("RaisingSolver"), "--solver", "yardstick",
               "--steps", "2", "--out", str(tmp_path)])
    out = capsys.readouterr().out
    assert rc == 1
    assert "[FAIL] run completed" in out and "yardstick: 2 steps" in out
    df = pd.read_csv(next(tmp_path.glob("*RaisingSolver.csv")))
    assert len(df) == 1
    assert df.loc[0, "status"] == "error" and df.loc[0, "reason"] == "RuntimeError: backend exploded"


def test_a_required_warm_start_parameter_is_named(tmp_path, capsys):
    assert main(["scenario", "reach", "--solver", spec("WarmRequired"), "--steps", "1",
                 "--out", str(tmp_path)]) == 2
    assert "its warm_start parameter has no default value" in capsys.readouterr().err


def test_a_plotted_joint_that_the_robot_lacks_is_named(tmp_path):
    """A typo in `[plot] joints` silently fell back to the 12 joints that move most."""
    f = tmp_path / "arm.toml"
    f.write_text('name = "arm"\nstack = "arm_reach"\nrobot = "ur5"\nsteps = 3\n'
                 '[plot]\njoints = ["shoulder_pan_joint", "shoulder_pan_jont"]\n')
    with pytest.raises(ScenarioError, match=r"plot.joints\[1\] = 'shoulder_pan_jont': expected a bounded 1-DOF "
                                            r"joint of ur5 \(shoulder_pan_joint, .*\) \(did you mean "
                                            r"'shoulder_pan_joint'"):
        load_scenario(f)
    # on another robot (--robot), the shipped scenarios' joints may be missing: the figure falls back
    assert load_scenario("reach", robot="g1").plot_joints


def test_velocity_limits_are_checked_with_the_joint_limits():
    """`limits = true` also judges the stack's velocity limits on the u each step commanded:
    a run within them passes, a step past them by more than VELOCITY_TOL fails the check and
    names the step (a solver that ignores a two-sided velocity row must not pass)."""
    from hikbench.bench.scenarios.checks import VELOCITY_TOL

    run = run_scenario(load_scenario("reach"), "hcod", steps=3, repeat=1)
    held = {c.name: c for c in check_run(run)}["velocity_limits held"]
    assert held.passed, held
    run.records.loc[1, "err_velocity_limits"] = 100 * VELOCITY_TOL
    held = {c.name: c for c in check_run(run)}["velocity_limits held"]
    assert not held.passed and held.judges == "solver"
    assert held.detail.startswith("max total excess 1.000e-04 rad/s at step 1 (tol 1e-06)"), held.detail


def test_scenario_certify_certifies_each_steps_x(tmp_path, capsys):
    """--certify: every step's x certified exactly after the run (worker processes), three columns
    in the per-step CSV; hcod's x attains the exact optimum on the first steps of reach."""
    code = main(["scenario", "reach", "--solver", "hcod", "--steps", "2", "--repeat", "1", "--certify", "1",
                 "--out", str(tmp_path)])
    out = capsys.readouterr().out
    assert code == 0 and "exact certificate: 2 of 2 steps certified, x attains the exact optimum on 2" in out, out
    df = pd.read_csv(next(tmp_path.glob("reach_*_hcod_*.csv")))
    assert df["certified"].tolist() == [True, True] and df["x_attains"].tolist() == [True, True]
    assert df["certify_reason"].isna().all()


def test_scenario_certify_needs_a_worker(capsys):
    assert main(["scenario", "reach", "--steps", "1", "--certify", "0"]) == 2
    assert "--certify must be >= 1 worker process; got 0" in capsys.readouterr().err
