"""The sweep of the cascades' settings (docs/solvers.md, "Fair settings").

For every cascade backend (the qpsolvers backends and cvxpy) it runs a grid
of settings over a representative subset of the shipped suites' problems and
robot stacks, and chooses, for every accuracy profile P (high, default, low:
hikbench.problems.verify.PROFILES), the settings under which the backend
solves the most problems *exactly* -- verified at P (column ``verified_P``:
hikbench's verdict from x, whatever the status) -- then the fastest: the
smallest geometric mean of ``time_median_s`` over the problems every such
candidate solves, those within 10 % of it (:data:`NOISE`) being equally fast,
and among these the plainest settings (:func:`_preference`).

The grid, per backend: ``tolerances`` (the backend's tolerance presets, 1e-9 /
its own / 1e-5; quadprog has none) x ``freeze`` (shift, equality, relaxed) x
``regularization`` (1e-12, 1e-10, 1e-8), and, for backends with an iteration
cap, ten times the cap at ``tolerances=high`` (not osqp: its ``high`` preset
already sets 100000, 25 times OSQP's own 4000, and 1e6 iterations ran into
the sweep's timeout on the 8-level equality stack). A candidate is chosen
only among the complete ones (a row for every problem of the sweep).

    python -m hikbench.bench.analysis.settings_sweep write bench/examples/sweep_cascade_settings.toml
    nice -n 5 env OPENBLAS_NUM_THREADS=1 hikbench run --suite bench/examples/sweep_cascade_settings.toml \\
        --out results/sweep-cascade-settings
    python -m hikbench.bench.analysis.settings_sweep choose results/sweep-cascade-settings

``choose`` prints the table of docs/solvers.md and the value of
:data:`hikbench.solvers._qp_backends.SETTINGS` it implies.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

from hikbench.problems.verify import PROFILES
from hikbench.solvers import _qp_backends as tables

__all__ = ["BACKENDS", "candidates", "choose", "suite_text"]

#: the cascades swept: the qpsolvers backends and cvxpy (its default solver, CLARABEL)
BACKENDS: tuple[str, ...] = (*sorted(tables.BACKENDS), "cvxpy")
FREEZES = ("shift", "equality", "relaxed")
REGULARIZATIONS = (1e-12, 1e-10, 1e-8)
#: each backend's own iteration cap (its documentation's default; highs: DEFAULT_MAX_ITER); the sweep
#: also tries ten times it at tolerances=high
OWN_MAX_ITER = {"proxqp": 10_000, "clarabel": 200, "daqp": 1000, "piqp": 250, "highs": 10_000, "cvxpy": 200}

#: the problems: the quick suite's, a few of the peers suite's, and the robot stacks
PROBLEMS = """\
[[problems]]   # quick: DOF sweep
family = "equality"
params = { depth = 3, rows = 4 }
grid = { n = [6, 12, 24, 48] }
seeds = [0]

[[problems]]   # quick: depth sweep (saturated from depth 6)
family = "equality"
params = { n = 24, rows = 4 }
grid = { depth = [1, 2, 4, 8] }
seeds = [0]

[[problems]]   # quick, peers
family = "ik-like"
grid = { n = [12, 20, 40] }
seeds = [0]

[[problems]]   # quick
family = "degenerate"
params = { n = 12 }
grid = { case = ["rank_deficient", "duplicate_rows", "infeasible_top", "free_rows"] }
seeds = [0]

[[problems]]   # peers: saturated
family = "equality"
params = { n = 36, depth = 24, rows = 6 }
seeds = [0]

[[problems]]   # panda: joint limits > 6D pose > posture
family = "robot-stack"
params = { stack = "arm_reach" }
seeds = [0, 1, 2, 3, 4]

