"""``hikbench solve FILE --solver NAME|module:Class [--repeat R] [--warm] [--timeout S] [--first-solve-timeout S]
[--certify [--accuracy PROFILE]] [--json]``.

The solve runs as one job of ``hikbench run`` does: in an isolated worker process
(hikbench.bench.harness.isolation) under a hard timeout, so a solver that hangs, segfaults or
exits costs a one-line ``timeout`` or ``crashed`` result (exit 1), not the command.

Exit status: 0; 1 when the solver failed (error, crashed, timeout) or, with ``--certify``, when
the certified optimum is below x at some level beyond the ``--accuracy`` profile's tolerance (x
is not optimal); 2 for bad input."""

from __future__ import annotations

import json
import math
import sys
import threading
from types import SimpleNamespace

import numpy as np

from hikbench.bench.harness.statuses import CRASHED, TIMEOUT
from hikbench.bench.specs import solver_info
from hikbench.problems.errors import HikbenchError
from hikbench.problems.files import load
from hikbench.problems.hierarchy import row_normalised
from hikbench.problems.schema import MAX_COUNT, check_at_most
from hikbench.problems.verify import PROFILES, judge, level_gaps, level_norms
from hikbench.solvers import registry
from hikbench.solvers.base import ERROR

HELP = "solve one problem file with one solver and print the result"


def add_arguments(p) -> None:
    p.add_argument("file", help="problem file (.npz or SOTH text)")
    p.add_argument("--solver", default="yardstick",
                   help="solver name (see `hikbench list solvers`; default: yardstick), or module:Class / "
                        "file.py:Class (a Solver subclass of your own: README, \"Adding a solver\")")
    p.add_argument("--repeat", type=int, default=1, help="timed repetitions (default 1)")
    p.add_argument("--warm", action="store_true",
                   help="time re-solves on one solver object that already solved the problem once")
    p.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                   help="solver option (repeatable); VALUE is parsed as JSON when it can be")
    p.add_argument("--timeout", type=float, default=None, metavar="S",
                   help="hard limit in seconds on the timed solves, as `run --timeout` (default: the quick "
                        "suite's, as `run`: 10); a solver that does not answer is killed: status timeout, exit 1")
    p.add_argument("--first-solve-timeout", type=float, default=None, metavar="S",
                   help="allowance in seconds for the solver's warm-up and first, untimed solve (hcod compiles "
                        "its kernels once, about 70 s without numba's cache), when larger than --timeout "
                        "(default: the quick suite's, as `run`: 300)")
    p.add_argument("--certify", action="store_true",
                   help="also certify x in exact rational arithmetic: the exact optimum on the active set read off x, "
                        "and its level norms (hikbench.problems.exact; ~0.05 s at n = 7, ~1 s at n = 80-120); for a "
                        "solver claiming row-normalised levels (daqp-hqp), of the row-normalised hierarchy")
    p.add_argument("--accuracy", default="default", choices=tuple(PROFILES),
                   help="with --certify: the profile whose verdict decides the exit status (1: x is not optimal; "
                        "default: default); the verdicts at every profile are printed")
    p.add_argument("--json", action="store_true", help="print one JSON object")


def parse_options(items: list[str]) -> dict:
    """``["a=1", "b=osqp"]`` -> ``{"a": 1, "b": "osqp"}``."""
    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise HikbenchError(f"--option {item!r}: expected KEY=VALUE")
        try:
            out[key] = json.loads(value)
        except json.JSONDecodeError:
            out[key] = value
    return out


def _finite_or_none(v: float):
    return v if math.isfinite(v) else None


NOTE_AFTER_S = 3.0  # a first solve still running then gets a note on stderr


def _timeouts(args) -> tuple[float, float]:
    """--timeout and --first-solve-timeout, the quick suite's where not given (as ``run``'s
    default suite); one-line HikbenchError for a value that is not seconds > 0."""
    from hikbench.bench.suites import load_suite

    for flag, value in (("--timeout", args.timeout), ("--first-solve-timeout", args.first_solve_timeout)):
        if value is not None and not (math.isfinite(value) and value > 0):
            raise HikbenchError(f"{flag} must be a number of seconds > 0; got {value}")
    if args.timeout is not None and args.first_solve_timeout is not None:
        return args.timeout, args.first_solve_timeout
    quick = load_suite("quick")
    return (quick.timeout if args.timeout is None else args.timeout,
            quick.first_solve_timeout if args.first_solve_timeout is None else args.first_solve_timeout)


