"""Scenario TOML files: every bad value is one line naming the file, the key path and
what was expected, exit 2 from `hikbench scenario` (no traceback, no silent default)."""

import pytest

from hikbench.bench.cli import main
from hikbench.problems.robots.scenarios import ScenarioError, load_scenario

HEAD = 'name = "s"\nstack = "arm_reach"\n'

BAD_SCENARIOS = [
    # values that ran as something else
    ("[initial]\nperturbation = nan\n", "initial.perturbation = nan: expected a finite number >= 0"),
    ('[[events]]\ntime = 0.0\ntask = "ee"\nofset = [0.1, 0.0, 0.0]\n',
     "unknown key events[0].ofset (did you mean 'offset'?)"),
    ('[checks]\nlimits = "yes"\n', "checks.limits = 'yes': expected true or false"),
    # tracebacks
    ('dt = "x"\n', "dt = 'x': expected a finite number > 0"),
    ('[[events]]\ntime = "now"\ntask = "ee"\n', "events[0].time = 'now': expected a finite number >= 0"),
    ('[initial]\nperturbation = 0.01\nseed = "x"\n', "initial.seed = 'x': expected an integer >= 0"),
    ("initial = 5\n", "initial = 5: expected a table"),
    ("events = [1]\n", "events[0] = 1: expected an [[events]] table"),
    ('steps = "many"\n', "steps = 'many': expected an integer >= 1"),
    ('[[trajectories]]\ntask = "ee"\nduration = "long"\n', "trajectories[0].duration = 'long': expected a finite "
                                                           "number > 0"),
    ('[[events]]\ntask = "ee"\noffset = 0.1\n', "events[0].offset = 0.1: expected 3 finite numbers"),
    ("checks = 3\n", "checks = 3: expected a table"),
    ('[checks]\ntracked = { ee = "tight" }\n', "checks.tracked.ee = 'tight': expected a finite number > 0"),
    ('[checks]\nreach = { task = "ee" }\n', "checks.reach: missing key 'out_of_reach_until'"),
    ('[plot]\njoints = "elbow"\n', "plot.joints = 'elbow': expected a non-empty list of joint names"),
    # misleading messages
    ("dt = nan\n", "dt = nan: expected a finite number > 0"),
    ('[checks]\nregulated = "ee"\n', "checks.regulated = 'ee': expected a list of task names"),
    ('[checks]\nregulated = ["eee"]\n', "checks.regulated[0] = 'eee': expected a task of stack 'arm_reach'"),
    ('[[events]]\ntask = "posture"\n', "events[0].task = 'posture': expected a pose, position or com task"),
    ('[[events]]\ntask = "ee"\nto_frames = ["nowhere"]\n', "events[0].to_frames[0] = 'nowhere': expected a frame"),
    ("[initial]\nperturbation = 1e300\n", "initial.perturbation = 1e+300: expected a finite number >= 0 and <= 3.14"),
]
BAD_IDS = ["perturbation-nan", "offset-typo", "limits-string", "dt-string", "time-string", "seed-string",
           "initial-int", "events-int", "steps-string", "duration-string", "offset-number", "checks-int",
           "tracked-string", "reach-incomplete", "plot-joints-string", "dt-nan", "regulated-string",
           "regulated-unknown-task", "event-on-posture", "to-frames-unknown", "perturbation-huge"]


def _error_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("hikbench scenario: error: "), err
    return err[0]


@pytest.mark.parametrize("body, message", BAD_SCENARIOS, ids=BAD_IDS)
def test_a_bad_scenario_value_is_one_line_naming_file_and_key(tmp_path, capsys, body, message):
    path = tmp_path / "s.toml"
    path.write_text(HEAD + ("" if body.startswith("steps") else "steps = 2\n") + body)
    assert main(["scenario", str(path), "--out", str(tmp_path / "out")]) == 2
    line = _error_line(capsys)
    assert f"{path}: " in line and message in line, line
    assert not any((tmp_path / "out").glob("*.csv"))  # nothing ran


@pytest.mark.parametrize("text, message", [
    ('name = "s"\nstack = 5\n', "stack = 5: expected a shipped stack name or the path of a stack .toml"),
    ('stack = "arm_reach"\n', "missing key 'name'"),
    (b"\x89PNG\r\n\x1a\n\x00\x00\xff\xfe", "not UTF-8 text"),
    ('name = "s"\nstack = [\n', "invalid TOML"),
], ids=["stack-int", "no-name", "binary", "toml-syntax"])
def test_a_file_that_is_no_scenario_is_one_line(tmp_path, capsys, text, message):
    path = tmp_path / "s.toml"
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    assert main(["scenario", str(path), "--out", str(tmp_path / "out")]) == 2
    line = _error_line(capsys)
    assert str(path) in line and message in line, line


def test_a_valid_scenario_keeps_its_values(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text(HEAD + 'steps = 2\ndt = 0.005\n[initial]\nperturbation = 0.01\nseed = 3\n[[events]]\ntime = 0.5\n'
                           'task = "ee"\noffset = [0.1, 0.0, 0.0]\n[checks]\nlimits = true\nregulated = ["ee"]\n')
    sc = load_scenario(path)
    assert sc.dt == 0.005 and sc.steps == 2 and sc.event_times() == [0.5]
    assert sc.checks == {"limits": True, "regulated": ["ee"]}
    assert sc.q_init.tolist() != sc.robot.q0.tolist()


def test_scenario_errors_are_scenario_errors(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text(HEAD + "[initial]\nperturbation = inf\n")
    with pytest.raises(ScenarioError, match=r"initial.perturbation = inf"):
        load_scenario(path)
