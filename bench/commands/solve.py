"""``hikbench solve FILE --solver NAME|module:Class [--repeat R] [--warm] [--certify [--accuracy PROFILE]] [--json]``.

Exit status: 0, 1 when the solver failed (error, crashed) or, with ``--certify``, when the
certified optimum is below x at some level beyond the ``--accuracy`` profile's tolerance (x is
not optimal), 2 for bad input."""

from __future__ import annotations

import json
import math
import os
import pickle
import sys
import tempfile
import threading
import traceback
from types import SimpleNamespace

from hikbench.bench.harness.isolation import describe_exit, die_with_parent
from hikbench.bench.harness.statuses import CRASHED
from hikbench.bench.harness.worker import solver_info
from hikbench.problems.errors import HikbenchError
from hikbench.problems.files import load
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
    p.add_argument("--certify", action="store_true",
                   help="also certify x in 50-digit arithmetic: the exact optimum on the active set read off x, "
                        "and its level norms (hikbench.problems.exact; ~0.1 s at n = 5, ~3 s at n = 20)")
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


NOTE_AFTER_S = 3.0  # a warm-up still running then gets a note on stderr


def _warm_up(solver, name: str) -> None:
    """The solver's ``warmup()`` (hcod: compile its kernels, ~70 s without numba's
    cache), untimed, with a note on stderr when it takes longer than NOTE_AFTER_S."""
    if not callable(getattr(solver, "warmup", None)):
        return
    note = threading.Timer(NOTE_AFTER_S, lambda: print(
        f"note: {name}: preparing its first solve in this process (hcod compiles its numba kernels once, "
        f"about 70 s, then loads them from numba's cache)...", file=sys.stderr, flush=True))
    note.start()
    try:
        solver.warmup()
    finally:
        note.cancel()


def _solve(args, h, info, options) -> tuple:
    """Build, warm up and time the solver (in the child of :func:`_contained`):
    ``("done", fields)``, or ``("error", reason)`` when the solver's constructor or
    solve raised (a user's file.py:Class); a HikbenchError (a wrong option) is raised."""
    from hikbench.bench.cli import solver_calls_killable
    from hikbench.bench.harness.timing import time_solves

    try:
        # names and options are checked here, before timing (a HikbenchError: exit 2); an exception
        # of the solver's own constructor or solve (a user's file.py:Class) is its answer: status error
        solver = registry.build(info, **options)
        if args.warm and not getattr(solver, "supports_warm_start", False):
            print(f"note: {args.solver} has no warm start: --warm times re-solves that redo a cold solve's "
                  f"work", file=sys.stderr)
        with solver_calls_killable():  # a backend looping in C code still ends on SIGTERM / Ctrl-C
            _warm_up(solver, args.solver)
            timing = time_solves(lambda: registry.build(info, **options), h, repeat=args.repeat,
                                 mode="warm" if args.warm else "cold")
    except HikbenchError:
        raise
    except Exception as err:  # noqa: BLE001 - the solver's exception (a user's file.py:Class), not hikbench's
        return "error", f"{type(err).__name__}: {err}"
    res = timing.result
    return "done", {"status": res.status, "reason": res.reason, "x": res.x, "iterations": res.iterations,
                    "median_s": timing.median_s, "min_s": timing.min_s}


def _contained(work) -> tuple:
    """``work()`` in a forked child process (POSIX): a solver that segfaults, aborts
    or calls sys.exit still lets this process report it, as ``("crashed", how it
    ended)``. The child keeps everything imported and loaded here (no start-up
    cost) and sends its answer back pickled in a temporary file; a HikbenchError it
    raises is raised here. On Linux the child dies with this process
    (PR_SET_PDEATHSIG). Without os.fork, or when sys.stdout or sys.stderr is
    not a file descriptor the child would write to (main() called from Python
    with its output captured: the child's notes would be lost), work() runs in
    this process."""
    from hikbench.bench.cli import solver_calls_killable

    if not hasattr(os, "fork") or not _streams_are_fds():
        return work()
    sys.stdout.flush()
    sys.stderr.flush()
    with tempfile.TemporaryFile() as f:
        parent = os.getpid()
        pid = os.fork()
        if pid == 0:
            _child(work, f, parent)
        with solver_calls_killable():  # ended by SIGTERM / Ctrl-C as the child is (which dies with it)
            _, status = os.waitpid(pid, 0)
        code = os.waitstatus_to_exitcode(status)
        f.seek(0)
        data = f.read()
    if code != 0 or not data:
        return "crashed", describe_exit(code, "solver process") + ("" if code else " before it answered")
    kind, payload = pickle.loads(data)
    if kind == "user_error":
        raise payload
    return kind, payload


