"""Stack TOML files: a file that is not UTF-8 text, a task missing its required keys
or misspelling one, are one-line StackErrors naming the file and the task."""

import pytest

from hikbench.bench.cli import main
from hikbench.problems.robots.stacks import StackError, build_stack

HEAD = 'name = "s"\nrobot = "panda"\n'


@pytest.mark.parametrize("content, message", [
    ((HEAD + '# caf\xe9\n[[levels]]\ntasks = [{ type = "com" }]\n').encode("latin-1"),
     "not UTF-8 text (invalid continuation byte at byte"),
    (HEAD.encode() + b"\x00\xff\xfe", "not UTF-8 text"),
    ((HEAD + '[[levels]]\ntasks = [{ type = "distance" }]\n').encode(),
     "level 0, task 0 (type 'distance'): task type 'distance': missing key(s) 'frame_a', 'frame_b', 'd_min'"),
    ((HEAD + '[[levels]]\ntasks = [{ type = "distance", frame_a = "ee" }]\n').encode(),
     "task type 'distance': missing key(s) 'frame_b', 'd_min'"),
    ((HEAD + '[[levels]]\ntasks = [{ type = "com", gian = 2.0 }]\n').encode(),
     "task type 'com': unknown key(s) ['gian'] (did you mean 'gain'?)"),
    ((HEAD + '[[levels]]\ntasks = [{ type = "positon", frame = "ee" }]\n').encode(),
     "unknown task type 'positon' (did you mean 'position'?)"),
    ((HEAD + '[[levels]]\ntasks = [5]\n').encode(), "levels[0].tasks[0] = 5: expected a task table"),
    ((HEAD + 'dt = nan\n[[levels]]\ntasks = [{ type = "com" }]\n').encode(), "dt = nan: expected a finite number"),
    ((HEAD + '[[levels]]\nname = 3\ntasks = [{ type = "com" }]\n').encode(), "levels[0].name = 3: expected"),
], ids=["latin-1", "binary", "distance-no-arguments", "distance-some-arguments", "key-typo", "type-typo",
        "task-int", "dt-nan", "level-name-int"])
def test_a_bad_stack_file_is_one_line_naming_file_and_task(tmp_path, content, message):
    path = tmp_path / "s.toml"
    path.write_bytes(content)
    with pytest.raises(StackError) as err:
        build_stack(path)
    text = str(err.value)
    assert text.startswith(f"{path}: ") and message in text and "\n" not in text, text


@pytest.mark.parametrize("content", [b"\xff\xfe\x00", (HEAD + '[[levels]]\ntasks = [{ type = "distance" }]\n').encode()],
                         ids=["binary", "distance-no-arguments"])
def test_a_scenario_on_a_bad_stack_file_exits_2(tmp_path, capsys, content):
    (tmp_path / "stack.toml").write_bytes(content)
    scenario = tmp_path / "s.toml"
    scenario.write_text('name = "s"\nstack = "stack.toml"\n')
    assert main(["scenario", str(scenario), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(tmp_path / "stack.toml") in err[0], err