def _solve(args, h, options: dict) -> dict:
    """One ``solve`` job (hikbench.bench.harness.worker.execute: the solver's warmup(), an
    untimed first solve, then ``--repeat`` timed ones) in an isolated worker process: its
    result dict, or status ``timeout`` / ``crashed`` with the reason. A note goes to stderr
    when the first solve takes longer than NOTE_AFTER_S."""
    from hikbench.bench.harness.isolation import IsolatedWorker

    timeout, first = _timeouts(args)
    job = {"kind": "solve", "hierarchy": h, "solver": args.solver, "options": options,
           "mode": "warm" if args.warm else "cold", "repeat": args.repeat, "warmup": 1, "samples": None}
    note = threading.Timer(NOTE_AFTER_S, lambda: print(
        f"note: {args.solver}: preparing its first solve in a fresh worker process (hcod compiles its numba "
        f"kernels once, about 70 s, then loads them from numba's cache)...", file=sys.stderr, flush=True))
    worker = IsolatedWorker()
    try:
        worker.start()  # (the process's own start, about 1 s of imports, is not the solver's)
        note.start()
        return worker.run(job, timeout, first_timeout=first, on_first_solve=note.cancel)
    except BaseException:  # Ctrl-C, SIGTERM (bench.signals.Terminated): the solve ends at once, not after close()'s 5 s
        worker.kill()
        raise
    finally:
        note.cancel()
        worker.close()


