"""``hikbench report RUN``: write RUN/report.md and RUN/plots/*.png."""

from __future__ import annotations

HELP = "write report.md and PNG plots for a run directory"


def add_arguments(p) -> None:
    p.add_argument("run_dir", help="directory written by `hikbench run` (holds results.csv)")


def run(args) -> int:
    from hikbench.bench.analysis.report import write_report

    out = write_report(args.run_dir)
    print(f"hikbench report: wrote {out} and {out.parent / 'plots'}/")
    return 0
