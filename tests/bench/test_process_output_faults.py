"""Processes and output: a solver raising KeyboardInterrupt, or an exception whose
``str`` raises, costs its row with a reason (no traceback); stdout on a full
device is one line; a level name cannot forge a line of ``inspect``'s table;
an x holding inf is judged without a RuntimeWarning."""

import os
import subprocess
import sys
import time
import warnings

import numpy as np
import pytest
from clitools import ROOT, run
from doubles import write_suite

from hikbench.bench.harness.results import read_results
from hikbench.problems.files import save_npz
from hikbench.problems.hierarchy import Hierarchy, Level
from hikbench.problems.verify import level_norms

SOLVERS = '''
from hikbench.solvers.base import Solver


class Interrupting(Solver):
    name = "interrupting"

    def solve(self, hierarchy):
        raise KeyboardInterrupt


class Lingering(Solver):
    """Correct (null-space recursion), after leaving a `sleep 60` in a session of its own, orphaned
    (its parent shell exits at once), its pid appended to $HIKBENCH_TEST_LOG."""
    name = "lingering"

    def solve(self, hierarchy):
        import os, subprocess
        from hikbench.solvers.base import OPTIMAL, SolveResult
        from hikbench.solvers.yardstick import nullspace_yardstick
        subprocess.run(["sh", "-c", f"setsid sleep 60 > /dev/null 2>&1 & echo $! >> {os.environ['HIKBENCH_TEST_LOG']}"],
                       check=True)
        return SolveResult(nullspace_yardstick(hierarchy), OPTIMAL)


class _Unprintable(Exception):
    def __str__(self):
        raise ValueError("no words")


class Unprintable(Solver):
    name = "unprintable"

    def solve(self, hierarchy):
        raise _Unprintable()
'''


@pytest.fixture(scope="module")
def solvers_file(tmp_path_factory):
    p = tmp_path_factory.mktemp("faulty") / "faulty_solvers.py"
    p.write_text(SOLVERS)
    return p


def test_a_solver_raising_keyboard_interrupt_or_an_unprintable_exception_costs_its_row(solvers_file, tmp_path,
                                                                                         capsys):
    suite = write_suite(tmp_path / "s.toml", ["yardstick"], grid={"n": [4], "depth": [1]}, repeat=1,
                        modes=("cold",))
    out = tmp_path / "o"
    code, _, err = run(capsys, "run", "--quiet", "--suite", suite, "--out", out, "--solvers", "yardstick",
                       f"{solvers_file}:Interrupting", f"{solvers_file}:Unprintable")
    assert code == 0 and "Traceback" not in err, err
    df = read_results(out).set_index("solver")
    assert df.loc["interrupting", "status"] == "error"
    assert df.loc["interrupting", "reason"].startswith("KeyboardInterrupt at faulty_solvers.py:")
    assert df.loc["unprintable", "status"] == "error"
    assert df.loc["unprintable", "reason"].startswith(
        "_Unprintable: (its message cannot be shown: str() raised ValueError) at faulty_solvers.py:")
    assert "Traceback" not in (out / "worker.log").read_text()


@pytest.mark.parametrize("solver, says", [
    ("Unprintable", "_Unprintable: (its message cannot be shown: str() raised ValueError)"),
    ("Interrupting", "KeyboardInterrupt"),
], ids=["unprintable", "keyboard interrupt"])
def test_solve_names_a_solver_s_keyboard_interrupt_or_unprintable_exception(solvers_file, tmp_path, solver, says):
    """As a process (its solve runs in a forked child, which printed the traceback)."""
    save_npz(Hierarchy.from_levels([Level.equality(np.eye(2), [1.0, 2.0], "t")]), tmp_path / "p.npz")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    p = subprocess.run([sys.executable, "-m", "hikbench", "solve", str(tmp_path / "p.npz"), "--solver",
                        f"{solvers_file}:{solver}"], capture_output=True, text=True, env=env, timeout=120)
    assert p.returncode == 1 and "Traceback" not in p.stderr, p.stderr
    assert says in p.stdout + p.stderr, p.stdout + p.stderr


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="needs /dev/full")
def test_stdout_on_a_full_device_is_one_line():
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    with open("/dev/full", "w") as full:
        p = subprocess.run([sys.executable, "-m", "hikbench", "columns"], stdout=full, stderr=subprocess.PIPE,
                           text=True, env=env, timeout=120)
    assert p.returncode == 2, p.stderr
    assert p.stderr.strip() == ("hikbench columns: error: No space left on device writing the output; free space "
                                "and run it again"), p.stderr


