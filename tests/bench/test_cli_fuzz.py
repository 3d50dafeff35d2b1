"""Fuzz test of the command line: random argument lists (commands, options, values,
valid and byte-mutated files) given to ``hikbench``. The property: exit 0, 1 or 2,
no traceback on stderr, within fuzz_tools.MEMORY bytes beyond the process's size and
SECONDS of wall time (a forked child: fuzz_tools.bounded).

`make test` runs FAST argument lists over the quick commands; the ``slow`` variant
runs SLOW ones and adds ``run`` and ``scenario``. Each test prints the exit codes it
counted (`pytest -rP`)."""

from __future__ import annotations

import shutil
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from fuzz_tools import bounded, byte_mutations
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hikbench.bench.cli import main
from hikbench.problems.hierarchy import Hierarchy, Level

ROOT = Path(__file__).resolve().parents[2]
FAST, SLOW = 40, 300
SECONDS = 60.0
QUICK = ["solve", "inspect", "generate", "export", "list", "columns", "report", "compare", "claims"]
SLOW_ONLY = ["run", "scenario"]
OPTIONS = ["--help", "-h", "--version", "--json", "--solver", "--repeat", "--warm", "--option", "--certify",
           "--seed", "--seeds", "--param", "--out", "--format", "--markdown", "--threshold", "--alpha", "--all",
           "--no-baseline", "--scenario", "--allow-missing", "--robot", "--steps", "--list", "--warm-start",
           "--suite", "--solvers", "--quiet", "--bogus", "--"]
VALUES = ["yardstick", "cascade-daqp", "nullspace", "nosuch", "0", "-1", "3", "1e9", "nan", "inf", "abc", "",
          "n=6", "n=1e12", "rows=abc", "depth=2", "k=v", "freeze=true", "npz", "soth", "equality", "random",
          "solvers", "families", "suites", "robots", "none", "stage", "error", "skip", "panda", "/nonexistent/x",
          "/dev/null", "/"]
SCENARIO = 'name = "fuzz"\nstack = "arm_reach"\nsteps = 3\n[checks]\nlimits = true\n'
SUITE = ('repeat = 1\nwarmup = 0\ntimeout = 5.0\nfirst_solve_timeout = 20.0\nmodes = ["cold"]\n'
         'solvers = ["yardstick"]\n[[problems]]\nfamily = "equality"\ngrid = { n = [4] }\n')


def _files(tmp: Path) -> dict[str, str]:
    """The named files and directories an argument list may use."""
    from hikbench.problems.files import save_npz
    from hikbench.problems.soth import save_soth

    rng = np.random.default_rng(0)
    h = Hierarchy.from_levels([Level.equality(rng.standard_normal((2, 4)), rng.standard_normal(2))])
    save_npz(h, tmp / "p.npz")
    save_soth(h, tmp / "p.soth")
    (tmp / "s.toml").write_text(SCENARIO)
    (tmp / "suite.toml").write_text(SUITE)
    shutil.copytree(ROOT / "results" / "sample", tmp / "run")
    return {"npz": str(tmp / "p.npz"), "soth": str(tmp / "p.soth"), "scenario": str(tmp / "s.toml"),
            "suite": str(tmp / "suite.toml"), "run": str(tmp / "run"), "out": str(tmp / "out"),
            "mutated": str(tmp / "mutated.npz"), "mutated_toml": str(tmp / "mutated.toml")}


