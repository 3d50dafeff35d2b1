"""``hikbench testset build|check|add``: the versioned test sets of docs/testset.md."""

from __future__ import annotations

import random
import sys
from pathlib import Path

from hikbench.problems.errors import HikbenchError

HELP = "build, check (hashes, re-certification) or grow a test set of certified problems (docs/testset.md)"

#: the closed-loop runs of hlsp-1: (scenario, robot name or a .urdf path relative to the robots package,
#: every k-th step, at most this many active-set-change steps (None: all), sequence length). The humanoid
#: runs are sampled more thinly: 700 steps of 117 rows and more each
ARM, HUMANOID = (5, None, 50), (50, 12, 25)
ROBOT_RUNS = (("arm_reach", "panda", *ARM), ("arm_reach", "arm7.urdf", *ARM), ("reach", "talos", *HUMANOID),
              ("step", "talos", *HUMANOID), ("reach", "romeo", *HUMANOID), ("step", "romeo", *HUMANOID),
              ("reach", "g1", *HUMANOID),
              ("step", "g1", *HUMANOID))
PARTS = ("hard", "sweeps", "peers", "robots")


def add_arguments(p) -> None:
    sub = p.add_subparsers(dest="action", metavar="ACTION", required=True,
                           help="build, check or add (each has its own --help)")
    b = sub.add_parser("build", help="generate, certify and write hlsp-1")
    b.add_argument("--out", type=Path, default=None, help="the set's folder (default: this tree's "
                   "problems/testset/hlsp-1)")
    b.add_argument("--nipm", type=Path, default=None, help="NIPM-HLSP's source folder: its tests/test1.cpp cases "
                   "join the set (without it they do not)")
    b.add_argument("--lexls", type=Path, default=None, help="LexLS's source folder: its tests/*.dat problems join "
                   "the set (a clone of jrl-umi3218/lexls; the release snapshot leaves them out)")
    b.add_argument("--parts", nargs="+", choices=PARTS, default=list(PARTS), help="which parts (default all)")
    b.add_argument("--runs", nargs="+", default=None, metavar="SCENARIO:ROBOT",
                   help="closed-loop runs (default: " + " ".join(f"{r[0]}:{r[1]}" for r in ROBOT_RUNS) + ")")
    b.add_argument("--steps", type=int, default=None, help="control steps of each run (default: the scenario's)")
    b.add_argument("--every", type=int, default=None, help="every k-th control step (default: 5 on the arms, "
                   "50 on the humanoids)")
    b.add_argument("--max-changes", type=int, default=None, help="at most this many active-set-change steps "
                   "per run (default: all on the arms, 12 on the humanoids)")
    b.add_argument("--sequence", type=int, default=None, help="consecutive steps kept as a sequence (default: "
                   "50 on the arms, 25 on the humanoids)")
    b.add_argument("--budget", type=float, default=60.0, help="leave out a problem whose certificate is "
                   "estimated to take longer (s, default 60)")
    b.add_argument("--workers", type=int, default=2, help="certificate processes (default 2)")
    b.add_argument("--cache", type=Path, default=None, help="earlier certificates, reused and appended to "
                   "(default: ~/.cache/hikbench/testset-certificates.jsonl)")
    b.add_argument("--no-cache", action="store_true", help="certify every candidate again")
    c = sub.add_parser("check", help="verify a set's hashes; re-certify a sample of it")
    c.add_argument("set", nargs="?", default="hlsp-1", help="a shipped set's name or a folder (default hlsp-1)")
    c.add_argument("--recertify", type=int, default=0, metavar="K", help="re-certify K problems drawn at random")
    c.add_argument("--all", action="store_true", help="re-certify every problem")
    c.add_argument("--seed", type=int, default=0, help="seed of the sample (default 0)")
    c.add_argument("--workers", type=int, default=2, help="certificate processes (default 2)")
    a = sub.add_parser("add", help="turn problem files or a scenario's steps into certified candidates")
    a.add_argument("inputs", nargs="*", type=Path, default=[], help="problem files: .npz, SOTH text, LexLS .dat")
    a.add_argument("--out", type=Path, required=True, help="the candidates' folder (written in the set format)")
    a.add_argument("--scenario", default=None, help="record this scenario's control steps (a name or a .toml)")
    a.add_argument("--robot", default=None, help="the scenario's robot (a name or a .urdf path)")
    a.add_argument("--steps", type=int, default=None, help="control steps (default: the scenario's)")
    a.add_argument("--every", type=int, default=10, help="every k-th control step (default 10)")
    a.add_argument("--sequence", type=int, default=50, help="consecutive steps kept as a sequence (default 50)")
    a.add_argument("--budget", type=float, default=600.0, help="certificate time cap per problem (s, default 600)")
    a.add_argument("--workers", type=int, default=2, help="certificate processes (default 2)")


def _robot_path(robot: str) -> str:
    """A robot name, or a .urdf shipped in hikbench.problems.robots (``arm7.urdf``) or given by path."""
    if robot.endswith(".urdf") and not Path(robot).exists():
        from hikbench.problems import robots
        shipped = Path(robots.__file__).parent / robot
        if shipped.exists():
            return str(shipped)
        raise HikbenchError(f"robot {robot!r}: no such .urdf file (nor one shipped in {shipped.parent})")
    return robot


