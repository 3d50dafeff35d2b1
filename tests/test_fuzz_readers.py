"""Fuzz tests of every file reader: random mutations of valid files (byte flips,
truncations, insertions; for TOML also key typos and values swapped to another type,
NaN, inf or huge numbers). The property: the reader returns a result or raises a
HikbenchError (one line), never another exception, within MEMORY bytes beyond its
size and SECONDS of wall time (a forked child: fuzz_tools.bounded).

`make test` runs FAST examples per reader (derandomized under CI=1); the ``slow``
variants run SLOW examples (`make test-all`). Each test prints the outcomes it
counted (`pytest -rP` shows them): files read, files refused with a HikbenchError,
and the slowest file's milliseconds."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from fuzz_tools import bounded, byte_mutations, toml_mutations
from hypothesis import HealthCheck, event, given, settings

from hikbench.problems.hierarchy import Hierarchy, Level

ROOT = Path(__file__).resolve().parents[1]
FAST, SLOW = 60, 400
SECONDS = 20.0

SCENARIO = '''name = "fuzz"
stack = "arm_reach"
steps = 3
dt = 0.01
[initial]
perturbation = 0.01
seed = 1
[[events]]
time = 0.0
task = "ee"
offset = [0.05, 0.0, 0.0]
[[trajectories]]
task = "ee"
start = 0.01
duration = 0.02
offset = [0.0, 0.05, 0.0]
[checks]
limits = true
regulated = ["ee"]
tracked = { ee = 0.01 }
reach = { task = "ee", out_of_reach_until = 0.01 }
[plot]
joints = ["panda_joint1"]
'''

SUITE = '''description = "fuzz"
repeat = 1
warmup = 0
timeout = 5.0
modes = ["cold"]
solvers = ["yardstick"]
[[settings]]
solver = "yardstick"
name = "other"
options = {}
[[problems]]
family = "equality"
params = { rows = 2 }
grid = { n = [4, 6], depth = [1, 2] }
seeds = [0, 1]
'''


def _hierarchy() -> Hierarchy:
    rng = np.random.default_rng(0)
    return Hierarchy.from_levels([Level.equality(rng.standard_normal((2, 4)), rng.standard_normal(2)),
                                  Level(rng.standard_normal((2, 4)), -np.ones(2), np.ones(2))])


def _read_npz(path):
    from hikbench.problems.files import load

    return load(path)


def _read_soth(path):
    from hikbench.problems.soth import load_soth

    return load_soth(path)


def _read_suite(path):
    from hikbench.bench.suites import expand, load_suite

    return expand(load_suite(str(path)))


def _read_stack(path):
    from hikbench.problems.robots.stacks import build_stack

    stack = build_stack(path)
    return stack.hierarchy(stack.robot.q0)


def _read_scenario(path):
    from hikbench.problems.robots.scenarios import load_scenario

    return load_scenario(path)


def _valid(kind: str, tmp: Path) -> bytes:
    """A valid file of each reader, as bytes."""
    if kind == "npz":
        from hikbench.problems.files import save_npz

        save_npz(_hierarchy(), tmp / "valid.npz")
        return (tmp / "valid.npz").read_bytes()
    if kind == "soth":
        from hikbench.problems.soth import to_soth_text

        return to_soth_text(_hierarchy()).encode()
    if kind == "stack":
        return (ROOT / "problems/robots/stacks/arm_reach.toml").read_bytes()
    return {"suite": SUITE, "scenario": SCENARIO}[kind].encode()


READERS = {"npz": (_read_npz, ".npz"), "soth": (_read_soth, ".soth"), "suite": (_read_suite, ".toml"),
           "stack": (_read_stack, ".toml"), "scenario": (_read_scenario, ".toml")}


def _warm(kind: str, tmp: Path, valid: bytes) -> None:
    """The reader run once on the valid file here, before the forks: the robot model and
    the solver registry are loaded once, in the parent, and the valid file is valid."""
    path = tmp / f"valid{READERS[kind][1]}"
    path.write_bytes(valid)
    READERS[kind][0](path)


def _fuzz(kind: str, tmp_path: Path, examples: int) -> None:
    read, suffix = READERS[kind]
    valid = _valid(kind, tmp_path)
    _warm(kind, tmp_path, valid)
    strategy = byte_mutations(valid) if kind in ("npz", "soth") else toml_mutations(valid.decode())
    path = tmp_path / f"fuzzed{suffix}"
    counts: Counter = Counter()

    @settings(max_examples=examples, deadline=None, database=None,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                     HealthCheck.function_scoped_fixture])
    @given(strategy)
    def check(content: bytes):
        path.write_bytes(content)
        out = bounded(lambda: read(path), seconds=SECONDS)
        event(f"outcome: {out.kind}")
        counts[out.kind] += 1
        counts["slowest_ms"] = max(counts["slowest_ms"], int(out.seconds * 1000))
        assert out.kind in ("result", "error"), f"{out.kind}: {out.detail}\ncontent: {content[:2000]!r}"
        if out.kind == "error":
            assert "\n" not in out.detail

    check()
    print(f"fuzz {kind}: {sum(v for k, v in counts.items() if k != 'slowest_ms')} files tried: {dict(counts)}")


@pytest.mark.parametrize("kind", list(READERS))
def test_a_mutated_file_gives_a_result_or_one_hikbench_error(tmp_path, kind):
    _fuzz(kind, tmp_path, FAST)


@pytest.mark.slow
@pytest.mark.parametrize("kind", list(READERS))
def test_a_mutated_file_gives_a_result_or_one_hikbench_error_many(tmp_path, kind):
    _fuzz(kind, tmp_path, SLOW)