def test_a_level_name_with_a_line_break_cannot_forge_a_line_of_inspect(tmp_path, capsys):
    h = Hierarchy.from_levels([Level.equality(np.eye(2), [1.0, 2.0], "reach\n9  forged  1  1"),
                               Level.equality(np.ones((1, 2)), [0.0], "posture")])
    save_npz(h, tmp_path / "p.npz")
    code, out, _ = run(capsys, "inspect", tmp_path / "p.npz")
    assert code == 0
    lines = out.splitlines()
    table = [ln for ln in lines[1:] if ln.lstrip()[:1].isdigit()]
    assert [ln.split()[0] for ln in table] == ["0", "1"], out
    assert "reach\\n9  forged  1  1" in table[0]


def test_an_x_holding_inf_is_judged_without_a_warning():
    h = Hierarchy.from_levels([Level(np.eye(2), -np.ones(2), np.ones(2), "box"),
                               Level.equality(np.array([[1.0, 1.0]]), [3.0], "target")])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        norms = level_norms(h, np.array([np.inf, 0.0]))
    assert not np.isfinite(norms).all()  # (a wrong result looks wrong: NaN or inf, never a small number)


def _gone(pid: int, within: float = 3.0) -> bool:
    """Whether process ``pid`` no longer exists (not even as a zombie) within ``within`` s."""
    deadline = time.monotonic() + within
    while time.monotonic() < deadline:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return True
        time.sleep(0.02)
    return False


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="a subreaper is Linux's")
def test_a_setsid_grandchild_of_a_python_solver_ends_with_its_job(solvers_file, tmp_path, capsys, monkeypatch):
    log = tmp_path / "pids"
    monkeypatch.setenv("HIKBENCH_TEST_LOG", str(log))
    suite = write_suite(tmp_path / "s.toml", [f"{solvers_file}:Lingering"], grid={"n": [4], "depth": [1]},
                        repeat=1, modes=("cold",))
    code, _, err = run(capsys, "run", "--quiet", "--suite", suite, "--out", tmp_path / "o")
    assert code == 0, err
    pids = [int(p) for p in log.read_text().split()]
    assert pids and all(_gone(p) for p in pids)
    log.unlink()
    save_npz(Hierarchy.from_levels([Level.equality(np.eye(2), [1.0, 2.0], "t")]), tmp_path / "p.npz")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    p = subprocess.run([sys.executable, "-m", "hikbench", "solve", str(tmp_path / "p.npz"), "--solver",
                        f"{solvers_file}:Lingering"], capture_output=True, text=True, env=env, timeout=120)
    assert p.returncode == 0, p.stderr
    pids = [int(p) for p in log.read_text().split()]
    assert pids and all(_gone(p) for p in pids)


def test_a_user_family_that_hangs_is_one_line_at_the_first_solve_timeout(tmp_path, capsys):
    """The family ran in the run's own process: a hanging one blocked it for good."""
    (tmp_path / "fam.py").write_text("import time\n\ndef hangs(seed=0, **params):\n    time.sleep(3600)\n")
    suite = tmp_path / "s.toml"
    import tomli_w
    suite.write_text(tomli_w.dumps({"repeat": 1, "modes": ["cold"], "solvers": ["yardstick"],
                                    "first_solve_timeout": 2.0,
                                    "problems": [{"family": f"{tmp_path / 'fam.py'}:hangs", "seeds": [0]}]}))
    t0 = time.monotonic()
    code, _, err = run(capsys, "run", "--quiet", "--suite", suite, "--out", tmp_path / "o")
    assert time.monotonic() - t0 < 60
    assert code == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert "problem fam.py:hangs/seed=0: family" in err and ("gave no problem within the suite's "
                                                             "first_solve_timeout of 2 s (does it hang?)") in err, err
    assert not (tmp_path / "o" / "results.csv").exists()
