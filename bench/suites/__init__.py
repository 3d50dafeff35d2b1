"""Suites: TOML files listing problem families with parameter grids and seeds,
solvers (names or glob patterns) with settings, repetitions and modes.

Built-in suites live in ``bench/suites/<name>.toml``; ``--suite`` also takes a
path. Schema (every key optional except ``problems``)::

    description = "..."
    repeat = 5              # timed repetitions per row
    rounds = 1              # the repetitions split over rounds: round r runs every job once (slow windows)
    warmup = 1              # discarded solves before timing
    timeout = 60.0          # seconds per job (warm-up + repetitions), hard
    first_solve_timeout = 300.0  # allowance for a solver's first solve in a worker process (JIT: hcod ~70 s without a cache)
    calibrate_each_job = false  # time the calibration kernel around every job (else once per worker)
    modes = ["cold", "warm"]
    accuracy = "default"    # verification profile, see ACCURACY
    export = ["npz"]        # problem files written to OUT/problems/ ("npz", "soth")
    solvers = ["*"]         # names, glob patterns ("cascade-*"), module:Class, external:NAME=CMD

    [[settings]]            # extra settings of a solver (every solver also runs "default")
    solver = "cascade-osqp"
    name = "low"
    options = { accuracy = "low" }   # checked against the solver before anything runs

    [[problems]]
    family = "equality"          # a `hikbench list families` name or module:function
    params = { rows = 6 }              # fixed parameters
    grid = { n = [6, 12], depth = [2, 4] }   # Cartesian product
    seeds = [0, 1]
    solvers = ["hcod", "nullspace-*", "cascade-osqp"]  # optional: restricts this group

Decisions (docs/suites.md, "The suite file"):

* ``warm`` mode runs only for solvers with ``supports_warm_start`` (for the
  others it would time the same cold solve twice); external solvers run cold.
* A solver named explicitly but not installed (a known optional backend) is
  reported on stderr and in run.json (``skipped_solvers``) with its install
  hint, and gets no rows; a glob pattern matches installed solvers only. A
  name the registry does not know at all is an error (SolverNotFoundError,
  listing the known solvers), as is a suite that selects no job.
* Every value is type-checked when the suite is loaded (SuiteError naming the
  file, the key and what was expected); the options of each ``[[settings]]``
  are checked against their solver before the run starts.
* The settings' options are part of a row's identity for resuming: after a
  ``[[settings]]`` changes, its rows run again and replace the old ones.
* ``grid = { case = "*" }`` expands to every ``hikbench.problems.generators.DEGENERATE_CASES``.
"""

from __future__ import annotations

import fnmatch
import itertools
import json
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from hikbench.bench.suites.problemset import ProblemSpec
from hikbench.bench.harness.worker import solver_info
from hikbench.problems.errors import HikbenchError
from hikbench.solvers.errors import SolverNotFoundError

__all__ = ["ACCURACY", "SolverEntry", "Suite", "Task", "builtin_suites", "load_suite", "resolve_solvers"]

SUITES_DIR = Path(__file__).parent

#: verification profiles: name -> (rtol, atol) of hikbench.problems.verify.verify
ACCURACY: dict[str, tuple[float, float]] = {
    "high": (1e-9, 1e-12),
    "default": (1e-6, 1e-9),
    "low": (1e-3, 1e-6),
    "relative": (1e-9, 0.0),  # high without its absolute part: problems far from O(1) (the units suite)
}
_TOP_KEYS = {"description", "repeat", "rounds", "warmup", "timeout", "first_solve_timeout", "calibrate_each_job",
             "modes", "accuracy", "export", "solvers", "settings", "problems"}
_GROUP_KEYS = {"family", "params", "grid", "seeds", "solvers"}
#: problems one group may make (its grid's combinations x its seeds): a few lines of TOML
#: must not ask for more problems than a run could generate and hold
MAX_GROUP_PROBLEMS = 100_000
_SETTINGS_KEYS = {"solver", "name", "options"}
_EXPORTS = ("npz", "soth")


class SuiteError(HikbenchError):
    """A suite file that cannot be used."""


@dataclass(frozen=True)
class SolverEntry:
    """A (solver, settings) pair to run."""

    solver: str                 # name in results.csv
    spec: str                   # how the worker builds it (registry name, module:Class, external:...)
    settings: str = "default"
    options: dict = field(default_factory=dict)
    strict: bool = True
    warm: bool = False          # supports_warm_start

    def options_json(self) -> str:
        return json.dumps(self.options, sort_keys=True)


