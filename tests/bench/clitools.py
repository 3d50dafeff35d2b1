"""Running the CLI from the tests: in-process, or as a process to signal."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from hikbench.bench.cli import main

ROOT = Path(__file__).resolve().parents[2]
#: ``python -c START ARGV`` is ``hikbench ARGV`` from the source tree, with Python's own SIGINT
#: handler even where pytest runs with SIGINT ignored (a background job)
START = ("import runpy, signal; signal.signal(signal.SIGINT, signal.default_int_handler); "
         "runpy.run_module('hikbench', run_name='__main__')")


def run(capsys, *argv):
    """``hikbench ARGV`` (each argument converted to str); returns (exit code, stdout, stderr)."""
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def assert_user_error(code, err, *fragments):
    """A user mistake: exit code 2, one line on stderr holding every fragment, no
    traceback, no warning."""
    assert code == 2, err
    assert len(err.strip().splitlines()) == 1, err
    assert "Traceback" not in err and "Warning" not in err
    for f in fragments:
        assert f in err, err


def start(argv, cwd, **popen_kw) -> subprocess.Popen:
    """``hikbench ARGV`` as a process in ``cwd``, the source tree and this folder (the test
    doubles) on its path; ``popen_kw`` go to Popen (stdout, stderr, start_new_session)."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), str(Path(__file__).parent)])}
    return subprocess.Popen([sys.executable, "-c", START, *map(str, argv)], env=env, cwd=cwd, text=True,
                            **popen_kw)