def _streams_are_fds() -> bool:
    """Whether sys.stdout and sys.stderr write to file descriptors (a forked child's
    writes then reach the same place)."""
    try:
        sys.stdout.fileno()
        sys.stderr.fileno()
    except (AttributeError, OSError, ValueError):  # (io.UnsupportedOperation: an in-memory stream)
        return False
    return True


def _answer_of(work) -> tuple:
    """work()'s answer, a HikbenchError it raises as ``("user_error", err)``."""
    try:
        return work()
    except HikbenchError as err:
        return "user_error", err


def _child(work, f, parent: int) -> None:
    """The forked child of :func:`_contained`: runs work(), writes its answer
    pickled to ``f`` and exits with os._exit (never returns into the CLI); a
    SystemExit of the solver exits with its code, unanswered."""
    code = 1
    try:
        die_with_parent()
        if os.getppid() != parent:  # the parent ended before the child was set to die with it
            return
        answer = _answer_of(work)
        try:
            data = pickle.dumps(answer)
        except (pickle.PicklingError, TypeError, AttributeError):  # an exception that does not pickle
            data = pickle.dumps(("user_error", HikbenchError(str(answer[1]))))
        f.write(data)
        f.flush()
        code = 0
    except SystemExit as stop:  # the solver's sys.exit(k): the child ends with k, as a worker would
        code = stop.code if isinstance(stop.code, int) else 1
    except BaseException:  # noqa: BLE001 - a bug: its traceback on stderr; the parent reports the exit code
        traceback.print_exc()
    finally:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError):  # a closed or broken stream: its output is lost, the exit code stays
                continue
        os._exit(code)


def run(args) -> int:
    if args.repeat < 1:
        raise HikbenchError(f"--repeat must be >= 1; got {args.repeat}")
    h = load(args.file)
    options = parse_options(args.option)
    info = solver_info(args.solver)  # a registry name, or module:Class as `run --solvers` takes it
    kind, answer = _contained(lambda: _solve(args, h, info, options))
    if kind != "done":  # the solver raised (error) or its process died (crashed)
        status = ERROR if kind == "error" else CRASHED
        if args.json:
            print(json.dumps({"solver": args.solver, "status": status, "reason": answer, "x": None,
                              "level_norms": None, "iterations": None, "time_s": None}
                             | ({"certificate": None} if args.certify else {})))
        else:
            print(f"solver      {args.solver}\nstatus      {status} ({answer})")
        return 1
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
    if args.certify and res.x is not None and all(map(math.isfinite, res.x)):
        from hikbench.problems.exact import certify

        cert = certify(h, res.x)
    # whether x itself reaches the certified optimum's level norms (judge, at each profile): the
    # certificate is of the optimum on the active set read off x, which any x has
    verdicts = None if cert is None or not cert.certified else {
        p: judge(h, res.x, cert.x, prof.rtol) for p, prof in PROFILES.items()}
    attains = None if verdicts is None else verdicts[args.accuracy]
    optimal = None if attains is None else attains.lower != "b"
    if args.certify:
        above = attains is not None and attains.lower == "b"
        out["certificate"] = None if cert is None else {
            "certified": cert.certified, "reason": cert.reason,
            "level_norms": [_finite_or_none(float(v)) for v in cert.level_norms],
            "accuracy": args.accuracy,
            "x_is_optimal": optimal,
            "verified": None if verdicts is None else {p: v.lower != "b" for p, v in verdicts.items()},
            "level_gaps": None if verdicts is None else [
                _finite_or_none(float(g)) for g in level_gaps(h, res.x, cert.x)],
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
            print("certificate " + ("none: no finite x" if cert is None else
                                    f"exact optimum, level norms {cert.level_norms.tolist()}" if cert.certified
                                    else f"refused: {cert.reason}"))
            if attains is not None:
                print("x           " + _attains_line(attains, verdicts, args.accuracy))
    # (an exception in the solver, or an answer off the contract; with --certify, an x the certified
    # optimum is below at the profile's tolerance)
    return 1 if res.status == ERROR or optimal is False else 0


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

