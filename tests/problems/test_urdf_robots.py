"""A user's robot from a URDF (tests/urdf_robots.py writes a 7-joint arm and a biped):
loading, root joint and reference configuration, aliases from link names, stacks
that hcod solves, and one-line errors for bad URDF, SRDF and frame names."""

import numpy as np
import pytest
from urdf_robots import arm_urdf, biped_srdf, biped_urdf, write_robots

from hikbench.problems.errors import HikbenchError
from hikbench.problems.robots.frames import find_frames, words
from hikbench.problems.robots.models import FrameNotFoundError, RobotFileError, load_robot, robot_source
from hikbench.problems.robots.stacks import build_stack
from hikbench.problems.robots.testsets import ROBOT_FAMILIES, stack_problem
from hikbench.problems.robots.urdf import UrdfSource
from hikbench.problems.verify import verify


@pytest.fixture(scope="session")
def files(tmp_path_factory):
    return write_robots(tmp_path_factory.mktemp("robots"))


@pytest.fixture(scope="session")
def arm(files):
    return load_robot(str(files["arm.urdf"]))


@pytest.fixture(scope="session")
def biped(files):
    return load_robot(robot_source(str(files["biped.urdf"]), str(files["biped.srdf"])))


def test_the_arm_is_a_fixed_base_chain_with_pattern_aliases(arm, files):
    assert (arm.name, arm.nq, arm.nv, arm.floating_base) == ("arm", 7, 7, False)
    assert arm.frames == {"base": "arm_base", "ee": "arm_flange"}
    np.testing.assert_array_equal(arm.q0, np.zeros(7))  # neutral: 0 is inside every range
    assert arm.bounded.all() and "fixed base (floating_base not set" in arm.description
    assert load_robot(str(files["arm.urdf"])) is arm  # loaded once per process


def test_the_biped_floats_by_its_srdf_and_starts_at_its_group_state(biped):
    assert (biped.nq, biped.nv, biped.floating_base) == (7 + 21, 6 + 21, True)
    assert not biped.bounded[:6].any() and biped.bounded[6:].all()
    q0 = biped.q0
    assert q0[2] == 0.7 and q0[biped.model.joints[biped.model.getJointId("r_knee_joint")].idx_q] == 0.8
    assert biped.frames == {"base": "pelvis", "right_hand": "r_hand", "left_hand": "l_hand",
                            "right_foot": "r_sole", "left_foot": "l_sole", "torso": "chest"}
    assert "the SRDF's floating virtual_joint" in biped.description
    assert "group_state 'half_sitting'" in biped.description


@pytest.mark.parametrize("floating, nv", [(True, 27), (False, 21)], ids=["floating", "fixed"])
def test_floating_base_given_without_srdf(files, floating, nv):
    robot = load_robot(UrdfSource(files["biped.urdf"], floating_base=floating))
    assert robot.nv == nv and robot.floating_base is floating
    assert robot.limit_margin(robot.q0).min() >= 0  # neutral: the knees at their lower limit 0


def test_a_neutral_configuration_outside_the_limits_starts_mid_range(tmp_path):
    urdf = tmp_path / "offset.urdf"
    urdf.write_text(arm_urdf().replace('lower="-2.5" upper="2.5"', 'lower="0.5" upper="1.5"', 1))
    robot = load_robot(str(urdf))
    assert robot.q0[0] == 1.0 and np.all(robot.q0[1:] == 0.0)


def test_relative_paths_in_a_stack_file_are_relative_to_the_file(tmp_path, monkeypatch, files):
    folder = tmp_path / "robots"
    write_robots(folder)
    (folder / "s.toml").write_text('name = "s"\nrobot = "biped.urdf"\nsrdf = "biped.srdf"\n'
                                   '[frames]\nright_hand = "r_wrist_link"\n'
                                   '[[levels]]\ntasks = [{ type = "joint_limits" }]\n'
                                   '[[levels]]\ntasks = [{ type = "position", frame = "right_hand" }]\n')
    monkeypatch.chdir(tmp_path)
    stack = build_stack(folder / "s.toml")
    assert stack.robot.floating_base and stack.robot.frames["right_hand"] == "r_wrist_link"
    assert stack.robot.model.frames[stack.task("right_hand").frame_id].name == "r_wrist_link"
    # the same URDF given again keeps the file's [frames]; another robot replaces the file's, and its
    # [frames] (written for the file's robot)
    assert build_stack(folder / "s.toml", robot=str(folder / "biped.urdf")).robot.frames["right_hand"] == "r_wrist_link"
    assert build_stack(folder / "s.toml", robot=str(files["biped.urdf"])).robot.frames["right_hand"] == "r_hand"


