"""``hikbench claims RUN [--scenario CSV] [--allow-missing]``."""

from __future__ import annotations

HELP = ("check the ICRA 2010 paper's claims on a run (PASS / FAIL / MISSING); exit 1 on FAIL, "
        "and on MISSING unless --allow-missing")


def add_arguments(p) -> None:
    p.add_argument("run_dir", help="run directory (use the `paper` suite for claims a-c)")
    p.add_argument("--scenario", default=None,
                   help="per-step CSV(s) of the reach scenario for claims d-e: a file or a directory "
                        "(default: the reach*.csv of RUN/scenarios/reach/, RUN/scenarios/, RUN/, "
                        "else results/scenarios/reach/, where `hikbench scenario reach` writes them)")
    p.add_argument("--allow-missing", action="store_true",
                   help="a claim without data does not fail the command")


def run(args) -> int:
    from hikbench.bench.analysis.claims import FAIL, MISSING, check_claims

    claims = check_claims(args.run_dir, args.scenario)
    print("### Claims of the ICRA 2010 paper")
    print()
    print("| claim | result | measured | paper | criterion |")
    print("|---|---|---|---|---|")
    for c in claims:
        print(f"| {c.name} | {c.status} | {c.measured} | {c.paper} | {c.criterion} |")
    failed = any(c.status == FAIL for c in claims)
    missing = any(c.status == MISSING for c in claims)
    return 1 if failed or (missing and not args.allow_missing) else 0