@dataclass(frozen=True)
class Task:
    """One row to produce."""

    problem: ProblemSpec
    entry: SolverEntry
    mode: str

    @property
    def key(self) -> tuple[str, str, str, str]:
        return (self.problem.id, self.entry.solver, self.entry.settings, self.mode)


@dataclass
class Suite:
    name: str
    description: str = ""
    repeat: int = 5
    rounds: int = 1
    warmup: int = 1
    timeout: float = 60.0
    first_solve_timeout: float = 300.0
    calibrate_each_job: bool = False
    modes: tuple[str, ...] = ("cold",)
    accuracy: str = "default"
    export: tuple[str, ...] = ("npz",)
    solvers: tuple[str, ...] = ("*",)
    settings: list = field(default_factory=list)
    groups: list = field(default_factory=list)
    source: str = ""

    def problems(self) -> list[tuple[ProblemSpec, tuple[str, ...] | None]]:
        """Every problem with its group's solver patterns (None: the suite's)."""
        out, seen = [], set()
        for g in self.groups:
            grid = dict(g.get("grid", {}))
            for k, v in grid.items():
                if v == "*" and k == "case":
                    from hikbench.problems.generators import DEGENERATE_CASES
                    grid[k] = list(DEGENERATE_CASES)
                elif not isinstance(v, list):
                    grid[k] = [v]
            keys = sorted(grid)
            for combo in itertools.product(*(grid[k] for k in keys)):
                params = {**g.get("params", {}), **dict(zip(keys, combo))}
                for seed in g.get("seeds", [0]):
                    spec = ProblemSpec(g["family"], params, int(seed))
                    if spec.id not in seen:
                        seen.add(spec.id)
                        out.append((spec, tuple(g["solvers"]) if "solvers" in g else None))
        return out

    def to_dict(self) -> dict:
        return {"name": self.name, "source": self.source, "description": self.description,
                "repeat": self.repeat, "rounds": self.rounds, "warmup": self.warmup, "timeout": self.timeout,
                "first_solve_timeout": self.first_solve_timeout, "calibrate_each_job": self.calibrate_each_job,
                "modes": list(self.modes), "accuracy": self.accuracy, "export": list(self.export),
                "solvers": list(self.solvers), "settings": self.settings, "problems": self.groups}


def builtin_suites() -> dict[str, Path]:
    return {p.stem: p for p in sorted(SUITES_DIR.glob("*.toml"))}


def load_suite(name_or_path: str) -> Suite:
    """A built-in suite by name, or a TOML file by path."""
    p = Path(name_or_path)
    builtins = builtin_suites()
    if name_or_path in builtins:
        p = builtins[name_or_path]
    elif not p.is_file():
        raise SuiteError(f"unknown suite {name_or_path!r}: not a file and not one of {', '.join(builtins)}")
    try:
        data = tomllib.loads(p.read_text())
    except tomllib.TOMLDecodeError as err:
        raise SuiteError(f"{p}: invalid TOML ({err})") from err
    except UnicodeDecodeError as err:
        raise SuiteError(f"{p}: not a text file ({err.reason} at byte {err.start}); expected a suite TOML file") \
            from err
    except OSError as err:
        raise SuiteError(f"{p}: cannot read the suite file: {err.strerror or err}") from err
    _resolve_paths(data, p.parent)
    return suite_from_dict(data, name=p.stem, source=str(p))


def _resolve_paths(data: dict, base: Path) -> None:
    """``file.py:attr`` families and solvers given relative to the suite file
    are found next to it (when the file exists there). Values of the wrong
    type are left alone for :func:`suite_from_dict` to reject."""
    def fix(spec):
        if not isinstance(spec, str) or spec.startswith("external:"):
            return spec
        mod, sep, attr = spec.rpartition(":")
        if sep and mod.endswith(".py") and not Path(mod).is_absolute() and (base / mod).exists():
            return f"{(base / mod).resolve()}:{attr}"
        return spec

    if isinstance(data.get("solvers"), list):
        data["solvers"] = [fix(s) for s in data["solvers"]]
    groups = data.get("problems")
    for g in groups if isinstance(groups, list) else ():
        if not isinstance(g, dict):
            continue
        if "family" in g:
            g["family"] = fix(g["family"])
        if isinstance(g.get("solvers"), list):
            g["solvers"] = [fix(s) for s in g["solvers"]]


def _is_int(v) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