def _tip_stack(folder):
    """A stack on arm.urdf whose [frames] table names the alias ``tip`` (no name pattern finds it)."""
    write_robots(folder)
    (folder / "st.toml").write_text('name = "st"\nrobot = "arm.urdf"\n[frames]\ntip = "arm_link7"\n'
                                    '[[levels]]\ntasks = [{ type = "joint_limits" }]\n'
                                    '[[levels]]\ntasks = [{ type = "position", frame = "tip" }]\n')
    return folder / "st.toml"


@pytest.mark.parametrize("given", ["absolute", "relative"], ids=["absolute-path", "path-from-the-working-dir"])
def test_a_stack_given_its_own_urdf_again_keeps_its_frames(tmp_path, monkeypatch, given):
    """A suite or a command line that names the stack's own URDF file (as the robot-stack family's
    ``robot`` or a [[scenarios]] entry's) runs the stack with its [frames] table."""
    stack_file = _tip_stack(tmp_path / "robots")
    monkeypatch.chdir(tmp_path)
    ref = str(tmp_path / "robots" / "arm.urdf") if given == "absolute" else "robots/arm.urdf"
    stack = build_stack(stack_file, robot=ref)
    assert stack.robot.frames["tip"] == "arm_link7"
    assert stack.robot.model.frames[stack.task("tip").frame_id].name == "arm_link7"
    h = stack_problem(str(stack_file), 0, robot=ref)
    assert h.n == 7 and h.depth == 2
    scenario = tmp_path / "robots" / "sc.toml"
    scenario.write_text('name = "sc"\nstack = "st.toml"\nsteps = 2\n')
    from hikbench.problems.robots.scenarios import load_scenario

    assert load_scenario(scenario, robot=ref).robot.frames["tip"] == "arm_link7"


def test_a_frames_table_left_out_for_another_robot_is_said(tmp_path, files):
    """On another robot the table is not applied, and the frame error says so and what to write."""
    stack_file = _tip_stack(tmp_path / "robots")
    with pytest.raises(HikbenchError) as err:
        build_stack(stack_file, robot=str(files["biped.urdf"]))
    text = str(err.value)
    assert "levels[1].tasks[0].frame = 'tip': expected an alias of robot 'biped'" in text, text
    assert text.endswith("; the file's frames.tip = 'arm_link7' is written for its robot 'arm' and is not applied "
                         "to robot 'biped': name the frame for this robot where the robot is given (a scenario "
                         "file's [frames] table, --frame tip=FRAME), or give the stack's own robot"), text


@pytest.mark.parametrize("stack, robot, srdf, n", [
    ("arm_reach", "arm.urdf", None, 7),
    ("humanoid_reach", "biped.urdf", "biped.srdf", 27),
    ("humanoid_step", "biped.urdf", "biped.srdf", 27),
], ids=["arm-arm_reach", "biped-humanoid_reach", "biped-humanoid_step"])
def test_a_stack_on_a_urdf_robot_solves_with_hcod(files, stack, robot, srdf, n):
    """hcod's answer has the yardstick's level norms (verify, rtol 1e-9) on seeded problems."""
    from hikbench.solvers.hcod import HcodSolver
    from hikbench.solvers.yardstick import cascade_yardstick

    for seed in range(2):
        h = stack_problem(stack, seed, robot=str(files[robot]), srdf=srdf and str(files[srdf]))
        assert h.n == n
        res = HcodSolver().solve(h)
        assert res.status == "optimal"
        verdict = verify(h, res.x, cascade_yardstick(h)[0])
        assert verdict.level is None, (seed, verdict)


def test_the_robot_stack_family_takes_a_urdf(files):
    fam = ROBOT_FAMILIES["robot-stack"]
    h = fam.generate(seed=1, stack="humanoid_reach", robot=str(files["biped.urdf"]), floating_base=True)
    assert h.n == 27
    assert h == stack_problem("humanoid_reach", 1, robot=str(files["biped.urdf"]), floating_base=True)
    with pytest.raises(HikbenchError, match="apply with robot = the path of a .urdf file"):
        fam.generate(seed=0, srdf="x.srdf")


