"""`hikbench scenario` on a robot from a URDF written by the tests (tests/urdf_robots.py):
the shipped scenarios run on it through the command line and report their checks; a
scenario file names its URDF, SRDF and frames; bad files and frame names are one line,
exit 2."""

import pandas as pd
import pytest
from urdf_robots import write_robots

from hikbench.bench.cli import main


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    return write_robots(tmp_path_factory.mktemp("robots"))


def _biped(files) -> list[str]:
    return ["--robot", str(files["biped.urdf"]), "--srdf", str(files["biped.srdf"])]


def test_reach_runs_on_a_urdf_robot_and_reports_its_checks(files, tmp_path, capsys):
    rc = main(["scenario", "reach", *_biped(files), "--solver", "hcod", "--steps", "40", "--out", str(tmp_path)])
    out = capsys.readouterr().out
    assert out.startswith("robot biped: nq=28 nv=27, URDF "), out
    assert "floating base (the SRDF's floating virtual_joint)" in out and "right_hand=r_hand" in out, out
    for check in ("run completed", "joint limits"):
        assert f"[pass] {check}: " in out, out
    for check in ("com regulated", "left_foot regulated", "right_foot regulated", "out of reach: lowest value"):
        assert f"[not judged] {check}: " in out, out  # (they need the final values of the 700 steps)
    df = pd.read_csv(tmp_path / "reach_biped_hcod_time.csv")
    assert len(df) == 40 and (df["status"] == "optimal").all()
    assert rc == 0 and "FAIL" not in out  # (40 steps: final values not judged; the checks of these steps hold)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["reach", "step"])
def test_the_shipped_scenarios_pass_on_the_test_biped_with_hcod(files, tmp_path, capsys, name):
    """The full schedules (700 and 225 steps) on a biped of legs 0.76 m and arms 0.55 m:
    every check passes (the talos offsets are out of and back in its reach)."""
    rc = main(["scenario", name, *_biped(files), "--solver", "hcod", "--out", str(tmp_path)])
    out = capsys.readouterr().out
    assert rc == 0 and "FAIL" not in out and out.count("[pass]") >= 5, out


def test_a_scenario_file_names_its_urdf_srdf_and_frames(tmp_path, capsys):
    write_robots(tmp_path / "robots")
    (tmp_path / "s.toml").write_text(
        'name = "mine"\nstack = "humanoid_reach"\nrobot = "robots/biped.urdf"\nsrdf = "robots/biped.srdf"\n'
        'steps = 200\n[frames]\nright_hand = "r_wrist_link"\n'
        '[[events]]\ntask = "right_hand"\noffset = [0.05, 0.0, 0.05]\n'
        '[checks]\nlimits = true\nregulated = ["com"]\n')
    rc = main(["scenario", str(tmp_path / "s.toml"), "--solver", "hcod", "--steps", "20",
               "--out", str(tmp_path / "out")])
    out = capsys.readouterr().out
    assert rc == 0 and "right_hand=r_wrist_link" in out and "[not judged] com regulated" in out, out


def _copy(src, dst) -> str:
    dst.write_text(src.read_text())
    return str(dst)


def _arm_stack(folder):
    (folder / "st.toml").write_text('name = "st"\nrobot = "arm.urdf"\n'
                                    '[[levels]]\ntasks = [{ type = "joint_limits" }]\n'
                                    '[[levels]]\ntasks = [{ type = "pose", frame = "arm_flang" }]\n')
    (folder / "sc.toml").write_text('name = "sc"\nstack = "st.toml"\n')
    return [str(folder / "sc.toml")]


@pytest.mark.parametrize("args, message", [
    (lambda f, d: ["reach", "--robot", str(d / "nope.urdf")], "nope.urdf: no such URDF file"),
    (lambda f, d: ["reach", "--robot", _copy(f["biped.srdf"], d / "srdf.urdf")],
     "srdf.urdf: no <link> element; expected a URDF with at least one link"),
    (lambda f, d: ["reach", "--robot", str(f["biped.urdf"]), "--srdf", str(f["arm.urdf"])],
     "arm.urdf: <link> elements at the top: a URDF; expected an SRDF"),
    (lambda f, d: ["reach", "--robot", str(f["biped.urdf"]), "--srdf", str(d / "nope.srdf")],
     "nope.srdf: no such SRDF file"),
    (lambda f, d: ["reach", "--srdf", str(f["biped.srdf"])], "--srdf: expected --robot PATH.urdf as well"),
    (lambda f, d: ["reach", *_biped(f), "--frame", "right_hand=r_hnd"],
     "--frame right_hand=r_hnd: expected a pinocchio frame name of robot 'biped' (did you mean 'r_hand'"),
    (lambda f, d: ["reach", *_biped(f), "--frame", "right_hand"], "--frame 'right_hand': expected ALIAS=FRAME"),
    (lambda f, d: ["reach", "--robot", str(f["arm.urdf"])],
     "humanoid_reach.toml: levels[2].tasks[0].frame = 'left_foot': expected an alias of robot 'arm' (base, ee) "
     "or one of its 18 pinocchio frame names"),
    (lambda f, d: _arm_stack(f["arm.urdf"].parent),
     "st.toml: levels[1].tasks[0].frame = 'arm_flang': expected an alias of robot 'arm' (base, ee) or one of "
     "its 18 pinocchio frame names (did you mean 'arm_flange'"),
], ids=["urdf-missing", "urdf-an-srdf", "srdf-a-urdf", "srdf-missing", "srdf-without-robot",
        "frame-typo", "frame-malformed", "alias-missing", "stack-frame-typo"])
def test_bad_robot_files_and_frames_are_one_line_exit_2(files, tmp_path, capsys, args, message):
    rc = main(["scenario", *args(files, tmp_path), "--steps", "1", "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and message in err[0], err