class _Checker:
    """Type checks of suite values; errors name the suite file and the key."""

    def __init__(self, where: str):
        self.where = where

    def fail(self, msg: str):
        raise SuiteError(f"suite {self.where}: {msg}")

    def integer(self, d: dict, key: str, default: int, minimum: int, ctx: str = "") -> int:
        v = d.get(key, default)
        if not _is_int(v) or v < minimum:
            self.fail(f"{ctx}{key} = {v!r}: expected an integer >= {minimum}")
        return v

    def positive(self, d: dict, key: str, default: float, ctx: str = "") -> float:
        v = d.get(key, default)
        if not _is_number(v) or v <= 0:
            self.fail(f"{ctx}{key} = {v!r}: expected a number of seconds > 0")
        return float(v)

    def boolean(self, d: dict, key: str, default: bool) -> bool:
        v = d.get(key, default)
        if not isinstance(v, bool):
            self.fail(f"{key} = {v!r}: expected true or false")
        return v

    def string(self, d: dict, key: str, default, ctx: str = "", choices=None) -> str:
        """A string; ``default`` None means required and non-empty."""
        v = d.get(key, default)
        if choices is not None:
            if not isinstance(v, str) or v not in choices:
                self.fail(f"{ctx}{key} {v!r}: expected one of {', '.join(map(repr, choices))}")
        elif not isinstance(v, str) or (default is None and not v):
            self.fail(f"{ctx}{key} = {v!r}: expected a {'non-empty ' if default is None else ''}string")
        return v

    def strings(self, d: dict, key: str, default, ctx: str = "", choices=None, example="") -> list[str]:
        v = d.get(key, default)
        if not isinstance(v, list) or not v or not all(isinstance(x, str) and x for x in v):
            hint = f", e.g. {key} = {example}" if example else ""
            self.fail(f"{ctx}{key} = {v!r}: expected a non-empty list of strings{hint}")
        for x in v:
            if choices is not None and x not in choices:
                self.fail(f"{ctx}{key.removesuffix('s')} {x!r}: "
                          f"expected {' or '.join(map(repr, choices))}")
        return v

    def table(self, d: dict, key: str, ctx: str = "") -> dict:
        v = d.get(key, {})
        if not isinstance(v, dict):
            self.fail(f"{ctx}{key} = {v!r}: expected a table, e.g. {key} = {{ n = 6 }}")
        return v

    def tables(self, d: dict, key: str, header: str) -> list[dict]:
        v = d.get(key, [])
        if not isinstance(v, list) or not all(isinstance(x, dict) for x in v):
            self.fail(f"{key} = {v!r}: expected {header} tables")
        return v


