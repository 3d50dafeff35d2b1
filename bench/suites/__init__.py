"""Suites: TOML files listing problem families with parameter grids and seeds,
solvers (names or glob patterns) with settings, repetitions and modes.

Built-in suites live in ``bench/suites/<name>.toml``; ``--suite`` also takes a
path. Schema (every key optional except ``problems``)::

    description = "..."
    repeat = 5              # timed repetitions per row (at least; setting it alone fixes the count)
    samples = 100           # more repetitions, up to this many, for a fast solve (default 100 without repeat)
    sample_time = 0.1       # ... while the row's timed solves add up to less than this (s)
    rounds = 1              # the repetitions split over rounds: round r runs every job once (slow windows)
    warmup = 1              # discarded solves before timing
    timeout = 60.0          # seconds per job (warm-up + repetitions), hard
    first_solve_timeout = 300.0  # allowance for a solver's first solve in a worker process (JIT: hcod ~70 s without a cache)
    certify_timeout = 30.0  # seconds for the exact certificate of one problem's yardstick (docs/verification.md)
    calibrate_each_job = false  # time the calibration kernel around every job (else once per worker)
    modes = ["cold", "warm"]
    accuracy = "default"    # headline verification profile: high, default, low (ACCURACY; every row records all three)
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

    [[scenarios]]               # closed-loop scenarios, run after the problems (hikbench.bench.scenarios.suite)
    name = "reach"              # a shipped scenario or a scenario .toml (relative: next to the suite file)
    robot = "talos"             # optional: a robot name or a .urdf path (default: the scenario's)
    solvers = ["hcod", "cascade-daqp"]  # optional (default: the suite's); patterns as for problems
    warm_start = ["time"]       # optional: modes of the solvers with a warm_start option (default: theirs)
    steps = 700                 # optional: control steps (default: the scenario's)
    repeat = 5                  # optional: timed calls per step (default 5)
    timeout = 600.0             # optional: seconds for one (scenario, solver, mode) run, hard

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
* Repetitions: a suite that sets no ``repeat`` times each row at least 5
  times, then up to ``samples`` = 100 while its timed solves add up to less
  than ``sample_time`` = 0.1 s (every solve under 1 ms gets 100 samples, so
  p99 is measured; hikbench.bench.harness.timing); a suite that sets
  ``repeat`` alone gets exactly that many (the ``ci`` suite: its baselines
  hold 9), and ``samples`` with it raises the count again.
* ``grid = { case = "*" }`` expands to every ``hikbench.problems.generators.DEGENERATE_CASES``
  (family ``hard``: every ``hikbench.problems.testset.cases.CASES``).
* ``grid = { problem = "*" }`` of family ``testset`` expands to every problem id of the set
  ``params.set`` (docs/testset.md).
"""

from __future__ import annotations

import itertools
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

from hikbench.bench.suites.problemset import ProblemSpec
from hikbench.bench.harness.timing import SAMPLE_TIME, SAMPLES
from hikbench.bench.specs import EXTERNAL, OBJECT, PATTERN, REGISTRY, SolverSpec, SolverSpecError, located
from hikbench.problems.errors import HikbenchError
from hikbench.problems.schema import (MAX_COUNT, MAX_SECONDS, Any, Bool, Int, List, Number, Str, Table, Where,
                                      read_toml, short)
from hikbench.problems.verify import PROFILES
from hikbench.solvers.errors import SolverNotFoundError

__all__ = ["ACCURACY", "SolverEntry", "Suite", "Task", "builtin_suites", "load_suite", "resolve_solvers"]

SUITES_DIR = Path(__file__).parent

#: verification profiles: name -> rtol of hikbench.problems.verify.judge (the table is
#: hikbench.problems.verify.PROFILES; a suite's ``accuracy`` is the headline one, column ``verified``)
ACCURACY: dict[str, float] = {name: p.rtol for name, p in PROFILES.items()}
#: problems one group may make (its grid's combinations x its seeds): a few lines of TOML
#: must not ask for more problems than a run could generate and hold
MAX_GROUP_PROBLEMS = 100_000
_EXPORTS = ("npz", "soth")


class SuiteError(HikbenchError):
    """A suite file that cannot be used."""