NUMBERS = ["0", "-1", "1", "3", "1e9", "nan", "abc"]
SOLVERS = ["yardstick", "cascade-daqp", "nullspace", "nosuch", "yardstick,x"]
#: command -> (its positional arguments' choices, its options -> their values' choices (None: a flag))
GRAMMAR = {
    "solve": (["npz", "soth", "mutated"], {"--solver": SOLVERS, "--repeat": NUMBERS, "--warm": None,
                                           "--option": ["freeze=true", "k=v", "freeze", "tol=nan"],
                                           "--certify": None, "--json": None}),
    "inspect": (["npz", "soth", "mutated"], {"--json": None}),
    "export": (["npz", "soth", "mutated"], {"--format": ["npz", "soth", "pdf"], "--out": ["out", "/"]}),
    "generate": (["equality", "random", "nosuch"], {"--seed": NUMBERS, "--seeds": NUMBERS, "--out": ["out"],
                                                   "--param": ["n=6", "n=1e12", "rows=abc", "depth=2",
                                                               "n=-3", "rows=2"],
                                                   "--format": ["npz", "soth", "txt"]}),
    "list": (["solvers", "families", "suites", "robots", "abc"], {}),
    "columns": ([], {"--markdown": None}),
    "report": (["run", "out", "/nonexistent/x"], {}),
    "compare": (["run", "out", "mutated"], {"--threshold": NUMBERS, "--alpha": NUMBERS, "--all": None,
                                           "--no-baseline": ["error", "skip", "x"]}),
    "claims": (["run", "out"], {"--scenario": ["run", "out"], "--allow-missing": None}),
    "scenario": (["scenario", "mutated_toml", "nosuch"], {"--solver": SOLVERS, "--steps": NUMBERS,
                                                          "--robot": ["panda", "ur5", "nosuch"],
                                                          "--warm-start": ["none", "stage", "x"],
                                                          "--out": ["out"], "--list": None,
                                                          "--option": ["k=v"]}),
    "run": ([], {"--suite": ["suite", "mutated_toml", "nosuch"], "--out": ["out", "/"],
                 "--solvers": SOLVERS, "--quiet": None}),
}


def _argv(commands, files):
    """A command, its positional arguments, 0-4 of its options with values, and
    sometimes a token from anywhere (an option of another command, a bad value)."""
    def value(name):
        return files.get(name, name)

    @st.composite
    def argv(draw):
        cmd = draw(st.sampled_from(commands))
        positional, options = GRAMMAR[cmd]
        out = [cmd]
        if positional and draw(st.integers(0, 4)):
            out += [value(draw(st.sampled_from(positional))) for _ in range(draw(st.integers(1, 2)))]
        for _ in range(draw(st.integers(0, 4)) if options else 0):
            opt = draw(st.sampled_from(sorted(options)))
            out += [opt] if options[opt] is None else [opt, value(draw(st.sampled_from(options[opt])))]
        if draw(st.integers(0, 3)) == 0:
            anywhere = OPTIONS + VALUES + list(files.values())
            out.insert(draw(st.integers(1, len(out))), draw(st.sampled_from(anywhere)))
        return out
    return argv()


def _fuzz(tmp_path: Path, commands: list[str], examples: int) -> None:
    files = _files(tmp_path)
    mutations = st.one_of(byte_mutations(Path(files["npz"]).read_bytes()),
                          byte_mutations((SCENARIO + SUITE).encode()))
    codes: Counter = Counter()

    @settings(max_examples=examples, deadline=None, database=None,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                     HealthCheck.function_scoped_fixture])
    @given(_argv(commands, files), mutations)
    def check(argv, mutated):
        Path(files["mutated"]).write_bytes(mutated)
        Path(files["mutated_toml"]).write_bytes(mutated)
        out = bounded(lambda: main(argv), seconds=SECONDS)
        codes[f"{out.kind} {out.code}"] += 1
        assert out.kind == "result" and out.code in (0, 1, 2), f"{argv}: {out.kind} {out.code}: {out.detail}"
        assert "Traceback" not in out.stderr, f"{argv}:\n{out.stderr[-3000:]}"

    check()
    print(f"cli fuzz: {sum(codes.values())} argument lists tried: {dict(codes)}")


def test_random_argument_lists_exit_0_1_or_2(tmp_path):
    _fuzz(tmp_path, QUICK, FAST)


@pytest.mark.slow
def test_random_argument_lists_exit_0_1_or_2_many(tmp_path):
    _fuzz(tmp_path, QUICK + SLOW_ONLY, SLOW)
