"""``hikbench certify RUN [--workers N] [--quiet]``: certify the recorded steps of a scenario run
after the fact (bench/scenarios/certify_run.py): every step's u, in N worker processes, resumable;
results in ``RUN/<run>_certificates.csv``, beside each run's per-step CSV.

Exit status: 0 when every step is certified and its u attains the exact optimum, or the certificate
refused a step (a refusal cannot tell: the summary says why); 1 when a certified step's u is above
its exact optimum at the high profile; 2 for bad input (not a run folder, a missing or unreadable
file).
"""

from __future__ import annotations

HELP = "certify a scenario run's recorded steps exactly, after the fact (parallel, resumable)"


def add_arguments(p) -> None:
    p.add_argument("run", metavar="RUN",
                   help="the --out folder of `hikbench scenario` (its <run>_steps/ folders: each step's problem and u)")
    p.add_argument("--workers", type=int, default=2, metavar="N", help="worker processes (default 2)")
    p.add_argument("--quiet", action="store_true", help="print only the summary line")


def run(args) -> int:
    from hikbench.bench.scenarios.certify_run import certify_run
    from hikbench.problems.errors import HikbenchError

    if args.workers < 1:
        raise HikbenchError(f"--workers must be >= 1; got {args.workers}")
    s = certify_run(args.run, workers=args.workers, log=None if args.quiet else __import__("sys").stderr)
    minutes, seconds = divmod(s.wall_s, 60)
    line = (f"hikbench certify {args.run}: {s.certified} of {s.steps} steps certified, x attains the exact optimum "
            f"on {s.attains}" + (f", above it on {len(s.not_optimal)} (first: {s.not_optimal[0][0]} step "
                                 f"{s.not_optimal[0][1]}, level {s.not_optimal[0][2]})" if s.not_optimal else "")
            + (f", {len(s.refused)} refused (first: {s.refused[0][0]} step {s.refused[0][1]}: {s.refused[0][2]})"
               if s.refused else "")
            + f"; {s.done_now} certified now, {s.resumed} before; {int(minutes)} min {seconds:.1f} s with "
              f"{args.workers} worker(s) -> " + ", ".join(str(f) for f in s.files))
    print(line, flush=True)
    return 1 if s.not_optimal else 0