@dataclass(frozen=True)
class SolverEntry:
    """A (solver, settings) pair to run."""

    solver: str                 # name in results.csv
    spec: SolverSpec            # how the worker builds it (registry name, module:Class, external:...)
    settings: str = "default"
    options: dict = field(default_factory=dict)
    strict: bool = True
    warm: bool = False          # supports_warm_start
    judged_on: str = "rows"     # the hierarchy its x is judged on: "rows" or "row-normalised"

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
    samples: int | None = None  # None: exactly ``repeat`` (see the module docstring)
    sample_time: float = SAMPLE_TIME
    rounds: int = 1
    warmup: int = 1
    timeout: float = 60.0
    first_solve_timeout: float = 300.0
    certify_timeout: float = 30.0
    calibrate_each_job: bool = False
    modes: tuple[str, ...] = ("cold",)
    accuracy: str = "default"
    export: tuple[str, ...] = ("npz",)
    solvers: tuple[str, ...] = ("*",)
    settings: list = field(default_factory=list)
    groups: list = field(default_factory=list)
    scenarios: list = field(default_factory=list)  # [[scenarios]] tables, checked (hikbench.bench.scenarios.suite)
    sequences: tuple[str, ...] = ()  # test sets whose sequences run in order (hikbench.bench.testset.sequences)
    source: str = ""

    def problems(self) -> list[tuple[ProblemSpec, tuple[str, ...] | None]]:
        """Every problem with its group's solver patterns (None: the suite's)."""
        out, seen = [], set()
        for g in self.groups:
            grid = dict(g.get("grid", {}))
            for k, v in grid.items():
                if v == "*" and k == "case" and g["family"] == "hard":
                    from hikbench.problems.testset.cases import CASES
                    grid[k] = list(CASES)
                elif v == "*" and k == "case":
                    from hikbench.problems.generators import DEGENERATE_CASES
                    grid[k] = list(DEGENERATE_CASES)
                elif v == "*" and k == "problem" and g["family"] == "testset":
                    from hikbench.problems.testset import TestSet
                    grid[k] = [e.id for e in TestSet.read(g.get("params", {}).get("set", "hlsp-1")).entries]
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
                "repeat": self.repeat, "samples": self.samples, "sample_time": self.sample_time,
                "rounds": self.rounds, "warmup": self.warmup, "timeout": self.timeout,
                "first_solve_timeout": self.first_solve_timeout, "certify_timeout": self.certify_timeout,
                "calibrate_each_job": self.calibrate_each_job,
                "modes": list(self.modes), "accuracy": self.accuracy, "export": list(self.export),
                "solvers": list(self.solvers), "settings": self.settings, "problems": self.groups,
                "scenarios": self.scenarios, "sequences": list(self.sequences)}


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
    data = read_toml(p, SuiteError, "a suite TOML file")
    _resolve_paths(data, p.parent)
    return suite_from_dict(data, name=p.stem, source=str(p))


def _resolve_paths(data: dict, base: Path) -> None:
    """``file.py:attr`` families and solvers given relative to the suite file
    are found next to it (when the file exists there). Values of the wrong
    type are left alone for :func:`suite_from_dict` to reject."""
    def fix(spec):
        return located(spec, base) if isinstance(spec, str) else spec

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
    entries = data.get("scenarios")
    for e in entries if isinstance(entries, list) else ():
        if not isinstance(e, dict):
            continue
        if isinstance(e.get("solvers"), list):
            e["solvers"] = [fix(s) for s in e["solvers"]]
        for key, suffix in (("name", ".toml"), ("robot", ".urdf")):  # (files next to the suite file)
            v = e.get(key)
            if isinstance(v, str) and v.endswith(suffix) and not Path(v).is_absolute():
                e[key] = str((base / v).resolve())


