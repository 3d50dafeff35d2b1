"""``hikbench compare BASE RUN [RUN ...] [--threshold 1.15] [--alpha 0.01] [--all] [--no-baseline error|skip]``."""

from __future__ import annotations

import math
from pathlib import Path

HELP = ("compare a run (or several: a case must fail in all) with a baseline run; exit 1 on a significant "
        "slowdown, a newly failing case or a missing one")


def add_arguments(p) -> None:
    p.add_argument("base", help="baseline run directory, or a directory of baselines (one subdirectory per "
                                "machine class: the one recorded on the first RUN's class is used)")
    p.add_argument("run", nargs="+", help="new run directory; with several, a case fails only if it fails "
                                         "in every one (confirmation re-runs in CI)")
    p.add_argument("--threshold", type=float, default=1.15,
                   help="flag a case whose normalised median (and minimum) time grew by more than this "
                        "factor beyond the calibration kernel's spread (default 1.15)")
    p.add_argument("--alpha", type=float, default=0.01,
                   help="significance level of a SLOWER or faster verdict: q, the larger p of the Mann-Whitney "
                        "test over the samples and of the test against the cases' run-to-run spread, adjusted "
                        "over the cases (Benjamini-Hochberg; default 0.01)")
    p.add_argument("--all", action="store_true", help="print every compared case")
    p.add_argument("--no-baseline", choices=("error", "skip"), default="error",
                   help="when BASE is a directory of baselines and none is of RUN's machine class: an error "
                        "(exit 2, the default), or skip: say so and exit 0 without comparing")


def run(args) -> int:
    from hikbench.bench.analysis.compare import (
        NoBaseline,
        baseline_for,
        compare_runs,
        confirmed,
        format_table,
        machine_class_of,
    )
    from hikbench.problems.errors import HikbenchError

    if not (1.0 < args.threshold < math.inf):  # also refuses nan
        raise HikbenchError(f"--threshold must be a finite number > 1 (a time ratio); got {args.threshold:g}")
    if not 0.0 < args.alpha < 1.0:
        raise HikbenchError(f"--alpha must be a significance level with 0 < alpha < 1 (e.g. 0.01); "
                            f"got {args.alpha:g}")
    try:
        base = baseline_for(args.base, args.run[0])
    except NoBaseline as err:
        if args.no_baseline == "error":
            raise
        print(f"compare skipped: {err}")
        return 0
    if base != Path(args.base):
        print(f"baseline: {base} (machine class {machine_class_of(base)!r})")
    c = confirmed([compare_runs(base, r, threshold=args.threshold, alpha=args.alpha) for r in args.run])
    print(format_table(c, show_all=args.all))
    print(f"\ncompared {len(c.table) - len(c.missing)} cases (times normalised by the calibration kernel): "
          f"{len(c.slowdowns)} slower (> {args.threshold:g}x beyond the calibration's spread, q < {args.alpha:g}), "
          f"{len(c.new_failures)} newly failing, {len(c.missing)} missing, "
          f"{len(c.inconclusive)} inconclusive (past the threshold, not beyond the spreads), "
          f"{int((c.table['verdict'] == 'faster').sum())} faster; "
          f"{len(c.only_base)} only in base, {len(c.only_new)} only in the new run")
    print(c.spreads())
    for note in c.notes:
        print(f"note: {note}")
    return 1 if c.failed else 0