def _runs(specs, every=None, max_changes=None, sequence=None) -> list[tuple]:
    """(scenario, robot, every, max_changes, sequence) of each run; the options given replace
    the runs' own (a run of ``--runs`` takes the arms' defaults)."""
    runs = list(ROBOT_RUNS) if specs is None else []
    for s in specs or ():
        scen, sep, robot = s.partition(":")
        if not sep or not scen or not robot:
            raise HikbenchError(f"--runs {s!r}: expected SCENARIO:ROBOT (arm_reach:panda)")
        runs.append((scen, robot, *ARM))
    return [(sc, rb, every or e, m if max_changes is None else max_changes, s if sequence is None else sequence)
            for sc, rb, e, m, s in runs]


def _positive(v, name: str) -> None:
    if v is not None and v < 1:
        raise HikbenchError(f"{name} must be >= 1; got {v}")


def run(args) -> int:
    for name in ("workers", "steps", "every", "sequence"):
        _positive(getattr(args, name, None), f"--{name}")
    return {"build": _build, "check": _check, "add": _add}[args.action](args)


def _robot_cands(runs, steps, budget, excluded) -> list:
    from hikbench.bench.testset.build import robot_candidates
    from hikbench.problems.exact import estimated_seconds

    cands = []
    for scen, robot, every, max_changes, sequence in runs:
        got = robot_candidates(scen, _robot_path(robot), label=Path(robot).stem, steps=steps, every=every,
                               sequence=sequence, max_changes=max_changes)
        est = max((estimated_seconds(c.hierarchy) for c in got), default=0.0)
        print(f"hikbench testset: {scen} on {robot}: {len(got)} steps selected (certificate estimated up to "
              f"{est:.1f} s each)", file=sys.stderr, flush=True)
        if est > budget:
            excluded.append({"id": f"robot/{scen}/{Path(robot).stem}", "family": f"robot:{scen}",
                             "reason": f"the run's {len(got)} selected steps left out: certificate estimated at "
                                       f"up to {est:.0f} s each, beyond the budget {budget:g} s",
                             "provenance": {"scenario": scen, "robot": robot}})
            continue
        cands += got
    return cands


def _build(args) -> int:
    from hikbench.bench.testset import build as B

    out = args.out or B.default_folder()
    cands, excluded = [], []
    if "hard" in args.parts:
        cands += B.hard_candidates()
    if "sweeps" in args.parts:
        cands += B.sweep_candidates()
    if "peers" in args.parts and args.nipm is not None:
        cands += B.nipm_candidates(args.nipm)
    if "peers" in args.parts and args.lexls is not None:
        cands += B.lexls_candidates(args.lexls)
    if "robots" in args.parts:
        cands += _robot_cands(_runs(args.runs, args.every, args.max_changes, args.sequence), args.steps, args.budget,
                              excluded)
    cache = None if args.no_cache else (args.cache or B.default_cache())
    outcomes = B.certify_candidates(cands, workers=args.workers, budget=args.budget, cache=cache)
    ts = B.write_set(out, "hlsp-1", outcomes, description=(
        "HLSP-1: hierarchical least-squares problems (hard cases on exact data, DOF and depth sweeps, the "
        "peers' cases, control steps of closed-loop robot scenarios), each with its certified optimum"),
        extra_excluded=excluded)
    robots = sum(e.family.startswith("robot:") for e in ts.entries)
    print(f"hikbench testset: {len(ts)} problems certified in {out} ({robots} robot control steps, "
          f"{len(ts.sequences)} sequences); {len(cands) - len(ts)} candidate(s) left out "
          f"(manifest: excluded)")
    return 0


def _check(args) -> int:
    from hikbench.bench.testset.build import recertify
    from hikbench.problems.testset import TestSet

    ts = TestSet.read(args.set)
    bad = ts.check_hashes()
    for line in bad:
        print(f"hikbench testset check: {line}", file=sys.stderr)
    print(f"hikbench testset check: {ts.name}: {len(ts)} problems, {len(ts) - len(bad)} files match the manifest's "
          f"SHA-256" if not bad else f"hikbench testset check: {ts.name}: {len(bad)} file(s) disagree")
    sample = list(ts.entries) if args.all else random.Random(args.seed).sample(
        ts.entries, min(args.recertify, len(ts)))
    if sample:
        wrong = recertify(ts, sample, workers=args.workers)
        for line in wrong:
            print(f"hikbench testset check: {line}", file=sys.stderr)
        print(f"hikbench testset check: {len(sample) - len(wrong)}/{len(sample)} re-certified with the stored "
              f"optimum")
        bad += wrong
    return 1 if bad else 0


def _add(args) -> int:
    from hikbench.bench.testset import build as B

    if not args.inputs and args.scenario is None:
        raise HikbenchError("hikbench testset add: give problem files or --scenario NAME")
    cands = B.problem_candidates(args.inputs) if args.inputs else []
    if args.scenario is not None:
        robot = args.robot or None
        cands += B.robot_candidates(args.scenario, _robot_path(robot) if robot else None,
                                    label=Path(robot).stem if robot else "default", steps=args.steps,
                                    every=args.every, sequence=args.sequence)
    outcomes = B.certify_candidates(cands, workers=args.workers, budget=args.budget)
    ts = B.write_set(args.out, "candidates", outcomes, description="candidate problems for the next test set")
    print(f"hikbench testset add: {len(ts)} of {len(cands)} candidates certified, written to {args.out}")
    return 0
