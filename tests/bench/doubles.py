"""Test doubles for the harness: solvers that hang, crash or sleep, and a tiny
generator. Injected as ``/path/doubles.py:Name`` (never registered)."""

from __future__ import annotations

import ctypes
import os
import time
from pathlib import Path

import numpy as np

from hikbench.problems.hierarchy import Hierarchy, Level
from hikbench.solvers.base import OPTIMAL, Solver, SolveResult
from hikbench.solvers.yardstick import nullspace_yardstick

HERE = Path(__file__).with_name("doubles.py")


def spec(name: str) -> str:
    """The solver / family spec of a double, e.g. spec("HangSolver")."""
    return f"{HERE}:{name}"


def tiny(seed: int = 0, n: int = 6, depth: int = 2, rows: int = 2) -> Hierarchy:
    """A random equality hierarchy: ``depth`` levels of ``rows`` rows in R^n."""
    rng = np.random.default_rng(seed)
    return Hierarchy.from_levels([Level.equality(rng.standard_normal((rows, n)), rng.standard_normal(rows))
                                  for _ in range(depth)])


def solve_job(solver: str, repeat: int = 1) -> dict:
    """A worker job (hikbench.bench.harness.worker): ``solver`` solves :func:`tiny` cold."""
    return {"kind": "solve", "hierarchy": tiny(), "solver": solver, "options": {}, "mode": "cold",
            "repeat": repeat, "warmup": 1}


class SleepSolver(Solver):
    """Correct (null-space recursion), after sleeping ``delay`` seconds."""

    name = "sleep"
    supports_warm_start = True

    def __init__(self, delay: float = 0.0):
        self.delay = float(delay)

    def solve(self, hierarchy):
        if self.delay:
            time.sleep(self.delay)
        return SolveResult(nullspace_yardstick(hierarchy), OPTIMAL, iterations=1)


class WrongSolver(Solver):
    """Returns x = 0: optimal by its own status, wrong by verification."""

    name = "wrong"

    def solve(self, hierarchy):
        return SolveResult(np.zeros(hierarchy.n), OPTIMAL)


class HangSolver(Solver):
    """Never returns."""

    name = "hang"

    def solve(self, hierarchy):
        while True:
            time.sleep(0.05)


def _spin(x):
    while x >= 0:  # never ends: x stays in [0, 2^31)
        x = (x * 1103515245 + 12345) % 2147483648
    return x


class SpinSolver(Solver):
    """Never returns, looping in numba-compiled code that holds the GIL: no
    Python signal handler can run (a backend stuck in C code). Touches the
    file ``marker`` (option) once compiled, just before it spins."""

    name = "spin"

    def __init__(self, marker: str = ""):
        self.marker = marker

    def solve(self, hierarchy):
        import numba

        spin = numba.njit(_spin)
        spin.compile("(int64,)")
        if self.marker:
            Path(self.marker).touch()
        return spin(1)


class HangOnWideSolver(SleepSolver):
    """Solves hierarchies of up to 6 variables, hangs on wider ones."""

    name = "hang-on-wide"

    def solve(self, hierarchy):
        while hierarchy.n > 6:
            time.sleep(0.05)
        return super().solve(hierarchy)


class SegfaultSolver(Solver):
    """Dereferences NULL: the process dies with SIGSEGV."""

    name = "segfault"

    def solve(self, hierarchy):
        ctypes.string_at(0)


class RaisingSolver(Solver):
    """Raises from inside the backend."""

    name = "raising"

    def solve(self, hierarchy):
        raise RuntimeError("backend exploded")


class WarmReference:
    """A stand-in for a warm-start solver (hcod): the reference plus a warm_start option;
    ``activations`` is 1 in mode none, 0 otherwise (so that a test sees the mode arrive)."""

    def __init__(self, warm_start="time"):
        from hikbench.solvers.yardstick import YardstickSolver

        if warm_start not in ("none", "stage", "time"):
            from hikbench.solvers.errors import SolverOptionError
            raise SolverOptionError(f"warm_start must be none, stage or time; got {warm_start!r}")
        self.warm_start = warm_start
        self._ref = YardstickSolver()

    def solve(self, h):
        res = self._ref.solve(h)
        res.activations = 1 if self.warm_start == "none" else 0
        return res


class LoggedModes(WarmReference):
    """WarmReference whose calls are logged in order (``LoggedModes.log``: the mode of each call)
    and whose x in mode ``stage`` is the reference's plus 1e-3: another answer than the others'."""

    log: list = []

    def solve(self, h):
        LoggedModes.log.append(self.warm_start)
        res = super().solve(h)
        if self.warm_start == "stage":
            res.x = res.x + 1e-3
        return res


