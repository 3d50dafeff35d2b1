"""A robot's own lengths (problems/robots/dimensions.py) and scenario offsets given in
them (``unit = "arm_length"`` / ``"leg_length"``)."""

import numpy as np
import pinocchio as pin
import pytest
from urdf_robots import write_robots

from hikbench.problems.robots.dimensions import limb_length, robot_length, robot_lengths
from hikbench.problems.robots.kinematics import KinematicState
from hikbench.problems.robots.models import load_robot
from hikbench.problems.robots.scenarios import ScenarioError, load_scenario


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    return write_robots(tmp_path_factory.mktemp("robots"))


@pytest.mark.parametrize("urdf, srdf, name, metres", [
    # the link offsets tests/urdf_robots.py writes: hand 0.05 + forearm 0.25 + upper arm 0.25 (+ 0 from the
    # shoulder roll to the shoulder pitch, the limb's root below the chest)
    ("biped.urdf", "biped.srdf", "arm_length", 0.05 + 0.25 + 0.25),
    # sole 0.06 + shin 0.35 + thigh 0.35 (the hip joints share an origin; the hip yaw hangs off the root)
    ("biped.urdf", "biped.srdf", "leg_length", 0.06 + 0.35 + 0.35),
    # flange 0.05 + joints 7..2 (joint 1, the limb's root, stands 0.1 m off the base)
    ("arm.urdf", None, "arm_length", 0.05 + 0.05 + 0.1 + 0.2 + 0.1 + 0.2 + 0.1),
], ids=["biped-arm", "biped-leg", "arm-arm"])
def test_lengths_are_the_link_offsets_of_the_urdf(files, urdf, srdf, name, metres):
    robot = load_robot(str(files[urdf])) if srdf is None else \
        load_robot(_source(files[urdf], files[srdf]))
    assert robot_length(robot, name) == pytest.approx(metres, abs=1e-12)


def _source(urdf, srdf):
    from hikbench.problems.robots.models import robot_source

    return robot_source(str(urdf), str(srdf))


def test_an_arm_has_no_leg_length(files):
    assert set(robot_lengths(load_robot(str(files["arm.urdf"])))) == {"arm_length"}


@pytest.mark.parametrize("robot, frame", [("talos", "right_hand"), ("talos", "right_foot"), ("g1", "right_hand"),
                                          ("romeo", "right_foot"), ("panda", "ee")],
                         ids=["talos-hand", "talos-foot", "g1-hand", "romeo-foot", "panda-ee"])
def test_limb_length_is_the_chain_of_joint_origins_at_any_configuration(robot, frame):
    """Summed from the model's placements, it equals the chain of world joint origins
    (forward kinematics) at q0 and at seeded random configurations."""
    r = load_robot(robot)
    model, data = r.model, r.model.createData()
    fid = r.frame_id(frame)
    length = limb_length(r, frame)
    chain, j = [], model.frames[fid].parentJoint
    children = np.bincount(np.asarray(model.parents[1:]), minlength=model.njoints)
    while j > 0:
        chain.append(j)
        if model.parents[j] == 0 or children[model.parents[j]] > 1:
            break
        j = model.parents[j]
    rng = np.random.default_rng(0)
    for q in [r.q0] + [r.random_configuration(rng) for _ in range(3)]:
        pin.forwardKinematics(model, data, q)
        pin.updateFramePlacements(model, data)
        points = [data.oMf[fid].translation] + [data.oMi[i].translation for i in chain]
        fk = sum(np.linalg.norm(a - b) for a, b in zip(points, points[1:]))
        np.testing.assert_allclose(fk, length, rtol=1e-12, atol=1e-12)
    assert 0.2 < length < 1.5  # (a limb of a human-sized robot)


def _scenario(tmp_path, body: str, stack: str = "arm_reach") -> str:
    path = tmp_path / "s.toml"
    path.write_text(f'name = "s"\nstack = "{stack}"\nsteps = 2\n' + body)
    return str(path)


@pytest.mark.parametrize("robot", ["panda", "ur5"])
def test_an_offset_in_arm_lengths_is_scaled_by_the_robots_arm(tmp_path, robot):
    """The same file moves the target of each robot by its own arm length times the offset."""
    f = _scenario(tmp_path, '[[events]]\ntask = "ee"\noffset = [0.1, -0.2, 0.3]\nunit = "arm_length"\n')
    sc = load_scenario(f, robot=robot)
    arm = robot_length(sc.robot, "arm_length")
    assert sc.units == {"arm_length": arm}
    nominal = sc.stack.task("ee").target.translation.copy()
    sc.reset()
    sc.targets_at(0.0, KinematicState(sc.robot, sc.q_init))
    np.testing.assert_allclose(sc.stack.task("ee").target.translation - nominal, arm * np.array([0.1, -0.2, 0.3]),
                               rtol=0, atol=1e-12)


def test_metres_stay_metres(tmp_path):
    f = _scenario(tmp_path, '[[events]]\ntask = "ee"\noffset = [0.1, 0.0, 0.0]\nunit = "m"\n'
                            '[[events]]\ntime = 1.0\ntask = "ee"\noffset = [0.0, 0.1, 0.0]\n')
    sc = load_scenario(f)
    assert sc.units == {}
    nominal = sc.stack.task("ee").target.translation.copy()
    sc.targets_at(0.0, KinematicState(sc.robot, sc.q_init))
    np.testing.assert_allclose(sc.stack.task("ee").target.translation - nominal, [0.1, 0.0, 0.0], atol=1e-12)


def test_a_swing_apex_in_leg_lengths_is_scaled(tmp_path):
    """The shipped step: the swing foot's apex (0.0616 leg lengths) is 5 cm on talos, and the
    robot's leg times 0.0616 on g1."""
    for robot in ("talos", "g1"):
        sc = load_scenario("step", robot=robot)
        leg = robot_length(sc.robot, "leg_length")
        item = sc._schedule["right_foot"][0]
        np.testing.assert_allclose(item.spec["apex"], [0.0, 0.0, 0.0616 * leg], atol=1e-12)
        np.testing.assert_allclose(item.spec["offset"], [0.123 * leg, 0.0, 0.0], atol=1e-12)
    assert 0.0616 * robot_length(load_robot("talos"), "leg_length") == pytest.approx(0.05, abs=2e-4)


@pytest.mark.parametrize("body, message", [
    ('[[events]]\ntask = "ee"\noffset = [0.1, 0.0, 0.0]\nunit = "leg_length"\n',
     "events[0].unit = 'leg_length': expected 'm' or a length robot 'panda' has: leg_length is measured on the "
     "right_foot frame, which it lacks"),
    ('[[events]]\ntask = "ee"\noffset = [0.1, 0.0, 0.0]\nunit = "arm_lenght"\n',
     "events[0].unit = 'arm_lenght': expected one of 'm', 'arm_length', 'leg_length' (did you mean 'arm_length'"),
], ids=["length-the-robot-lacks", "unknown-unit"])
def test_a_unit_that_cannot_be_used_names_the_key(tmp_path, body, message):
    f = _scenario(tmp_path, body)
    with pytest.raises(ScenarioError) as err:
        load_scenario(f)
    assert str(err.value).startswith(f"{f}: ") and message in str(err.value), str(err.value)
