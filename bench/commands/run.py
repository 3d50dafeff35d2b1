"""``hikbench run [--suite NAME|FILE] [--solvers ...] [--out DIR] [--accuracy PROFILE] [--repeat R]
[--rounds K] [--timeout S] [--first-solve-timeout S] [--workers N | --scheduler ADDR] [--rerun] [--quiet] [--limit N]``."""

from __future__ import annotations

import os
from pathlib import Path

from hikbench.problems.errors import HikbenchError
from hikbench.problems.schema import MAX_COUNT, MAX_SECONDS, check_at_most

HELP = "run a benchmark suite; rows are appended to OUT/results.csv and the run resumes where it stopped"


def add_arguments(p) -> None:
    names = sorted(f.stem for f in (Path(__file__).parents[1] / "suites").glob("*.toml"))  # (hikbench.bench.suites'
    # builtin_suites(), without importing the solvers on every command's start)
    p.add_argument("--suite", default="quick", help=f"built-in suite name ({', '.join(names)}; "
                   f"`hikbench list suites` says what each holds) or a TOML file (default: quick)")
    p.add_argument("--solvers", "--solver", nargs="+", action="extend", default=None, metavar="SOLVER",
                   help="replace the suite's solvers (repeatable: `--solver a --solver b` takes both): names, "
                        "glob patterns ('cascade-*'), module:Class, "
                        "or external:NAME=CMD (external:NAME[strict=false]=CMD: a program that does not "
                        "claim the lexicographic optimum)")
    p.add_argument("--out", default=None, help="output directory (default: results/<suite>)")
    p.add_argument("--accuracy", default=None, choices=("high", "default", "low"),
                   help="the headline accuracy profile: column `verified` and the ranking's order (default: "
                        "the suite's `accuracy`, default); every row records its verdict at each profile "
                        "(verified_high, verified_default, verified_low; docs/verification.md)")
    p.add_argument("--repeat", type=int, default=None, metavar="R",
                   help="exactly R timed repetitions per row (default: the suite's repeat, and up to its "
                        "samples for a fast solve: 100 for a solve under 1 ms in quick)")
    p.add_argument("--rounds", type=int, default=None,
                   help="split each row's repetitions over K rounds, each round running every job once, so "
                        "that a slow moment of the machine shifts part of every row, not whole rows "
                        "(1 <= K <= repeat; default: the suite's, 1)")
    p.add_argument("--timeout", type=float, default=None,
                   help="hard limit per job in seconds, warm-up and repetitions included; with --rounds, "
                        "per round (default: the suite's). A solver's first solve in a worker (numba "
                        "compilation) has its own allowance, --first-solve-timeout")
    p.add_argument("--first-solve-timeout", type=float, default=None, metavar="S",
                   help="allowance in seconds for a solver's first, untimed solve in a worker process, "
                        "when larger than --timeout (default: the suite's first_solve_timeout, 300); a "
                        "solver that hangs on its first problem costs this once")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--workers", type=int, default=None,
                   help="run on a local Dask cluster of N single-threaded worker processes")
    g.add_argument("--scheduler", default=None, metavar="ADDR",
                   help="run on an existing Dask cluster, e.g. tcp://host:8786")
    p.add_argument("--rerun", action="store_true",
                   help="run finished rows again; each re-run row replaces its old one, the others are "
                        "kept, and the previous results.csv is first copied to a new backup "
                        "(results.csv.bak, results.csv.bak.1, ...)")
    p.add_argument("--limit", type=int, default=None,
                   help="stop after N new rows, a suite's scenario rows after its problem rows (N >= 0; resume later)")
    p.add_argument("--quiet", action="store_true", help="no progress bar (CI)")


def max_workers() -> int:
    """The largest --workers: 4 local worker processes per CPU (each holds a Dask worker and its
    isolated solve process; more only compete for the same CPUs, and grow the run's memory)."""
    return 4 * (os.cpu_count() or 1)


def _check_args(args) -> None:
    """Bad option values: one-line HikbenchError naming the option (exit 2)."""
    import math

    if args.repeat is not None and args.repeat < 1:
        raise HikbenchError(f"--repeat must be >= 1; got {args.repeat}")
    if args.rounds is not None and args.rounds < 1:
        raise HikbenchError(f"--rounds must be >= 1; got {args.rounds}")
    if args.timeout is not None and not (math.isfinite(args.timeout) and args.timeout > 0):
        raise HikbenchError(f"--timeout must be a number of seconds > 0; got {args.timeout}")
    fst = args.first_solve_timeout
    if fst is not None and not (math.isfinite(fst) and fst > 0):
        raise HikbenchError(f"--first-solve-timeout must be a number of seconds > 0; got {fst}")
    if args.workers is not None and args.workers < 1:
        raise HikbenchError(f"--workers must be >= 1; got {args.workers}")
    if args.limit is not None and args.limit < 0:
        raise HikbenchError(f"--limit must be >= 0 (new rows to write before stopping); got {args.limit}")
    check_at_most("--repeat", args.repeat, MAX_COUNT, "timed solves per row")
    check_at_most("--rounds", args.rounds, MAX_COUNT, "rounds per row")
    check_at_most("--timeout", args.timeout, MAX_SECONDS, "seconds: a week")
    check_at_most("--first-solve-timeout", fst, MAX_SECONDS, "seconds: a week")
    check_at_most("--workers", args.workers, max_workers(), f"4 worker processes per CPU of this machine's "
                                                           f"{os.cpu_count() or 1}")
    if args.scheduler is not None:
        from hikbench.bench.harness.executors import _check_scheduler_address
        _check_scheduler_address(args.scheduler)


def _check_out(out) -> None:
    """--out must be (or be creatable as) a directory; it is created by the run."""
    for d in (out, *out.parents):
        if d.exists():
            if not d.is_dir():
                what = "exists" if d == out else f"is under {d}, which exists"
                raise HikbenchError(f"--out {out}: {what} and is not a directory; expected an output directory")
            return


def run(args) -> int:
    import dataclasses
    from pathlib import Path

    from hikbench.bench.harness.runner import run_suite
    from hikbench.bench.suites import load_suite

    _check_args(args)
    suite = load_suite(args.suite)
    if args.first_solve_timeout is not None:
        suite = dataclasses.replace(suite, first_solve_timeout=args.first_solve_timeout)
    out = Path(args.out or f"results/{suite.name}")
    _check_out(out)
    executor = None
    if args.workers or args.scheduler:
        from hikbench.bench.harness.executors import DaskExecutor
        executor = DaskExecutor(workers=args.workers, scheduler=args.scheduler)
    try:
        s = run_suite(suite, out, solvers=args.solvers, repeat=args.repeat, timeout=args.timeout,
                      rounds=args.rounds, rerun=args.rerun, executor=executor, quiet=args.quiet, limit=args.limit,
                      accuracy=args.accuracy)
    finally:
        if executor is not None:
            executor.close()
    statuses = ", ".join(f"{k} {v}" for k, v in sorted(s.statuses.items())) or "none"
    print(f"hikbench run: suite {suite.name}: {s.total} rows in the suite, "
          f"{s.skipped_finished} already done, "
          f"{s.written} written ({statuses}) -> {out / 'results.csv'}")
    if s.scenario_runs:
        st = ", ".join(f"{k} {v}" for k, v in sorted(s.scenario_statuses.items())) or "none"
        print(f"hikbench run: suite {suite.name}: {s.scenario_runs} scenario runs in the suite, "
              f"{s.scenario_skipped_finished} already done, {s.scenario_written} written ({st}) "
              f"-> {out / 'scenarios.csv'}")
    return 0
