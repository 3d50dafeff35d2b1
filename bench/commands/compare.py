"""``hikbench compare BASE RUN [RUN ...] [--threshold 1.15] [--alpha 0.01] [--all]``."""

from __future__ import annotations

import math

HELP = ("compare a run (or several: a case must fail in all) with a baseline run; exit 1 on a significant "
        "slowdown, a newly failing case or a missing one")


def add_arguments(p) -> None:
    p.add_argument("base", help="baseline run directory")
    p.add_argument("run", nargs="+", help="new run directory; with several, a case fails only if it fails "
                                         "in every one (confirmation re-runs in CI)")
    p.add_argument("--threshold", type=float, default=1.15,
                   help="flag a case whose normalised median (and minimum) time grew by more than this "
                        "factor (default 1.15)")
    p.add_argument("--alpha", type=float, default=0.01,
                   help="significance level of the one-sided Mann-Whitney test (default 0.01)")
    p.add_argument("--all", action="store_true", help="print every compared case")


def run(args) -> int:
    from bench.compare import compare_runs, confirmed, format_table
    from problems.errors import HikbenchError

    if not (1.0 < args.threshold < math.inf):  # also refuses nan
        raise HikbenchError(f"--threshold must be a finite number > 1 (a time ratio); got {args.threshold:g}")
    if not 0.0 < args.alpha < 1.0:
        raise HikbenchError(f"--alpha must be a significance level with 0 < alpha < 1 (e.g. 0.01); "
                            f"got {args.alpha:g}")
    c = confirmed([compare_runs(args.base, r, threshold=args.threshold, alpha=args.alpha) for r in args.run])
    print(format_table(c, show_all=args.all))
    print(f"\ncompared {len(c.table) - len(c.missing)} cases (times normalised by the calibration kernel): "
          f"{len(c.slowdowns)} slower (> {args.threshold:g}x, p < {args.alpha:g}), "
          f"{len(c.new_failures)} newly failing, {len(c.missing)} missing, "
          f"{len(c.inconclusive)} inconclusive (past the threshold, p >= {args.alpha:g}), "
          f"{int((c.table['verdict'] == 'faster').sum())} faster; "
          f"{len(c.only_base)} only in base, {len(c.only_new)} only in the new run")
    for note in c.notes:
        print(f"note: {note}")
    return 1 if c.failed else 0