def suite_from_dict(data: dict, name: str, source: str = "") -> Suite:
    """A :class:`Suite` from parsed TOML; every value is checked (SuiteError
    naming the suite file, the key and what was expected)."""
    c = _Checker(source or name)
    bad = set(data) - _TOP_KEYS
    if bad:
        c.fail(f"unknown key(s) {sorted(bad)}; expected some of {sorted(_TOP_KEYS)}")
    groups = c.tables(data, "problems", "[[problems]]")
    if not groups:
        c.fail("no [[problems]] group")
    for i, g in enumerate(groups):
        ctx = f"problems group {i}: "
        if "family" not in g:
            c.fail(f"problems group {i} has no 'family'")
        badg = set(g) - _GROUP_KEYS
        if badg:
            c.fail(f"{ctx}unknown key(s) {sorted(badg)}; expected some of {sorted(_GROUP_KEYS)}")
        c.string(g, "family", None, ctx)
        params = c.table(g, "params", ctx)
        for k, v in c.table(g, "grid", ctx).items():
            if k in params:
                c.fail(f"{ctx}{k!r} is in both params ({params[k]!r}) and grid ({v!r}): expected it in one of "
                       f"them (the grid's values would replace the param)")
            if isinstance(v, list) and not v:
                c.fail(f"{ctx}grid key {k!r} is an empty list: expected at least one value")
            if isinstance(v, dict):
                c.fail(f"{ctx}grid key {k!r} = {v!r}: expected a list of values")
        seeds = g.get("seeds", [0])
        if not isinstance(seeds, list) or not seeds or not all(_is_int(x) for x in seeds):
            c.fail(f"{ctx}seeds = {seeds!r}: expected a non-empty list of integers, e.g. seeds = [0, 1]")
        count = math.prod(len(v) if isinstance(v, list) else 1 for v in c.table(g, "grid", ctx).values()) * len(seeds)
        if count > MAX_GROUP_PROBLEMS:
            c.fail(f"{ctx}its grid and seeds make {count:.3g} problems: expected at most {MAX_GROUP_PROBLEMS} "
                   f"per group (each is generated, kept in memory and saved before any job runs)")
        if "solvers" in g:
            c.strings(g, "solvers", None, ctx, example='["hcod"]')
    settings = c.tables(data, "settings", "[[settings]]")
    seen = set()
    for i, st in enumerate(settings):
        ctx = f"settings {i}: "
        bads = set(st) - _SETTINGS_KEYS
        if bads:
            c.fail(f"{ctx}unknown key(s) {sorted(bads)}; expected some of {sorted(_SETTINGS_KEYS)}")
        for k in ("solver", "name"):
            if k not in st:
                c.fail(f"{ctx}missing key {k!r} (a [[settings]] needs solver, name and options)")
        c.string(st, "solver", None, ctx)
        sname = c.string(st, "name", None, ctx)
        if sname == "default":
            c.fail(f"{ctx}name 'default' is reserved for the solver's own defaults: choose another name")
        c.table(st, "options", ctx)
        if (st["solver"], sname) in seen:
            c.fail(f"{ctx}settings {sname!r} of solver {st['solver']!r} is defined twice")
        seen.add((st["solver"], sname))
    modes = tuple(c.strings(data, "modes", ["cold"], choices=("cold", "warm"), example='["cold", "warm"]'))
    acc = c.string(data, "accuracy", "default", choices=tuple(ACCURACY))
    suite = Suite(name=name, description=c.string(data, "description", ""),
                  repeat=c.integer(data, "repeat", 5, 1), rounds=c.integer(data, "rounds", 1, 1),
                  warmup=c.integer(data, "warmup", 1, 0),
                  timeout=c.positive(data, "timeout", 60.0),
                  first_solve_timeout=c.positive(data, "first_solve_timeout", 300.0),
                  calibrate_each_job=c.boolean(data, "calibrate_each_job", False), modes=modes,
                  accuracy=acc, export=tuple(c.strings(data, "export", ["npz"], choices=_EXPORTS,
                                                       example='["npz"]')),
                  solvers=tuple(c.strings(data, "solvers", ["*"], example='["hcod", "cascade-*"]')),
                  settings=list(settings), groups=groups, source=source)
    if suite.rounds > suite.repeat:
        c.fail(f"rounds = {suite.rounds}: expected at most repeat = {suite.repeat} (each round times at "
               "least one solve of every row)")
    return suite


def _entry_for_object(spec: str, where: str) -> SolverEntry:
    from hikbench.solvers import registry

    obj = solver_info(spec).factory
    mod, _, attr = spec.rpartition(":")
    if mod.endswith(".py") and not Path(mod).is_absolute():  # the workers (Dask) may run in another directory
        spec = f"{Path(mod).resolve()}:{attr}"
    name = getattr(obj, "name", "") or attr
    name = name if isinstance(name, str) else spec
    known = registry.available().get(name)
    if (known is not None and known.factory is not obj) or name in registry.missing():  # (e.g. inherited)
        raise SuiteError(f"{where}: solver {spec!r} is named {name!r} (its attribute `name`), the name of a "
                         f"registered solver, whose rows it would take: give it a name of its own")
    return SolverEntry(solver=name, spec=spec, strict=bool(getattr(obj, "strict", True)),
                       warm=bool(getattr(obj, "supports_warm_start", False)))


def _check_options(entry: SolverEntry, settings_name: str, options: dict, suite_file: str) -> None:
    """Reject settings options the solver would refuse (before anything runs)."""
    from hikbench.solvers import registry

    ctx = f"suite {suite_file}: [[settings]] {settings_name!r}"
    if entry.spec.startswith("external:"):
        if options:
            raise SuiteError(f"{ctx}: solver {entry.solver!r} is external and takes no options; "
                             f"got {sorted(options)}")
        return
    user = ":" in entry.spec  # module:Class or any factory
    try:  # as the worker builds it for every job (hikbench.bench.harness.worker.solver_factory)
        registry.build(solver_info(entry.spec, entry.solver), **options)  # names and values
    except HikbenchError as err:
        raise SuiteError(f"{ctx}: {err}") from err
    except Exception as err:  # a user's factory raises what it likes: reported, never dropped
        if not user:
            raise
        raise SuiteError(f"{ctx}: solver {entry.solver!r} rejected its options {options}: "
                         f"{type(err).__name__}: {err}") from err


