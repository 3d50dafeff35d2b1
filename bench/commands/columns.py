"""``hikbench columns [--markdown]``: the documented columns of results.csv."""

from __future__ import annotations

HELP = "describe every column of results.csv"


def add_arguments(p) -> None:
    p.add_argument("--markdown", action="store_true", help="print a markdown table (as in docs/columns.md)")


def run(args) -> int:
    from hikbench.bench.harness.columns import COLUMNS, markdown

    if args.markdown:
        print(markdown())
        return 0
    width = max(len(c) for c, _ in COLUMNS)
    for c, d in COLUMNS:
        print(f"{c:<{width}}  {d}")
    return 0