class WarmOnOff(WarmReference):
    """A warm_start parameter with its own modes, "on" and "off" (not hcod's)."""

    def __init__(self, warm_start="on"):
        from hikbench.solvers.yardstick import YardstickSolver

        if warm_start not in ("on", "off"):
            from hikbench.solvers.errors import SolverOptionError
            raise SolverOptionError(f"warm_start must be on or off; got {warm_start!r}")
        self.warm_start = warm_start
        self._ref = YardstickSolver()


class WarmRequired(WarmReference):
    """A warm_start parameter without a default value."""

    def __init__(self, warm_start):
        super().__init__(warm_start)


def write_suite(path, solvers, grid=None, seeds=(0,), repeat=3, timeout=5.0, modes=("cold", "warm"),
                family="tiny") -> Path:
    """Write a suite TOML over the ``tiny`` generator; returns its path."""
    import tomli_w

    data = {"repeat": repeat, "warmup": 1, "timeout": timeout, "first_solve_timeout": timeout,
            "modes": list(modes), "solvers": list(solvers),
            "problems": [{"family": spec(family), "grid": grid or {"n": [4, 6], "depth": [1, 2]},
                          "seeds": list(seeds)}]}
    path = Path(path)
    path.write_bytes(tomli_w.dumps(data).encode())
    return path


class FirstSlowSolver(SleepSolver):
    """The first solve in a process takes 1 s (like a JIT compilation)."""

    name = "first-slow"
    _compiled = False

    def solve(self, hierarchy):
        if not FirstSlowSolver._compiled:
            time.sleep(1.0)
            FirstSlowSolver._compiled = True
        return super().solve(hierarchy)


class Sleep2ms(SleepSolver):
    """``sleeper``: 2 ms per solve (the baseline of the compare tests)."""

    name = "sleeper"

    def __init__(self, delay: float = 0.002):
        super().__init__(delay)


class Sleep4ms(Sleep2ms):
    """``sleeper`` again, 4 ms per solve: an injected 2x slowdown."""

    def __init__(self, delay: float = 0.004):
        super().__init__(delay)


class Sleep20ms(Sleep2ms):
    """``sleeper`` again, 20 ms per solve: an injected 10x slowdown."""

    def __init__(self, delay: float = 0.02):
        super().__init__(delay)


def still_run(sc, steps: int, status=None, err: float = 1e-3):
    """A ScenarioRun of ``steps`` steps standing at ``sc.q_init`` (no solve), every task error
    ``err``, statuses ``status`` (default all optimal); a last status "diverged" adds no q, as
    in hikbench.bench.scenarios.runner.run_scenario."""
    import pandas as pd

    from hikbench.bench.scenarios.runner import ScenarioRun

    status = list(status or ["optimal"] * steps)
    rec = pd.DataFrame({"step": np.arange(steps), "time_s": np.arange(steps) * sc.dt, "solve_time_min_s": 1e-4,
                        "solve_time_first_s": 2e-4, "repeat": 5, "repeats_agree": True, "activations": 0,
                        "deactivations": 0, "active_rows": 0, "rows_entered": 0, "rows_left": 0,
                        "status": status, "reason": "",
                        **{f"err_{task.name}": err for task in sc.stack.tasks}})
    n_q = steps if status[-1] == "diverged" else steps + 1
    return ScenarioRun(sc, "hcod", "time", rec, np.tile(sc.q_init, (n_q, 1)))


class LogSolver(SleepSolver):
    """Correct; appends ``n`` of every hierarchy it solves to the file named by
    the environment variable HIKBENCH_TEST_LOG (the order in which the run's
    jobs solve)."""

    name = "log"

    def _log(self, hierarchy):
        with open(os.environ["HIKBENCH_TEST_LOG"], "a") as f:
            f.write(f"{self.name} {hierarchy.n}\n")

    def solve(self, hierarchy):
        self._log(hierarchy)
        return super().solve(hierarchy)


class PidLogSolver(LogSolver):
    """As LogSolver, each line also naming the process that solved: ``name n pid``."""

    name = "pid-log"

    def _log(self, hierarchy):
        with open(os.environ["HIKBENCH_TEST_LOG"], "a") as f:
            f.write(f"{self.name} {hierarchy.n} {os.getpid()}\n")


class LogSegfaultSolver(LogSolver):
    """Logs (as LogSolver), then dies with SIGSEGV."""

    name = "log-segfault"

    def solve(self, hierarchy):
        self._log(hierarchy)
        ctypes.string_at(0)