@pytest.mark.parametrize("name, expected", [
    ("RWristYawLink", ["r", "wrist", "yaw", "link"]), ("l_sole", ["l", "sole"]),
    ("gripper_right_base_link", ["gripper", "right", "base", "link"]), ("tool0", ["tool"]),
    ("LeftFoot", ["left", "foot"]),
], ids=["camel", "snake", "talos-gripper", "digits", "pascal"])
def test_link_names_split_into_words(name, expected):
    assert words(name) == expected


@pytest.mark.parametrize("name", ["talos", "g1"])
def test_name_patterns_find_the_curated_hands_and_feet(name):
    robot = load_robot(name)
    found = find_frames(robot.model)
    for alias in ("right_hand", "left_hand", "right_foot", "left_foot", "base"):
        assert found[alias] == robot.frames[alias], alias


def _error(fn):
    with pytest.raises(HikbenchError) as err:
        fn()
    text = str(err.value)
    assert "\n" not in text, text
    return text


def _bad_urdf(tmp_path, case):
    path = tmp_path / "robot.urdf"
    if case == "missing":
        return path, "no such URDF file"
    if case == "directory":
        path.mkdir()
        return path, "no such URDF file (a directory)"
    text, message = {
        "not-xml": ("robot name='x'", "not an XML URDF file (syntax error: line 1, column 0)"),
        "truncated": (biped_urdf()[:500], "not an XML URDF file (unclosed token: line 2, column "),
        "not-robot": ("<model/>", "the root element is <model>; expected <robot>"),
        "no-links": ('<robot name="x"></robot>', "no <link> element"),
        "no-limits": (arm_urdf().replace('<limit lower="-2.5" upper="2.5" velocity="4.0" effort="100"/>', "", 1),
                      "pinocchio cannot read this URDF: Joint [arm_joint1] is of type REVOLUTE but it does not "
                      "specify limits"),
        "unknown-parent": (arm_urdf().replace('<parent link="arm_base"/>', '<parent link="arm_bse"/>'),
                           "pinocchio cannot read this URDF: "),
        "no-joint": ('<robot name="x"><link name="a"/></robot>', "the model has no joint (nv = 0)"),
    }[case]
    path.write_text(text)
    return path, message


BAD_URDF = ["missing", "directory", "not-xml", "truncated", "not-robot", "no-links", "no-limits", "unknown-parent",
            "no-joint"]


@pytest.mark.parametrize("case", BAD_URDF)
def test_a_bad_urdf_is_one_line_naming_the_file(tmp_path, capfd, case):
    path, message = _bad_urdf(tmp_path, case)
    text = _error(lambda: load_robot(str(path)))
    assert text.startswith(f"{path}: ") and message in text, text
    assert capfd.readouterr().err == ""  # pinocchio's own messages are in the error, not on stderr


def _bad_srdf(tmp_path, case):
    srdf = tmp_path / "robot.srdf"
    good = biped_srdf()
    text, message, reference = {
        "missing": (None, "no such SRDF file", None),
        "not-xml": ("<robot", "not an XML SRDF file", None),
        "not-robot": ("<srdf/>", "the root element is <srdf>; expected <robot> (SRDF)", None),
        "unknown-joint": (good.replace("r_knee_joint", "r_kne_joint"),
                          "group_state 'half_sitting': joint 'r_kne_joint' is not a joint of the model "
                          "(did you mean 'r_knee_joint'", None),
        "value-count": (good.replace('value="0 0 0.7 0 0 0 1"', 'value="0 0 0.7"'),
                        "joint 'root_joint' value = '0 0 0.7': expected 7 finite numbers", None),
        "not-a-number": (good.replace('value="0.8"', 'value="bent"', 1),
                         "joint 'l_knee_joint' value = 'bent': expected 1 finite number", None),
        "outside-limits": (good.replace('value="0.8"', 'value="3.0"', 1),
                           "joint 'l_knee_joint' = 3 is outside its limits [0, 2.2]", None),
        "quaternion": (good.replace('value="0 0 0.7 0 0 0 1"', 'value="0 0 0.7 0 0 0 2"'),
                       "a quaternion (free flyer) or cos/sin pair is not of norm 1", None),
        "no-reference": (good, "no group_state 'standing' (reference); expected one of 'half_sitting'", "standing"),
        "planar": (good.replace('type="floating"', 'type="planar"'), "virtual_joint type 'planar'", None),
    }[case]
    if text is not None:
        srdf.write_text(text)
    return srdf, message, reference