_SECONDS = Number(0, MAX_SECONDS, low_open=True, what=f"a number of seconds > 0 and <= {MAX_SECONDS:g} (a week)")
_COUNT = Int(1, MAX_COUNT)
_NAMES = 'a non-empty list of strings, e.g. solvers = ["hcod", "cascade-*"]'
_GROUP = Table({
    "family": Str(what="a non-empty string: a `hikbench list families` name or module:function"),
    "params": Table(values=Any(), what="a table, e.g. params = { n = 6 }"),
    "grid": Table(values=Any(), what="a table of lists, e.g. grid = { n = [6, 12] }"),
    "seeds": List(Int(0, 2**63 - 1), what="a non-empty list of integers >= 0, e.g. seeds = [0, 1]"),
    "solvers": List(Str(), what=_NAMES),
}, required=("family",), what="a [[problems]] table")
_SETTINGS = Table({"solver": Str(what="a solver name"), "name": Str(what="a settings name"),
                   "options": Table(values=Any(), what="a table, e.g. options = { accuracy = \"low\" }")},
                  required=("solver", "name"), what="a [[settings]] table")
_SCENARIO = Table({
    "name": Str(what="a non-empty string: a shipped scenario (`hikbench scenario --list`) or a scenario .toml"),
    "robot": Str(what="a non-empty string: a robot name (`hikbench list robots`) or a .urdf path"),
    "solvers": List(Str(), what=_NAMES),
    "warm_start": List(Str(), what='a non-empty list of strings, e.g. warm_start = ["none", "time"]'),
    "steps": _COUNT, "repeat": _COUNT, "timeout": _SECONDS,
}, required=("name",), what="a [[scenarios]] table")
#: the suite file (see the module docstring); solver options are checked against their solvers later
SCHEMA = Table({
    "description": Str(empty=True), "repeat": _COUNT, "samples": _COUNT, "sample_time": _SECONDS,
    "rounds": _COUNT, "warmup": Int(0, MAX_COUNT),
    "timeout": _SECONDS, "first_solve_timeout": _SECONDS, "certify_timeout": _SECONDS, "calibrate_each_job": Bool(),
    "modes": List(Str(("cold", "warm")), what='a non-empty list of strings, e.g. modes = ["cold", "warm"]'),
    "accuracy": Str(tuple(ACCURACY)),
    "export": List(Str(_EXPORTS), what='a non-empty list of strings, e.g. export = ["npz"]'),
    "solvers": List(Str(), what=_NAMES),
    "settings": List(_SETTINGS, min_len=0, what="[[settings]] tables"),
    "problems": List(_GROUP, what="[[problems]] tables (at least one)"),
    "scenarios": List(_SCENARIO, min_len=0, what="[[scenarios]] tables"),
    "sequences": List(Str(), min_len=0, what='a list of test set names, e.g. sequences = ["hlsp-1"]'),
}, required=("problems",), defaults={
    "description": "", "repeat": 5, "sample_time": SAMPLE_TIME, "rounds": 1, "warmup": 1, "timeout": 60.0,
    "first_solve_timeout": 300.0, "certify_timeout": 30.0,
    "calibrate_each_job": False, "modes": ["cold"], "accuracy": "default", "export": ["npz"],
    "solvers": ["*"], "settings": [], "scenarios": [], "sequences": []})


def suite_from_dict(data: dict, name: str, source: str = "") -> Suite:
    """A :class:`Suite` from parsed TOML; every value is checked against :data:`SCHEMA`
    (SuiteError naming the suite file, the key path and what was expected)."""
    at = Where(f"suite {source or name}", SuiteError)
    d = SCHEMA.check(data, "", at)
    samples = d.get("samples", None if "repeat" in data else SAMPLES)  # (repeat alone: a fixed count)
    for i, g in enumerate(d["problems"]):
        _check_grid(g, f"problems[{i}]", at)
    seen = set()
    for i, st in enumerate(d["settings"]):
        if st["name"] == "default":
            at.say(f"settings[{i}].name 'default' is reserved for the solver's own defaults: expected "
                   "another name")
        if (st["solver"], st["name"]) in seen:
            at.say(f"settings[{i}]: settings {st['name']!r} of solver {st['solver']!r} is defined twice")
        seen.add((st["solver"], st["name"]))
    if d["rounds"] > d["repeat"]:
        at.say(f"rounds = {d['rounds']}: expected at most repeat = {d['repeat']} (each round times at "
               "least one solve of every row)")
    return Suite(name=name, description=d["description"], repeat=d["repeat"], samples=samples,
                 sample_time=float(d["sample_time"]), rounds=d["rounds"],
                 warmup=d["warmup"], timeout=float(d["timeout"]), first_solve_timeout=float(d["first_solve_timeout"]),
                 certify_timeout=float(d["certify_timeout"]),
                 calibrate_each_job=d["calibrate_each_job"], modes=tuple(d["modes"]), accuracy=d["accuracy"],
                 export=tuple(d["export"]), solvers=tuple(d["solvers"]), settings=d["settings"],
                 groups=d["problems"], scenarios=d["scenarios"], sequences=tuple(d["sequences"]), source=source)