class LogHangLaterSolver(LogSolver):
    """Logs (as LogSolver); from its fourth solve on (counted in the log) it never
    returns: with the first solve, one warm-up and one timed solve per round,
    round 1 ends, round 2 hangs."""

    name = "log-hang-later"

    def solve(self, hierarchy):
        res = super().solve(hierarchy)
        log = Path(os.environ["HIKBENCH_TEST_LOG"])
        if sum(line.startswith(self.name + " ") for line in log.read_text().splitlines()) > 3:
            while True:
                time.sleep(0.05)
        return res


class FlakySolver(SleepSolver):
    """Correct on every second call in the process, x + 1 on the others: a run's
    last timed repetition may be right while an earlier one was not."""

    name = "flaky"
    calls = 0

    def solve(self, hierarchy):
        FlakySolver.calls += 1
        res = super().solve(hierarchy)
        return res if FlakySolver.calls % 2 == 0 else SolveResult(res.x + 1.0, OPTIMAL, iterations=1)


def verified_run(out, problems, solver="s") -> str:
    """A run directory whose results.csv holds one verified cold row per problem id."""
    import json

    from hikbench.bench.harness.results import ResultsWriter

    with ResultsWriter(out) as w:
        for p in problems:
            w.write({"problem": p, "solver": solver, "settings": "default", "mode": "cold", "status": "optimal",
                     "verified": True, "samples_ns": json.dumps([1000, 1010, 1020]), "time_median_s": 1.01e-6,
                     "calib_ns": 1_000_000, "host": "h"})
    return str(out)


#: a small suite where nullspace-svd declines ik-like (the `declining_run` fixture of conftest.py)
DECLINING_SUITE = """repeat = 1
warmup = 0
timeout = 20.0
modes = ["cold"]
solvers = ["nullspace-svd", "yardstick"]
[[problems]]
family = "equality"
grid = { n = [6, 8], depth = [2] }
[[problems]]
family = "ik-like"
grid = { n = [6] }
"""


class BaseOnlySolver(Solver):
    """Correct where ``hikbench`` runs from an installed base revision (a ``site``
    folder: ``hikbench regress``'s base side), x = 0 from the working tree: a
    case that fails on the change alone."""

    name = "base-only"

    def solve(self, hierarchy):
        import hikbench

        on_base = Path(hikbench.__file__).parents[1].name == "site"
        return SolveResult(nullspace_yardstick(hierarchy) if on_base else np.zeros(hierarchy.n), OPTIMAL)


class CountingSolver(Solver):
    """The yardstick's answer; its iterations are the calls this object has answered, this one
    included: a state that grows with every solve, as a warm start's does."""

    name = "counting"
    supports_inequalities = True

    def __init__(self):
        from hikbench.solvers.yardstick import YardstickSolver

        self._ref = YardstickSolver()
        self.calls = 0

    def solve(self, hierarchy):
        self.calls += 1
        res = self._ref.solve(hierarchy)
        res.iterations = self.calls
        return res


class SerialSolver(CountingSolver):
    """The yardstick's answer; its iterations are the order in which its object was built
    (objects that disagree)."""

    name = "serial"
    built = 0

    def __init__(self):
        super().__init__()
        SerialSolver.built += 1
        self.serial = SerialSolver.built

    def solve(self, hierarchy):
        res = self._ref.solve(hierarchy)
        res.iterations = self.serial
        return res


#: random n=12 seed 0 with A rescaled, and the yardstick's point on it before levels and units were
#: scaled (above the optimum): tests/solvers/data/rescaled_random_12_0.npz
RESCALED = Path(__file__).parents[1] / "solvers" / "data" / "rescaled_random_12_0.npz"


def rescaled_random(seed: int = 0, i: int = 0) -> Hierarchy:
    """A family (``seed`` unused): :data:`RESCALED`'s problem with A times its i-th scale (1e-12, 1e100)."""
    with np.load(RESCALED) as z:
        return Hierarchy(z["A"] * z["scales"][i], z["lower"], z["upper"], z["level"])


class OldYardstickSolver(Solver):
    """Returns the old yardstick's point on :func:`rescaled_random`'s problems (optimal by its own
    status, above the optimum by the certified yardstick); x = 0 on any other problem."""

    name = "old-yardstick"

    def solve(self, hierarchy):
        with np.load(RESCALED) as z:
            for i in range(len(z["scales"])):
                if np.array_equal(hierarchy.A, z["A"] * z["scales"][i]):
                    return SolveResult(z[f"x_old_{i}"], OPTIMAL)
        return SolveResult(np.zeros(hierarchy.n), OPTIMAL)