def resolve_solvers(patterns, settings=(), where: str = "the suite",
                    suite_file: str = "") -> tuple[list[SolverEntry], dict[str, str]]:
    """Solver entries for ``patterns`` (+ extra settings, whose options are
    checked against their solver), and the skipped ones (name -> why: a known
    solver whose optional backend is not installed, or a glob matching no
    installed solver). A name the registry does not know raises
    SolverNotFoundError. Order: as the patterns list them, registry order
    within a glob."""
    from hikbench.solvers import registry

    avail = registry.available()
    missing = registry.missing()
    entries: list[SolverEntry] = []
    skipped: dict[str, str] = {}
    seen: dict[tuple[str, str], str] = {}  # (name, settings) -> spec

    def add(e: SolverEntry):
        key = (e.solver, e.settings)
        if key not in seen:
            seen[key] = e.spec
            entries.append(e)
        elif seen[key] != e.spec:  # two solvers whose rows would share one key of results.csv
            raise SuiteError(f"{where}: two solvers are named {e.solver!r}: {seen[key]} and {e.spec} "
                             f"(a module:Class solver is named by its attribute `name`: give it one of its own)")

    for pat in patterns:
        pat = registry.ALIASES.get(pat, pat)  # an earlier name of a solver: its rows take the current one
        if pat.startswith("external:"):
            add(parse_external(pat))
        elif ":" in pat:
            add(_entry_for_object(pat, where))
        elif any(c in pat for c in "*?["):
            matched = [n for n in avail if fnmatch.fnmatchcase(n, pat)]
            if not matched:
                skipped[pat] = "pattern matches no installed solver"
            for n in matched:
                info = avail[n]
                add(SolverEntry(n, n, strict=info.strict, warm=info.supports_warm_start))
        elif pat in avail:
            info = avail[pat]
            add(SolverEntry(pat, pat, strict=info.strict, warm=info.supports_warm_start))
        elif pat in missing:
            skipped[pat] = f"not installed: {missing[pat]}"
        else:
            known = list(avail) + [m for m in missing if m not in avail and "." not in m]
            raise SolverNotFoundError(f"unknown solver {pat!r} (in {where}); known solvers: {', '.join(known)} "
                                      f"(or a glob pattern, module:Class, external:NAME=CMD)")
    for s in settings:
        base = [e for e in entries if e.solver == s.get("solver") and e.settings == "default"]
        for e in base:
            options = dict(s.get("options", {}))
            _check_options(e, str(s["name"]), options, suite_file or where)
            add(SolverEntry(e.solver, e.spec, settings=str(s["name"]), options=options,
                            strict=e.strict, warm=e.warm))
    return entries, skipped


def expand(suite: Suite, solver_patterns=None) -> tuple[list[Task], dict[str, str]]:
    """Every task of the suite; ``solver_patterns`` (from --solvers) replaces
    the suite's and the groups' solver lists."""

    tasks: list[Task] = []
    skipped: dict[str, str] = {}
    cache: dict[tuple, list[SolverEntry]] = {}
    suite_file = suite.source or suite.name
    where = "--solvers" if solver_patterns else f"suite {suite_file}"
    for spec, group_pats in suite.problems():
        pats = tuple(solver_patterns) if solver_patterns else (group_pats or suite.solvers)
        if pats not in cache:
            cache[pats], sk = resolve_solvers(pats, suite.settings, where, suite_file)
            skipped.update(sk)
        for entry in cache[pats]:
            for mode in suite.modes:
                if mode == "warm" and not entry.warm:
                    continue
                tasks.append(Task(spec, entry, mode))
    if not solver_patterns:  # a [[settings]] for a solver that is nowhere: most likely a typo
        names = {e.solver for entries in cache.values() for e in entries}
        for i, st in enumerate(suite.settings):
            if st["solver"] not in names and st["solver"] not in skipped:
                raise SuiteError(f"suite {suite_file}: [[settings]] {st['name']!r}: solver "
                                 f"{st['solver']!r} is not one of the suite's solvers "
                                 f"({', '.join(sorted(names)) or 'none'}): expected it in the suite's (or a "
                                 f"group's) solvers, or no [[settings]] for it")
    return tasks, skipped


def parse_external(text: str):
    """``external:NAME=CMD`` -> SolverEntry."""
    body = text[len("external:"):]
    name, sep, cmd = body.partition("=")
    if not sep or not name or not cmd.strip():
        raise HikbenchError(f"{text!r}: expected external:NAME=CMD, e.g. "
                            "external:mysolver='./mysolver {problem} {out}'")
    if "{out}" not in cmd:
        raise HikbenchError(f"{text!r}: CMD must contain the placeholder {{out}} (where x is written)")
    return SolverEntry(solver=f"external:{name}", spec=text, strict=True, warm=False)