def _check_grid(g: dict, path: str, at: Where) -> None:
    """A group's grid: lists of values (or one value), none empty, no key also in params."""
    params = g.get("params", {})
    for k, v in g.get("grid", {}).items():
        if k in params:
            at.say(f"{path}: {k!r} is in both params ({short(params[k])}) and grid ({short(v)}): expected it "
                   f"in one of them (the grid's values would replace the param)")
        if isinstance(v, list) and not v:
            at.fail(f"{path}.grid.{k}", v, "at least one value")
        if isinstance(v, dict):
            at.fail(f"{path}.grid.{k}", v, "a list of values")
    count = math.prod(len(v) if isinstance(v, list) else 1 for v in g.get("grid", {}).values())
    count *= len(g.get("seeds", [0]))
    if count > MAX_GROUP_PROBLEMS:
        at.say(f"{path}: its grid and seeds make {count:.3g} problems: expected at most {MAX_GROUP_PROBLEMS} "
               f"per group (each is generated, kept in memory and saved before any job runs)")


def _entry_for_object(spec: SolverSpec, where: str) -> SolverEntry:
    from hikbench.solvers import registry

    obj = spec.info().factory
    spec = spec.located()  # the workers (Dask) may run in another directory
    name = getattr(obj, "name", "") or spec.text.rpartition(":")[2]
    name = name if isinstance(name, str) else spec.text
    known = registry.available().get(name)
    if (known is not None and known.factory is not obj) or name in registry.missing():  # (e.g. inherited)
        raise SuiteError(f"{where}: solver {spec.text!r} is named {name!r} (its attribute `name`), the name of a "
                         f"registered solver, whose rows it would take: give it a name of its own")
    strict = getattr(obj, "strict", True)
    if not isinstance(strict, bool):  # (its claim decides how every row of it is judged: no guessing)
        raise SuiteError(f"{where}: solver {spec.text!r} has strict = {strict!r}: expected True or False (True: it "
                         f"returns the lexicographic optimum; False: weighted, damped, not strict)")
    judged_on = getattr(obj, "judged_on", "rows")
    if judged_on not in ("rows", "row-normalised"):
        raise SuiteError(f"{where}: solver {spec.text!r} has judged_on = {judged_on!r}: expected 'rows' or "
                         f"'row-normalised' (the hierarchy its levels are: hikbench.solvers.base.Solver.judged_on)")
    return SolverEntry(solver=name, spec=spec, strict=strict, warm=bool(getattr(obj, "supports_warm_start", False)),
                       judged_on=judged_on)


def _judged_on(info, options: dict) -> str:
    """What a registry solver built with ``options`` claims its levels are
    (:attr:`hikbench.solvers.registry.SolverInfo.judged_on`): ``"rows"`` or ``"row-normalised"``."""
    from hikbench.solvers import registry

    return info.judged_on(registry.check_buildable(info, **options)) if info.judged_on else "rows"


def _check_options(entry: SolverEntry, settings_name: str, options: dict, suite_file: str) -> None:
    """Reject settings options the solver would refuse (before anything runs)."""
    from hikbench.solvers import registry

    ctx = f"suite {suite_file}: [[settings]] {settings_name!r}"
    if entry.spec.kind == EXTERNAL:
        if options:
            raise SuiteError(f"{ctx}: solver {entry.solver!r} is external and takes no options; "
                             f"got {sorted(options)}")
        return
    user = entry.spec.kind == OBJECT  # module:Class or any factory
    try:  # as the worker builds it for every job (hikbench.bench.specs.SolverSpec.factory)
        registry.build(entry.spec.info(entry.solver), **options)  # names and values
    except HikbenchError as err:
        raise SuiteError(f"{ctx}: {err}") from err
    except Exception as err:  # a user's factory raises what it likes: reported, never dropped
        if not user:
            raise
        raise SuiteError(f"{ctx}: solver {entry.solver!r} rejected its options {options}: "
                         f"{type(err).__name__}: {err}") from err


