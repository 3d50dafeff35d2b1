"""``hikbench scenario NAME [--robot R|PATH.urdf [--srdf PATH] [--floating-base] [--reference NAME]]
[--frame ALIAS=FRAME ...] --solver S [--solver S2 ...] [--warm-start MODE ...]
[--[no-]interleave] [--steps K] [--repeat R] [--resolve] [--out DIR] [--plot] [--option KEY=VALUE ...]``.

Runs a closed-loop robot scenario (``problems/robots/scenarios/NAME.toml`` or a
TOML path) once per (solver, warm-start mode) -- several modes of one solver
interleaved step by step in one process unless ``--no-interleave``
(:func:`hikbench.bench.scenarios.runner.run_interleaved`) --, writes one per-step CSV per run
(columns documented in ``bench/scenarios/runner.py``), ``summary.csv`` (one row per
run: cost per step, max and final task errors by level, checks) and, with
``--plot``, the figures of ICRA 2010 sec. XII; prints the scenario's checks and,
for several runs, their task errors by level side by side. A solver is a
registered one, ``module:Class`` / ``file.py:Class``, or a scenario controller
(``pink``: bench/scenarios/controllers.py). Exit code 1 when a check fails.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from hikbench.bench.commands.solve import parse_options
from hikbench.problems.errors import HikbenchError
from hikbench.problems.schema import MAX_COUNT, check_at_most

#: the solver of a scenario run without --solver: the strict hierarchy solver a controller would run
DEFAULT_SOLVER = "hcod"
HELP = "run a closed-loop robot scenario (reach, step, or a TOML file) and write CSV + figures"


def add_arguments(p) -> None:
    p.add_argument("name", nargs="?", default=None,
                   help="scenario name (reach, step, ...) or path of a scenario .toml; "
                        "`hikbench scenario --list` lists them")
    p.add_argument("--robot", default=None, metavar="NAME|PATH.urdf",
                   help="run on another robot: a name (`hikbench list robots`) or the path of a URDF file "
                        "(default: the scenario's)")
    p.add_argument("--srdf", default=None, metavar="PATH",
                   help="with --robot PATH.urdf: an SRDF whose group_state gives the reference configuration "
                        "(and whose floating virtual_joint, if any, a floating base)")
    p.add_argument("--floating-base", action=argparse.BooleanOptionalAction, default=None,
                   help="with --robot PATH.urdf: add a free-flyer root joint (default: only when the SRDF "
                        "declares a floating virtual_joint)")
    p.add_argument("--reference", default=None, metavar="NAME",
                   help="with --srdf: the group_state of the reference configuration (default: the first)")
    p.add_argument("--frame", action="append", default=[], metavar="ALIAS=FRAME",
                   help="frame alias of the robot (repeatable), e.g. right_hand=r_wrist_link "
                        "(default: from the files' [frames] tables and the link names)")
    p.add_argument("--solver", action="append", default=None,
                   help="solver name or module:Class / file.py:Class, or the controller pink (weighted IK on the "
                        f"stack's tasks; repeatable; default: {DEFAULT_SOLVER})")
    p.add_argument("--warm-start", nargs="+", action="extend", default=None, metavar="MODE",
                   help="warm-start modes to run (repeatable), one run each, for solvers with a warm_start option "
                        "(hcod: none stage time; a module:Class solver: the values its warm_start "
                        "parameter takes; default: the solver's default); ignored for the others")
    p.add_argument("--interleave", action=argparse.BooleanOptionalAction, default=None,
                   help="with several --warm-start modes: solve every mode at each step in turn, in one process "
                        "(the default: the modes' ratio is the solver's, not the machine's drift; the loop follows "
                        "the first mode's u, column x_gap_to_first); --no-interleave runs them one after the other")
    p.add_argument("--steps", type=int, default=None, help="control steps (default: the scenario's)")
    p.add_argument("--repeat", type=int, default=None, metavar="R",
                   help="timed calls per step, on R solver objects fed the same steps (same warm-start "
                        "state): the CSV records their minimum (the solver's cost) and the first (what a "
                        "controller sees); x and counts are the first's (default: 5)")
    p.add_argument("--resolve", action="store_true",
                   help="after each step's timed calls, time each solver object solving the same step's problem "
                        "again (column resolve_time_min_s: the cost of a problem the solver has just solved, "
                        "hcod time's warm re-solve)")
    p.add_argument("--certify", nargs="?", type=int, const=2, default=None, metavar="WORKERS",
                   help="after each run, certify every step's x exactly (hikbench.problems.exact) in WORKERS "
                        "processes (default 2): columns certified, certify_reason, x_attains")
    p.add_argument("--out", default=None, help="output directory (default: results/scenarios/NAME)")
    p.add_argument("--plot", action="store_true", help="write the figures (PNG)")
    p.add_argument("--option", action="append", default=[], metavar="[SOLVER.]KEY=VALUE",
                   help="solver option (repeatable), applied to every solver, or with SOLVER. to that one only "
                        "(e.g. pink.level_factor=3)")
    p.add_argument("--list", action="store_true",
                   help="list the shipped scenarios, stacks and controllers, then exit")


def run(args) -> int:
    from hikbench.bench.signals import solver_calls_killable
    from hikbench.bench.scenarios.controllers import CONTROLLERS, build_controller
    from hikbench.bench.scenarios.rows import slug
    from hikbench.bench.scenarios.runner import REPEAT, run_interleaved, run_scenario
    from hikbench.bench.specs import CONTROLLER, SolverSpec, warm_start_modes
    from hikbench.problems.robots.scenarios import load_scenario, scenario_names
    from hikbench.problems.robots.stacks import stack_names
    from hikbench.solvers.registry import build

    if args.list:
        print("scenarios: " + ", ".join(scenario_names()))
        print("stacks:    " + ", ".join(stack_names()))
        print("controllers (--solver): " + ", ".join(CONTROLLERS))
        return 0
    if args.name is None:
        raise HikbenchError("give a scenario NAME (reach, step, ...) or the path of a scenario .toml; "
                            "`hikbench scenario --list` lists them")
    if args.steps is not None and args.steps < 1:
        raise HikbenchError(f"--steps must be >= 1; got {args.steps}")
    if args.repeat is not None and args.repeat < 1:
        raise HikbenchError(f"--repeat must be >= 1; got {args.repeat}")
    if args.certify is not None and args.certify < 1:
        raise HikbenchError(f"--certify must be >= 1 worker process; got {args.certify}")
    check_at_most("--steps", args.steps, MAX_COUNT, "control steps")
    check_at_most("--repeat", args.repeat, MAX_COUNT, "timed calls per step")
    repeat = REPEAT if args.repeat is None else args.repeat
    scenario = load_scenario(args.name, robot=_robot(args), frames=_frames(args.frame))
    print(_robot_line(scenario.robot))
    if scenario.units:
        print("offsets in the robot's lengths: " + ", ".join(f"{k} = {v:.4f} m" for k, v in scenario.units.items()))
    solvers = args.solver or [DEFAULT_SOLVER]
    options, scoped = _split_options(parse_options(args.option), solvers)
    if "warm_start" in options and args.warm_start:
        raise HikbenchError("give the warm-start mode either with --warm-start or --option warm_start=..., "
                            "not both")
    out = Path(args.out or Path("results") / "scenarios" / slug(scenario.name))
    if out.exists() and not out.is_dir():
        raise HikbenchError(f"--out {out}: is a file; expected a directory (created if missing)")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise HikbenchError(f"--out {out}: cannot create the directory: {err.strerror or err}") from err
    plan = []  # (solver, options, modes), each mode built once here so that a bad mode or option fails first
    for solver in solvers:
        spec = SolverSpec.parse(solver, controllers=True)
        if spec.kind == CONTROLLER:  # pink: built on the scenario's stack (an unsupported task fails here)
            opts = {**{k: v for k, v in options.items() if k != "warm_start"}, **scoped.get(solver, {})}
            build_controller(solver, scenario.stack, **opts)
            plan.append((solver, opts, [None]))
            continue
        info = spec.info()
        own = scoped.get(solver, {})
        modes = warm_start_modes(info, args.warm_start, own.get("warm_start", options.get("warm_start")))
        has_modes = modes != [None]  # a warm_start option: hcod's, or a class parameter
        opts = {k: v for k, v in {**options, **own}.items() if k != "warm_start" or has_modes}
        for mode in modes:
            build(info, **{**opts, **({"warm_start": mode} if has_modes else {})})
        plan.append((solver, opts, modes))
    runs, checks, failed = [], [], False
    for solver, opts, modes in plan:
        interleave = len(modes) > 1 and args.interleave is not False
        with solver_calls_killable():  # a backend looping in C code still ends on SIGTERM / Ctrl-C
            t0 = time.perf_counter()
            if interleave:
                group = run_interleaved(scenario, solver, modes, opts, steps=args.steps, repeat=repeat,
                                        resolve=args.resolve, certify=args.certify or 0)
            else:
                group = [run_scenario(scenario, solver, options=opts, warm_start=mode, steps=args.steps,
                                      repeat=repeat, resolve=args.resolve, certify=args.certify or 0)
                         for mode in modes]
            wall = time.perf_counter() - t0
        if interleave:
            print(f"{solver}: warm-start modes {', '.join(r.warm_start for r in group)} interleaved step by step "
                  f"(the loop follows {group[0].label}'s u; --no-interleave runs them one after the other)")
        for run_ in group:
            failed |= _report_run(run_, scenario, out, repeat, args, wall, runs, checks)
    if len(runs) > 1:
        _print_side_by_side(runs, checks)
    _summary(runs, checks).to_csv(out / "summary.csv", index=False)
    print(f"summary (one row per run) -> {out / 'summary.csv'}")
    if args.plot:
        from hikbench.bench.scenarios.plots import plot_runs

        for path in plot_runs(runs, out, joints=scenario.plot_joints):
            print(f"figure {path}")
    return 1 if failed else 0


def _report_run(run_, scenario, out: Path, repeat: int, args, wall: float, runs: list, checks: list) -> bool:
    """Write one run's CSV and trajectory, print its costs, certificates, errors and checks,
    append it to ``runs`` and its checks to ``checks``; True when a check failed."""
    from hikbench.bench.scenarios.checks import check_run
    from hikbench.bench.scenarios.recorded import write_steps
    from hikbench.bench.scenarios.rows import run_stem

    runs.append(run_)
    stem = run_stem(scenario.name, scenario.robot.name, run_.label)
    csv = out / f"{stem}.csv"
    run_.records.to_csv(csv, index=False)
    np.save(out / f"{stem}_q.npy", run_.q)
    write_steps(out, stem, run_.steps)  # (each step's problem and u: `hikbench certify OUT`)
    df = run_.records
    print(f"{run_.label}: {len(df)} steps, solve time per step (min of {repeat} calls) median "
          f"{np.median(df['solve_time_min_s']) * 1e3:.3f} ms, max "
          f"{df['solve_time_min_s'].max() * 1e3:.3f} ms; "
          f"first call median {np.median(df['solve_time_first_s']) * 1e3:.3f} ms, max "
          f"{df['solve_time_first_s'].max() * 1e3:.3f} ms -> {csv}")
    if args.resolve:
        print(f"  re-solve of each step's problem (min of {repeat} calls) median "
              f"{np.median(df['resolve_time_min_s']) * 1e3:.3f} ms")
    apart = int((~df["repeats_agree"].astype(bool)).sum())
    if apart:
        print(f"  note: on {apart} of {len(df)} steps the {repeat} solver objects did not all return the "
              f"first's answer (x, status or counts): their minimum may time other work (repeats_agree)")
    if args.certify:
        ok = df["certified"].eq(True)
        print(f"  exact certificate: {int(ok.sum())} of {len(df)} steps certified, x attains the exact optimum "
              f"on {int(df['x_attains'].eq(True).sum())} (run and certificates {wall:.1f} s, "
              f"{args.certify} worker(s))" + ("" if ok.all() else
                                              f"; first refused: step {int(df.loc[~ok, 'step'].iloc[0])}: "
                                              f"{df.loc[~ok, 'certify_reason'].iloc[0]}"))
    if "x_gap_to_first" in df and (gap := df["x_gap_to_first"].max()) > 0:
        print(f"  x against the first mode's, on its steps: max |du| {gap:.1e} (x_gap_to_first; nonzero on "
              f"{int((df['x_gap_to_first'] > 0).sum())} of {len(df)} steps)")
    errs = [c for c in df.columns if c.startswith("err_")]
    print("  final errors: " + ", ".join(f"{c[4:]}={df[c].iloc[-1]:.2e}" for c in errs))
    checks.append(check_run(run_))
    for check in checks[-1]:
        print(f"  [{check.verdict}] {check.name}: {check.detail}")
    return any(c.passed is False for c in checks[-1])


def _robot(args):
    """The --robot reference with --srdf, --floating-base and --reference (None: the scenario's)."""
    from hikbench.problems.robots.models import robot_source

    given = [f"--{k.replace('_', '-')}" for k in ("srdf", "floating_base", "reference")
             if getattr(args, k) is not None]
    if args.robot is None:
        if given:
            raise HikbenchError(f"{', '.join(given)}: expected --robot PATH.urdf as well")
        return None
    return robot_source(args.robot, args.srdf, args.floating_base, args.reference)


def _frames(items: list[str]):
    """``["right_hand=r_wrist"]`` -> a FrameTable for the --robot (None when empty)."""
    from hikbench.problems.robots.models import FrameTable

    names = {}
    for item in items:
        alias, sep, frame = item.partition("=")
        if not sep or not alias or not frame:
            raise HikbenchError(f"--frame {item!r}: expected ALIAS=FRAME, e.g. --frame right_hand=r_wrist_link")
        names[alias] = frame
    return FrameTable(names, "--frame", key="") if names else None


def _robot_line(robot) -> str:
    """``robot NAME: nq, nv, where it comes from; frames: alias=frame, ...``."""
    frames = ", ".join(f"{a}={f}" for a, f in sorted(robot.frames.items()))
    return (f"robot {robot.name}: nq={robot.nq} nv={robot.nv}, {robot.description or 'example-robot-data'}; "
            f"frames: {frames or 'none'}")


def _split_options(options: dict, solvers: list[str]) -> tuple[dict, dict]:
    """``{"a": 1, "pink.level_factor": 3}`` -> ``({"a": 1}, {"pink": {"level_factor": 3}})``: a key
    ``SOLVER.KEY`` whose SOLVER is one of ``solvers`` applies to that solver only."""
    common, scoped = {}, {}
    for key, value in options.items():
        name, dot, own = key.rpartition(".")
        if dot and name in solvers and own:
            scoped.setdefault(name, {})[own] = value
        elif dot and name and own:
            raise HikbenchError(f"--option {key}=...: {name!r} is not one of the --solver names "
                                f"({', '.join(solvers)}); expected SOLVER.KEY=VALUE with SOLVER given to --solver")
        else:
            common[key] = value
    return common, scoped


def _task_levels(stack) -> dict[str, int]:
    """Task name -> its level (0 the highest priority)."""
    return {t.name: k for k, level in enumerate(stack.levels) for t in level}


def _print_side_by_side(runs, checks) -> None:
    """Task errors of every run side by side, by priority level: max over the run / final
    value; then the median / worst solver's cost per step and the checks passed."""
    level = _task_levels(runs[0].scenario.stack)
    cols = [c for c in runs[0].records.columns if c.startswith("err_")]
    names = {c: f"L{level.get(c[4:], '?')} {c[4:]}" for c in cols}
    width = max(len(n) for n in [*names.values(), "median / max solve"])
    cell = max(21, *(len(r.label) for r in runs))
    print("\ntask errors by level (L0 the highest priority), max over the run / final value:")
    print(" " * width + "  " + "  ".join(f"{r.label:>{cell}}" for r in runs))
    for c in cols:
        cells = [f"{r.records[c].max():.2e} / {r.records[c].iloc[-1]:.2e}" if c in r.records else "-"
                 for r in runs]
        print(f"{names[c]:<{width}}  " + "  ".join(f"{x:>{cell}}" for x in cells))
    cost = [r.records["solve_time_min_s"].to_numpy(dtype=float) * 1e3 for r in runs]
    med = [f"{np.median(t):.3f} / {t.max():.3f} ms" for t in cost]
    print(f"{'median / max solve':<{width}}  " + "  ".join(f"{m:>{cell}}" for m in med))
    passed = [f"{sum(c.passed is True for c in cs)} of {len(cs)}"
              + (f" ({n} not judged)" if (n := sum(c.passed is None for c in cs)) else "") for cs in checks]
    print(f"{'checks passed':<{width}}  " + "  ".join(f"{p:>{cell}}" for p in passed))


def _summary(runs, checks):
    """One row per run (``summary.csv``): solver, warm_start, strict, steps, the cost columns of
    OUT/scenarios.csv (:func:`.rows.step_costs`: time_median_s ... steps_not_optimal), per task
    ``max_err_L<level>_<task>`` and ``final_err_L<level>_<task>``, and the checks
    (:func:`.rows.check_counts`: checks_passed, checks_failed, checks_not_judged, failed_checks)."""
    import pandas as pd

    from hikbench.bench.scenarios.plots import run_strict
    from hikbench.bench.scenarios.rows import check_counts, step_costs

    level = _task_levels(runs[0].scenario.stack)
    rows = []
    for run, cs in zip(runs, checks):
        df = run.records
        row = {"solver": run.solver, "warm_start": run.warm_start, "strict": run_strict(run), "steps": len(df),
               **step_costs(df)}
        for c in (c for c in df.columns if c.startswith("err_")):
            key = f"L{level.get(c[4:], '?')}_{c[4:]}"
            row[f"max_err_{key}"] = float(df[c].max())
            row[f"final_err_{key}"] = float(df[c].iloc[-1])
        rows.append(row | check_counts((c.name, c.passed) for c in cs))
    return pd.DataFrame(rows)
