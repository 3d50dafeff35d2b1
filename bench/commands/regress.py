"""``hikbench regress --base REV``: the timing regression gate. The suite (``ci``)
is run in rounds on the base revision and on the working tree alternately, in
one job, and each case is decided on its paired rounds' time ratios
(``hikbench.bench.analysis.regress``); docs/ci-timing.md."""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

HELP = ("time a suite on a base git revision and on the working tree, interleaved in one job; exit 1 on a "
        "significant slowdown past the threshold or a newly failing case")


def add_arguments(p) -> None:
    p.add_argument("--base", required=True, metavar="REV",
                   help="git revision to compare with (a branch, tag or commit: HEAD~1, main, origin/main)")
    p.add_argument("--suite", default="ci", help="built-in suite name or TOML file (default: ci)")
    p.add_argument("--out", default="results/regress",
                   help="folder for the rounds' runs, the base's install, regress.md and regress.json "
                        "(default: results/regress)")
    p.add_argument("--threshold", type=float, default=1.15,
                   help="flag a case only when its time ratio change/base exceeds this factor (default 1.15)")
    p.add_argument("--alpha", type=float, default=0.01,
                   help="significance level after the Benjamini-Hochberg correction over the cases "
                        "(default 0.01)")
    p.add_argument("--min-rounds", type=int, default=20,
                   help="paired rounds always run (default 20); each times every case once on each side")
    p.add_argument("--max-rounds", type=int, default=60,
                   help="paired rounds at most, the ones past --min-rounds only while a case is borderline "
                        "(default 60)")
    p.add_argument("--budget", type=float, default=150.0,
                   help="seconds of paired rounds after which no further round is started (default 150)")
    p.add_argument("--repeat", type=int, default=None,
                   help="timed repetitions per job of a paired round (default 15)")
    p.add_argument("--repo", default=".", help="the git checkout holding the base revision (default: .)")
    p.add_argument("--markdown", metavar="FILE", help="also write the Markdown table here (a PR comment)")
    p.add_argument("--json", metavar="FILE", help="also write the JSON decision here")


def _check(args) -> None:
    from hikbench.problems.errors import HikbenchError
    from hikbench.problems.schema import MAX_COUNT, MAX_SECONDS, check_at_most

    if not (1.0 < args.threshold < math.inf):
        raise HikbenchError(f"--threshold must be a finite time ratio > 1 (e.g. 1.15); got {args.threshold:g}")
    if not 0.0 < args.alpha < 1.0:
        raise HikbenchError(f"--alpha must satisfy 0 < alpha < 1 (e.g. 0.01); got {args.alpha:g}")
    if not 2 <= args.min_rounds <= args.max_rounds:
        raise HikbenchError(f"--min-rounds and --max-rounds must satisfy 2 <= min <= max; got "
                            f"{args.min_rounds} and {args.max_rounds}")
    if not (0.0 < args.budget < math.inf):
        raise HikbenchError(f"--budget must be a positive number of seconds; got {args.budget:g}")
    if args.repeat is not None and args.repeat < 2:
        raise HikbenchError(f"--repeat must be at least 2; got {args.repeat}")
    check_at_most("--repeat", args.repeat, MAX_COUNT, "timed solves per pair")
    check_at_most("--max-rounds", args.max_rounds, MAX_COUNT, "paired rounds")
    check_at_most("--budget", args.budget, MAX_SECONDS, "seconds: a week")
    suite = Path(args.suite)
    if suite.suffix == ".toml" and not suite.is_file():
        raise HikbenchError(f"--suite {args.suite}: no such file")


def _start_warm(side):
    """``hikbench warmup`` of ``side`` started in a child process (its kernels compile there)."""
    import subprocess

    return subprocess.Popen(side.command("warmup", "--quiet"), env=side.env, cwd=side.cwd, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)


def _end_warm(side, proc) -> None:
    """Wait for :func:`_start_warm`'s child; a failure is a RevisionError naming its last line."""
    from hikbench.bench.harness.revisions import RevisionError

    out, err = proc.communicate()
    if proc.returncode:
        lines = [ln for ln in err.decode(errors="replace").splitlines() if ln.strip()]
        raise RevisionError(f"`hikbench warmup` failed on {side.label}: {lines[-1].strip() if lines else ''}")
    print(f"hikbench regress: {side.label}: {out.decode().strip().removeprefix('hikbench warmup: ')}", flush=True)


