"""``hikbench run [--suite NAME|FILE] [--solvers ...] [--out DIR] [--repeat R]
[--timeout S] [--workers N | --scheduler ADDR] [--rerun] [--quiet] [--limit N]``."""

from __future__ import annotations

from problems.errors import HikbenchError

HELP = "run a benchmark suite; rows are appended to OUT/results.csv and the run resumes where it stopped"


def add_arguments(p) -> None:
    p.add_argument("--suite", default="quick", help="built-in suite name (quick, paper, peers, full, ci) "
                   "or a TOML file (default: quick)")
    p.add_argument("--solvers", nargs="+", default=None, metavar="SOLVER",
                   help="replace the suite's solvers: names, glob patterns ('cascade-*'), module:Class, "
                        "or external:NAME=CMD")
    p.add_argument("--out", default=None, help="output directory (default: results/<suite>)")
    p.add_argument("--repeat", type=int, default=None,
                   help="timed repetitions per row (default: the suite's)")
    p.add_argument("--timeout", type=float, default=None,
                   help="hard limit per job in seconds, warm-up and repetitions included "
                        "(default: the suite's)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--workers", type=int, default=None,
                   help="run on a local Dask cluster of N single-threaded worker processes")
    g.add_argument("--scheduler", default=None, metavar="ADDR",
                   help="run on an existing Dask cluster, e.g. tcp://host:8786")
    p.add_argument("--rerun", action="store_true",
                   help="run finished rows again (the old results.csv is kept as results.csv.bak)")
    p.add_argument("--limit", type=int, default=None, help="stop after N new rows (resume later)")
    p.add_argument("--quiet", action="store_true", help="no progress bar (CI)")


def run(args) -> int:
    from pathlib import Path

    from bench.runner import run_suite
    from bench.suites import load_suite

    suite = load_suite(args.suite)
    if args.repeat is not None and args.repeat < 1:
        raise HikbenchError(f"--repeat must be >= 1; got {args.repeat}")
    if args.timeout is not None and args.timeout <= 0:
        raise HikbenchError(f"--timeout must be > 0; got {args.timeout}")
    if args.workers is not None and args.workers < 1:
        raise HikbenchError(f"--workers must be >= 1; got {args.workers}")
    out = Path(args.out or f"results/{suite.name}")
    executor = None
    if args.workers or args.scheduler:
        from bench.executors import DaskExecutor
        executor = DaskExecutor(workers=args.workers, scheduler=args.scheduler)
    try:
        s = run_suite(suite, out, solvers=args.solvers, repeat=args.repeat, timeout=args.timeout,
                      rerun=args.rerun, executor=executor, quiet=args.quiet, limit=args.limit)
    finally:
        if executor is not None:
            executor.close()
    statuses = ", ".join(f"{k} {v}" for k, v in sorted(s.statuses.items())) or "none"
    print(f"hikbench run: suite {suite.name}: {s.total} rows in the suite, "
          f"{s.skipped_finished} already done, "
          f"{s.written} written ({statuses}) -> {out / 'results.csv'}")
    return 0