[[problems]]   # talos: the reach scenario's stack; every task family; solo12
family = "robot-stack"
grid = { stack = ["humanoid_reach", "humanoid_tasks", "quadruped_stance"] }
seeds = [0, 1]
"""


def _name(opts: dict) -> str:
    parts = [opts.get("tolerances", "-"), opts["freeze"], f"{opts['regularization']:.0e}".replace("e-0", "e-")]
    if "max_iter" in opts:
        parts.append(f"iter{opts['max_iter']}")
    return "-".join(parts)


def candidates(backend: str) -> list[dict]:
    """The grid of option dicts swept for ``backend`` (module doc)."""
    tols = ("high",) if backend == "quadprog" else tables.PROFILES  # (quadprog: no tolerance to set)
    out = [{"tolerances": t, "freeze": f, "regularization": r} for t in tols for f in FREEZES
           for r in REGULARIZATIONS]
    if backend in OWN_MAX_ITER:
        out += [{"tolerances": "high", "freeze": f, "regularization": r, "max_iter": 10 * OWN_MAX_ITER[backend]}
                for f in FREEZES for r in REGULARIZATIONS]
    if backend == "quadprog":
        for o in out:
            del o["tolerances"]
    return out


def _toml_value(v) -> str:
    return json.dumps(v) if isinstance(v, str) else repr(v)


def suite_text() -> str:
    """The sweep's suite (TOML): every backend's grid as ``[[settings]]``, cold, 3 repetitions."""
    head = ('description = "The sweep of the cascades\' settings (docs/solvers.md, Fair settings; written by '
            'python -m hikbench.bench.analysis.settings_sweep write): per backend, tolerances x freeze x '
            'regularization, and 10x the iteration cap, on the quick suite\'s problems, a few of the peers '
            'suite\'s and the robot stacks; cold, 3 repetitions."\n'
            'repeat = 3\nwarmup = 0\ntimeout = 5.0\nmodes = ["cold"]\naccuracy = "default"\n'
            f'solvers = [{", ".join(json.dumps("cascade-" + b) for b in BACKENDS)}]\n\n')
    settings = []
    for b in BACKENDS:
        for opts in candidates(b):
            body = ", ".join(f"{k} = {_toml_value(v)}" for k, v in opts.items())
            settings.append(f'[[settings]]\nsolver = "cascade-{b}"\nname = "{_name(opts)}"\n'
                            f"options = {{ {body} }}\n")
    return head + PROBLEMS + "\n" + "\n".join(settings)


#: tied candidates whose geometric mean time is within this fraction of the fastest's are equally fast
#: (the sweep's times on a shared machine move by a few per cent from run to run)
NOISE = 0.10


def _preference(opts: dict, profile: str) -> tuple:
    """Among equally fast candidates, the one nearest the plain settings: the profile's own
    tolerance preset, the backend's own iteration cap, the smallest regularisation, then the
    freeze modes in the order shift (Kanoun et al.), equality, relaxed."""
    tol = opts.get("tolerances", profile)
    return (tol != profile, tables.PROFILES.index(tol), opts.get("max_iter") is not None,
            opts["regularization"], FREEZES.index(opts["freeze"]))


def _geomean(values) -> float:
    values = [v for v in values if v > 0]
    return math.exp(sum(math.log(v) for v in values) / len(values)) if values else math.inf


def choose(frame) -> dict:
    """For each (solver, profile): the settings name chosen (module doc) from a results frame
    (hikbench.bench.harness.results.read_results) holding the sweep's rows, with ``solved``
    (problems verified at the profile), ``of`` (problems with a certified yardstick),
    ``geomean_s`` and, per candidate, the same figures (``table``)."""
    out = {}
    problems = frame["problem"].nunique()
    complete = frame.groupby(["solver", "settings"])["problem"].nunique() == problems
    whole = np.array([bool(complete[(a, b)]) for a, b in zip(frame["solver"], frame["settings"])], dtype=bool)
    # (the suite's "default" run of each solver repeats the grid point of the settings it had)
    rows = frame[(frame["yardstick"] == "certified").to_numpy() & whole & (frame["settings"] != "default").to_numpy()]
    for solver, part in rows.groupby("solver"):
        of = part["problem"].nunique()
        for profile in PROFILES:
            ok = part[part[f"verified_{profile}"].astype(str) == "True"]
            solved = {s: set(g["problem"]) for s, g in ok.groupby("settings")}
            for s in part["settings"].unique():
                solved.setdefault(s, set())
            best = max(len(v) for v in solved.values())
            tied = sorted(s for s, v in solved.items() if len(v) == best)
            common = set.intersection(*(solved[s] for s in tied))
            times = {s: _geomean(ok[(ok["settings"] == s) & ok["problem"].isin(common)]["time_median_s"])
                     for s in tied}
            fastest = min(times.values())
            fast = [s for s in tied if times[s] <= (1 + NOISE) * fastest]
            pick = min(fast, key=lambda s: (_preference(_options(frame, solver, s), profile), times[s]))
            table = {s: {"solved": len(v),
                         "geomean_s": _geomean(ok[(ok["settings"] == s) & ok["problem"].isin(common)]
                                               ["time_median_s"]) if s in tied else None}
                     for s, v in solved.items()}
            failed = sorted(set(part["problem"]) - solved[pick])
            out[(solver, profile)] = {"settings": pick, "solved": best, "of": of, "geomean_s": times[pick],
                                      "tied": tied, "table": table, "failed": failed,
                                      "union": len(set.union(*solved.values())),
                                      "elsewhere": {p: sorted(s for s, v in solved.items() if p in v)
                                                    for p in failed}}
    return out


def _options(frame, solver: str, settings: str) -> dict:
    """The options of a sweep's settings; ``default`` (the suite's run of the solver's defaults):
    the row of tables.SETTINGS at ``high``, the cascades' default accuracy."""
    if settings == "default":
        return dict(tables.SETTINGS[solver.removeprefix("cascade-")]["high"])
    opts = frame[(frame["solver"] == solver) & (frame["settings"] == settings)]["options"].iloc[0]
    return opts if isinstance(opts, dict) else json.loads(opts or "{}")


