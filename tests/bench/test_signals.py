"""A solver that never returns to the interpreter does not keep a command from
ending on SIGTERM and Ctrl-C: ``scenario``'s in-process solver calls end by the
signal; ``solve``'s solve runs in the isolated worker, which the command kills
before it exits as ``run`` does (130 interrupted, 143 terminated)."""

from __future__ import annotations

import os
import signal
import subprocess
import time

import pytest
from clitools import start
from doubles import spec, tiny

from hikbench.problems.files import save_npz


@pytest.mark.parametrize("sig", ["SIGTERM", "SIGINT"])
@pytest.mark.parametrize("command", ["solve", "scenario"])
def test_a_solver_spinning_in_compiled_code_is_stopped(tmp_path, command, sig):
    marker = tmp_path / "spinning"
    if command == "solve":
        save_npz(tiny(), tmp_path / "p.npz")
        argv = ["solve", str(tmp_path / "p.npz")]
    else:
        argv = ["scenario", "reach", "--steps", "2", "--out", str(tmp_path / "out")]
    argv += ["--solver", spec("SpinSolver"), "--option", f"marker={marker}"]
    proc = start(argv, tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 120
        while not marker.exists() and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        assert marker.exists(), proc.poll()
        time.sleep(0.2)  # inside the compiled loop
        os.kill(proc.pid, getattr(signal, sig))
        _, err = proc.communicate(timeout=30)
    finally:
        proc.kill()
    if command == "solve":  # (the worker killed, its session with it: isolation.IsolatedWorker.kill)
        assert proc.returncode == 128 + getattr(signal, sig), err
        assert err.splitlines()[-1] == ("hikbench solve: interrupted" if sig == "SIGINT" else
                                        "hikbench solve: terminated (SIGTERM)"), err
    else:
        assert proc.returncode == -getattr(signal, sig), err  # the kernel's default action: ended by the signal