def _check_constructible(entry: SolverEntry, where: str) -> None:
    """SuiteError naming the solver and the argument when the worker could not build it
    with its options (a ``module:Class`` whose constructor needs an argument): refused
    before any job, as ``solve`` refuses it, rather than one error row per job."""
    from hikbench.solvers import registry

    if entry.spec.kind == EXTERNAL:
        return
    try:
        registry.check_buildable(entry.spec.info(entry.solver), **entry.options)
    except HikbenchError as err:
        raise SuiteError(f"{where}: {err}") from err


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
    seen: dict[tuple[str, str], SolverSpec] = {}  # (name, settings) -> spec

    def add(e: SolverEntry):
        key = (e.solver, e.settings)
        if key not in seen:
            if e.settings == "default":  # (a [[settings]]'s options are checked by _check_options)
                _check_constructible(e, where)
            seen[key] = e.spec
            entries.append(e)
        elif seen[key] != e.spec:  # two solvers whose rows would share one key of results.csv
            raise SuiteError(f"{where}: two solvers are named {e.solver!r}: {seen[key]} and {e.spec} "
                             f"(a module:Class solver is named by its attribute `name`: give it one of its own)")

    for text in patterns:
        spec = _parse(text, where)  # (an earlier name of a solver: its rows take the current one)
        pat = spec.text
        if spec.kind == EXTERNAL:
            add(_external_entry(spec))
        elif spec.kind == OBJECT:
            add(_entry_for_object(spec, where))
        elif spec.kind == PATTERN:
            matched = spec.matches(avail)
            if not matched:
                skipped[pat] = "pattern matches no installed solver"
            for n in matched:
                add(_registry_entry(n, avail[n]))
        elif pat in avail:
            add(_registry_entry(pat, avail[pat]))
        elif pat in missing:
            skipped[pat] = f"not installed: {missing[pat]}"
        else:
            known = list(avail) + [m for m in missing if m not in avail and "." not in m]
            raise SolverNotFoundError(f"unknown solver {pat!r} (in {where}){registry.close_match(pat, known)}; "
                                      f"known solvers: {', '.join(known)} "
                                      f"(or a glob pattern, module:Class, external:NAME=CMD)")
    for s in settings:
        base = [e for e in entries if e.solver == s.get("solver") and e.settings == "default"]
        for e in base:
            options = dict(s.get("options", {}))
            _check_options(e, str(s["name"]), options, suite_file or where)
            judged_on = _judged_on(avail[e.spec.text], options) if e.spec.kind == REGISTRY else e.judged_on
            add(SolverEntry(e.solver, e.spec, settings=str(s["name"]), options=options,
                            strict=e.strict, warm=e.warm, judged_on=judged_on))
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


def _parse(text: str, where: str) -> SolverSpec:
    """:meth:`SolverSpec.parse`, its error a SuiteError naming ``where`` (the suite file, or --solvers)."""
    try:
        return SolverSpec.parse(text)
    except SolverSpecError as err:
        raise SuiteError(f"{where}: {err}") from None


def _registry_entry(name: str, info) -> SolverEntry:
    return SolverEntry(name, SolverSpec(name, REGISTRY), strict=info.strict,
                       warm=info.supports_warm_start, judged_on=_judged_on(info, {}))


def _external_entry(spec: SolverSpec) -> SolverEntry:
    return SolverEntry(solver=spec.name, spec=spec, strict=spec.external.strict, warm=False)


def parse_external(text: str, where: str = "--solvers") -> SolverEntry:
    """``external:NAME=CMD`` or ``external:NAME[strict=false]=CMD``
    (hikbench.bench.specs.parse_spec) -> SolverEntry; SuiteError
    naming ``where`` (the suite file, or --solvers) and the spec otherwise."""
    spec = _parse(text, where)
    if spec.kind != EXTERNAL:
        raise SuiteError(f"{where}: {text!r}: expected external:NAME=CMD, e.g. "
                         f"external:mysolver='./mysolver {{problem}} {{out}}'")
    return _external_entry(spec)