BAD_SRDF = ["missing", "not-xml", "not-robot", "unknown-joint", "value-count", "not-a-number", "outside-limits",
            "quaternion", "no-reference", "planar"]


@pytest.mark.parametrize("case", BAD_SRDF)
def test_a_bad_srdf_is_one_line_naming_the_file(tmp_path, files, case):
    srdf, message, reference = _bad_srdf(tmp_path, case)
    text = _error(lambda: load_robot(UrdfSource(files["biped.urdf"], srdf, reference=reference)))
    assert text.startswith(f"{srdf}: ") and message in text, text


HEAD = 'name = "s"\nrobot = "arm.urdf"\n'


@pytest.mark.parametrize("content, message", [
    (HEAD + '[[levels]]\ntasks = [{ type = "pose", frame = "arm_flang" }]\n',
     "levels[0].tasks[0].frame = 'arm_flang': expected an alias of robot 'arm' (base, ee) or one of its 18 "
     "pinocchio frame names (did you mean 'arm_flange'"),
    (HEAD + '[[levels]]\ntasks = [{ type = "distance", frame_a = "ee", frame_b = "arm_lnk3", d_min = 0.1 }]\n',
     "levels[0].tasks[0].frame_b = 'arm_lnk3': expected an alias of robot 'arm' (base, ee)"),
    (HEAD + '[[levels]]\ntasks = [{ type = "position", frame = "right_hand" }]\n',
     "levels[0].tasks[0].frame = 'right_hand': expected an alias of robot 'arm' (base, ee) or one of its 18 "
     "pinocchio frame names: universe, arm_base"),
    (HEAD + '[frames]\nee = "arm_flang"\n[[levels]]\ntasks = [{ type = "pose", frame = "ee" }]\n',
     "frames.ee = 'arm_flang': expected a pinocchio frame name of robot 'arm' (did you mean 'arm_flange'"),
    ('name = "s"\nrobot = "talos"\nsrdf = "x.srdf"\n[[levels]]\ntasks = [{ type = "com" }]\n',
     "robot 'talos': srdf applies to a URDF robot only"),
    ('name = "s"\nrobot = "arm.urdf"\nreference = "home"\n[[levels]]\ntasks = [{ type = "com" }]\n',
     "reference = 'home' names an SRDF group_state; expected an srdf as well"),
    ('name = "s"\nrobot = "arm.urdf"\nfloating_base = "yes"\n[[levels]]\ntasks = [{ type = "com" }]\n',
     "floating_base = 'yes': expected true or false"),
], ids=["frame-typo", "frame_b-typo", "alias-missing", "frames-table-typo", "srdf-with-a-name",
        "reference-without-srdf", "floating_base-string"])
def test_a_bad_frame_or_robot_key_in_a_stack_file_is_one_line(tmp_path, content, message):
    write_robots(tmp_path)
    path = tmp_path / "s.toml"
    path.write_text(content)
    text = _error(lambda: build_stack(path))
    assert text.startswith(f"{path}: ") and message in text, text


def test_a_missing_alias_says_which_key_to_set(arm):
    with pytest.raises(FrameNotFoundError, match=r"set frames.left_foot = \"<frame name>\" in the stack or "
                                                 r"scenario file \(or --frame left_foot=FRAME\)"):
        arm.frame_id("left_foot")


def test_a_robot_name_that_is_not_a_urdf_says_what_is_expected():
    with pytest.raises(HikbenchError, match=r"or the path of a .urdf file\)"):
        load_robot("my_robot.xml")
    with pytest.raises(RobotFileError, match="floating_base applies to a URDF robot only"):
        robot_source("talos", floating_base=True)


def test_a_com_task_on_a_robot_without_masses_is_one_line(tmp_path):
    import re

    (tmp_path / "massless.urdf").write_text(re.sub(r"<inertial>.*?</inertial>", "", arm_urdf()))
    path = tmp_path / "s.toml"
    path.write_text('name = "s"\nrobot = "massless.urdf"\n[[levels]]\ntasks = [{ type = "com" }]\n')
    text = _error(lambda: build_stack(path))
    assert text.startswith(f"{path}: level 0, task 0 (type 'com'): task 'com': robot 'massless' has a total mass "
                           "of 0 kg (no <inertial> in its URDF)"), text