def _main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m hikbench.bench.analysis.settings_sweep", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="cmd", required=True)
    w = sub.add_parser("write", help="write the sweep's suite TOML")
    w.add_argument("path")
    c = sub.add_parser("choose", help="the settings chosen from a sweep's OUT/results.csv")
    c.add_argument("out")
    args = p.parse_args(argv)
    if args.cmd == "write":
        Path(args.path).write_text(suite_text())
        return 0
    from hikbench.bench.harness.results import read_results

    frame = read_results(Path(args.out))
    chosen = choose(frame)
    print("| backend | profile | settings chosen | solved | by any setting | geomean ms (solved by all tied) | "
          "settings solving as many | not solved (settings that solve it) |")
    print("|---|---|---|---|---|---|---|---|")
    for (solver, profile), c in sorted(chosen.items()):
        missed = "; ".join(f"{p} ({len(c['elsewhere'][p])}: {', '.join(c['elsewhere'][p][:3])}"
                           f"{', ...' if len(c['elsewhere'][p]) > 3 else ''})" if c["elsewhere"][p] else p
                           for p in c["failed"]) or "-"
        print(f"| {solver} | {profile} | {c['settings']} | {c['solved']}/{c['of']} | {c['union']} | "
              f"{1e3 * c['geomean_s']:.3g} | {len(c['tied'])} | {missed} |")
    print()
    settings = {}
    for (solver, profile), c in sorted(chosen.items()):
        opts = _options(frame, solver, c["settings"])
        settings.setdefault(solver.removeprefix("cascade-"), {})[profile] = {
            "tolerances": opts.get("tolerances", profile), "freeze": opts["freeze"],
            "regularization": opts["regularization"], "max_iter": opts.get("max_iter")}
    print(json.dumps(settings, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(_main())