def run(args) -> int:
    from hikbench.bench.analysis.regress import decide, markdown, to_json
    from hikbench.bench.harness.interleave import PairedTimer, Rounds
    from hikbench.bench.harness.revisions import install_revision, working_side

    _check(args)
    t0 = time.perf_counter()
    out = Path(args.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    suite = str(Path(args.suite).resolve()) if Path(args.suite).suffix == ".toml" else args.suite
    base = install_revision(Path(args.repo).resolve(), args.base, out / "base",
                            progress=lambda m: print(m, flush=True))
    change = working_side(out)
    # each side's full run (statuses, verification, the problem files); the change's runs while the
    # base's kernels compile, when its hcod sources differ (1-4 min): the two overlap on a 2-core runner
    warming = _start_warm(base)
    rounds = Rounds(base, change, suite, out, repeat=args.repeat)
    try:
        _end_warm(change, _start_warm(change))
        rounds.run_side("change")
    except BaseException:  # (the gate stops: the base's compile with it)
        warming.kill()
        warming.wait()
        raise
    _end_warm(base, warming)
    rounds.run_side("base")
    meta_change = _meta(out / "rounds" / "change-1" / "run.json")
    timer = PairedTimer(base, change, rounds, repeat=args.repeat or 15)
    t_rounds, dec = time.perf_counter(), None
    try:
        while timer.done < args.max_rounds:
            started = time.perf_counter()
            timer.run_round()
            lasted = time.perf_counter() - started
            if timer.done % 5 and timer.done < args.min_rounds:  # (min_rounds <= max_rounds: _check)
                continue  # (nothing to print or to decide yet)
            dec = decide(timer.frames["base"], timer.frames["change"], args.threshold, args.alpha, meta_change)
            if timer.done % 5 == 0 or timer.done >= args.min_rounds:
                print(f"hikbench regress: paired round {timer.done} in {lasted:.1f} s: {len(dec.failed)} failing, "
                      f"{len(dec.borderline)} borderline", file=sys.stderr, flush=True)
            if timer.done >= args.min_rounds and (
                    not dec.borderline or time.perf_counter() - t_rounds + lasted > args.budget):
                break
    finally:
        timer.close()
    if timer.skipped:
        dec.notes.append(f"{len(timer.skipped)} case(s) not timed in pairs (a solver outside the registry, or a "
                         f"case of one side only): {', '.join(' · '.join(map(str, k)) for k in timer.skipped[:5])}"
                         + (" ..." if len(timer.skipped) > 5 else ""))
    wall = time.perf_counter() - t0
    head = (f"### hikbench regress: {change.label} vs base {base.label}, suite {args.suite}\n\n"
            f"{'REGRESSION' if dec.failed else 'no regression'}: {len(dec.failed)} failing of {len(dec.cases)} "
            f"cases; {timer.done} paired rounds (each case on base and change back to back), {wall:.0f} s in all")
    text = markdown(dec, head)
    meta = {"base": {"revision": args.base, "label": base.label}, "change": {"label": change.label},
            "suite": args.suite, "rounds": timer.done,
            "worker_processes": {name: len(set(pids)) for name, pids in timer.pids.items()},
            "cpus": sorted(set(timer.cpus)), "wall_s": wall, "paired_s": time.perf_counter() - t_rounds,
            "run_seconds": rounds.seconds, "exit": 1 if dec.failed else 0}
    (out / "regress.md").write_text(text)
    to_json(dec, meta, out / "regress.json")
    for target, src in ((args.markdown, out / "regress.md"), (args.json, out / "regress.json")):
        if target:
            Path(target).write_text(src.read_text())
    print(text)
    print(f"hikbench regress: wrote {out / 'regress.md'} and {out / 'regress.json'}")
    return 1 if dec.failed else 0


def _meta(path: Path) -> dict:
    import json

    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return {}
