"""Option values and suite keys have ranges, checked before anything runs
(problems/schema.py MAX_COUNT, MAX_SECONDS; bench/commands/run.py max_workers);
a suite whose problems cannot fit is refused from their sizes
(problems/hierarchy.py check_sizes_fit), in one line each."""

import resource
import time

import numpy as np
import pytest
import tomli_w
from clitools import assert_user_error, run
from doubles import write_suite

from hikbench.bench.commands.run import max_workers
from hikbench.problems.errors import ProblemTooLargeError
from hikbench.problems.generators import equality_stack, random_hierarchy


@pytest.mark.parametrize("option, value, says", [
    ("--workers", "1000000", f"--workers must be <= {max_workers()} (4 worker processes per CPU"),
    ("--timeout", "1e300", "--timeout must be <= 604800 (seconds: a week); got 1e+300"),
    ("--first-solve-timeout", "1e300", "--first-solve-timeout must be <= 604800"),
    ("--repeat", "1000000000000", "--repeat must be <= 1000000 (timed solves per row); got 1000000000000"),
    ("--rounds", "10000000", "--rounds must be <= 1000000"),
], ids=["workers", "timeout", "first-solve-timeout", "repeat", "rounds"])
def test_a_run_option_out_of_range_is_one_line(tmp_path, capsys, option, value, says):
    suite = write_suite(tmp_path / "s.toml", ["yardstick"], grid={"n": [4]}, repeat=1, modes=("cold",))
    code, _, err = run(capsys, "run", "--quiet", "--suite", suite, "--out", tmp_path / "o", option, value)
    assert_user_error(code, err, says)
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("argv, says", [
    (["solve", "{p}", "--repeat", "1000000000000"], "--repeat must be <= 1000000 (timed solves)"),
    (["regress", "--base", "HEAD", "--out", "{d}", "--budget", "1e300"], "--budget must be <= 604800"),
], ids=["solve repeat", "regress budget"])
def test_another_command_s_option_out_of_range_is_one_line(tmp_path, capsys, argv, says):
    from hikbench.problems.files import save_npz
    save_npz(equality_stack(4, 1, 2), tmp_path / "p.npz")
    code, _, err = run(capsys, *[a.format(p=tmp_path / "p.npz", d=tmp_path / "r") for a in argv])
    assert_user_error(code, err, says)


@pytest.mark.parametrize("key, value, says", [
    ("timeout", 1e300, "timeout = 1e+300: expected a number of seconds > 0 and <= 604800 (a week)"),
    ("repeat", 10**12, "repeat = 1000000000000: expected an integer >= 1 and <= 1000000"),
    ("samples", 10**12, "samples = 1000000000000: expected an integer >= 1 and <= 1000000"),
    ("warmup", 10**12, "warmup = 1000000000000: expected an integer >= 0 and <= 1000000"),
], ids=["timeout", "repeat", "samples", "warmup"])
def test_a_suite_key_out_of_range_is_one_line(tmp_path, capsys, key, value, says):
    suite = tmp_path / "s.toml"
    suite.write_text(tomli_w.dumps({key: value, "solvers": ["yardstick"], "modes": ["cold"],
                                    "problems": [{"family": "equality", "seeds": [0]}]}))
    code, _, err = run(capsys, "run", "--quiet", "--suite", suite, "--out", tmp_path / "o")
    assert_user_error(code, err, f"suite {suite}", says)


def test_a_suite_of_huge_depth_is_refused_from_its_sizes(tmp_path, capsys):
    """It grew to 5.7 GB before a MemoryError."""
    suite = tmp_path / "s.toml"
    suite.write_text(tomli_w.dumps({"solvers": ["yardstick"], "modes": ["cold"], "problems": [
        {"family": "random", "params": {"n": 6, "depth": 10**9, "rows": 2}, "seeds": [0]}]}))
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    t0 = time.monotonic()
    code, _, err = run(capsys, "run", "--quiet", "--suite", suite, "--out", tmp_path / "o")
    assert time.monotonic() - t0 < 30
    assert (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before) * 1024 < 500e6
    assert_user_error(code, err, "problem random/depth=1000000000,n=6,rows=2/seed=0: random_hierarchy: depth = ",
                      "rows of n = 6 variables need", "more than half of this machine's")


@pytest.mark.parametrize("make", [
    lambda: random_hierarchy(6, 10**9, 2),
    lambda: random_hierarchy(6, 2, [10**12, 1]),
    lambda: equality_stack(10, 10**9, 3),
], ids=["random depth", "random rows", "equality depth"])
def test_a_generator_refuses_sizes_beyond_memory_before_making_a_level(make):
    with pytest.raises(ProblemTooLargeError, match="more than half of this machine's"):
        make()


def test_a_deep_hierarchy_within_memory_is_made():
    h = random_hierarchy(8, 300, 2, seed=0)
    assert h.A.shape == (600, 8) and np.isfinite(h.A).all()


def test_a_large_soth_file_refused_at_its_third_token_takes_no_memory_for_its_tokens(tmp_path, capsys):
    """A 40 MB SOTH file refused at its third token first listed every token (1.64 GB)."""
    import tracemalloc

    from hikbench.problems.errors import ProblemFileError
    from hikbench.problems.soth import from_soth_text

    text = "variable size many\n" + "1.0 " * 10_000_000
    tracemalloc.start()
    try:
        with pytest.raises(ProblemFileError, match=r"<soth text>: line 1: expected the number of variables n "
                                                   r"\(a nonnegative integer\), got 'many'"):
            from_soth_text(text)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 10e6, peak