def run(args) -> int:
    if args.repeat < 1:
        raise HikbenchError(f"--repeat must be >= 1; got {args.repeat}")
    _timeouts(args)  # (a bad value: exit 2 before the problem is read)
    check_at_most("--repeat", args.repeat, MAX_COUNT, "timed solves")
    h = load(args.file)
    options = parse_options(args.option)
    info = solver_info(args.solver)  # a registry name, or module:Class as `run --solvers` takes it
    # names and options checked here, before any solve (a SolverOptionError: exit 2); an exception of
    # the solver's own constructor or solve (a user's file.py:Class) is its answer: status error
    checked = registry.check_buildable(info, **options)
    # the hierarchy the solver claims its levels are (a row-normalised claim: certified on that one)
    judged_on = (info.judged_on(checked) if info.judged_on
                 else getattr(info.factory, "judged_on", "rows"))  # (module:Class: its class attribute)
    if judged_on not in ("rows", "row-normalised"):
        raise HikbenchError(f"solver {args.solver!r} has judged_on = {judged_on!r}: expected 'rows' or "
                            f"'row-normalised' (the hierarchy its levels are: hikbench.solvers.base.Solver.judged_on)")
    if args.warm and not getattr(info.factory, "supports_warm_start", info.supports_warm_start):
        print(f"note: {args.solver} has no warm start: --warm times re-solves that redo a cold solve's "
              f"work", file=sys.stderr)
    answer = _solve(args, h, options)
    if answer.get("user_error"):  # a HikbenchError of the worker's build or solve (an option's value)
        raise HikbenchError(answer["user_error"])
    if answer["status"] in (ERROR, CRASHED, TIMEOUT) and answer.get("x") is None:
        # the solver raised (error), its process died (crashed) or it did not answer (timeout)
        status, reason = answer["status"], answer.get("reason", "")
        if args.json:
            print(json.dumps({"solver": args.solver, "status": status, "reason": reason, "x": None,
                              "level_norms": None, "iterations": None, "time_s": None}
                             | ({"certificate": None} if args.certify else {})))
        else:
            print(f"solver      {args.solver}\nstatus      {status} ({reason})")
        return 1
    samples = np.asarray(answer["samples_ns"], dtype=float)
    answer |= {"median_s": float(np.median(samples)) * 1e-9, "min_s": float(np.min(samples)) * 1e-9}
    res = SimpleNamespace(**answer)
    timing = SimpleNamespace(median_s=answer["median_s"], min_s=answer["min_s"])
    norms = level_norms(h, res.x).tolist() if res.x is not None else None
    out = {
        "solver": args.solver,
        "status": res.status,
        "reason": res.reason,
        "x": None if res.x is None else [_finite_or_none(float(v)) for v in res.x],
        "level_norms": None if norms is None else [_finite_or_none(v) for v in norms],
        # SolveResult.iterations is 0 when the solver does not report iterations
        # (reference, cascades over backends that count none): null / '-', not a count of 0
        "iterations": int(res.iterations) or None,
        "time_s": {"median": timing.median_s, "min": timing.min_s},
    }
    cert = None
    hc = row_normalised(h) if judged_on == "row-normalised" else h
    if args.certify and res.x is not None and all(map(math.isfinite, res.x)):
        from hikbench.problems.exact import certify

        cert = certify(hc, res.x)
    # whether x itself reaches the certified optimum's level norms (judge, at each profile): the
    # certificate is of the optimum on the active set read off x, which any x has
    verdicts = None if cert is None or not cert.certified else {
        p: judge(hc, res.x, cert.x, prof.rtol) for p, prof in PROFILES.items()}
    attains = None if verdicts is None else verdicts[args.accuracy]
    optimal = None if attains is None else attains.lower != "b"
    if args.certify:
        above = attains is not None and attains.lower == "b"
        out["certificate"] = None if cert is None else {"judged_on": judged_on,
            "certified": cert.certified, "reason": cert.reason,
            "level_norms": [_finite_or_none(float(v)) for v in cert.level_norms],
            "accuracy": args.accuracy,
            "x_is_optimal": optimal,
            "verified": None if verdicts is None else {p: v.lower != "b" for p, v in verdicts.items()},
            "level_gaps": None if verdicts is None else [
                _finite_or_none(float(g)) for g in level_gaps(hc, res.x, cert.x)],
            "x_above_at_level": attains.level if above else None,
            "x_above_by": attains.difference if above else None}
    if args.json:
        print(json.dumps(out))
    else:
        print(f"solver      {out['solver']}")
        print(f"status      {out['status']}" + (f" ({res.reason})" if res.reason else ""))
        print(f"level norms {norms}")
        print(f"iterations  {'-' if out['iterations'] is None else out['iterations']}")
        print(f"time        median {timing.median_s * 1e6:.1f} us, min {timing.min_s * 1e6:.1f} us "
              f"over {args.repeat} {'warm' if args.warm else 'cold'} solve(s)")
        if args.certify:
            print("certificate " + ("" if judged_on == "rows" else f"(of the {judged_on} hierarchy, the solver's "
                                                                     f"claim) ")
                  + ("none: no finite x" if cert is None else
                                    f"exact optimum, level norms {cert.level_norms.tolist()}" if cert.certified
                                    else f"refused: {cert.reason}"))
            if attains is not None:
                print("x           " + _attains_line(attains, verdicts, args.accuracy))
    # (an exception in the solver, or an answer off the contract; with --certify, an x the certified
    # optimum is below at the profile's tolerance)
    return 1 if res.status in (ERROR, CRASHED, TIMEOUT) or optimal is False else 0


def _attains_line(v, verdicts: dict, accuracy: str) -> str:
    """The ``x`` line of ``--certify``: whether x attains the certified optimum at ``accuracy``
    (v, its :func:`hikbench.problems.verify.judge` verdict), and at which profiles."""
    at = ", ".join(p for p, w in verdicts.items() if w.lower != "b") or "none"
    rtol = f"{PROFILES[accuracy].rtol:.0e}".replace("e-0", "e-")
    if v.lower == "b":
        return (f"is NOT optimal at the {accuracy} profile: above the certified optimum at level {v.level} by "
                f"{v.difference:.3g} (tolerance {v.tolerance:.3g}, rtol {rtol} of the level's terms); "
                f"verified at: {at}")
    if v.lower == "a":
        return (f"attains it at the {accuracy} profile (no level above it beyond rtol {rtol} of its terms), "
                f"below it at level {v.level} by {-v.difference:.3g}: a level above is over the exact optimum "
                f"within its tolerance; verified at: {at}")
    return (f"attains it (no level above it beyond rtol {rtol} of its terms, the {accuracy} profile); "
            f"verified at: {at}")

