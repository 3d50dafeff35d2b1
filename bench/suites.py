"""Suites: TOML files listing problem families with parameter grids and seeds,
solvers (names or glob patterns) with settings, repetitions and modes.

Built-in suites live in ``bench/suites/<name>.toml``; ``--suite`` also takes a
path. Schema (every key optional except ``problems``)::

    description = "..."
    repeat = 5              # timed repetitions per row
    warmup = 1              # discarded solves before timing
    timeout = 60.0          # seconds per job (warm-up + repetitions), hard
    first_solve_timeout = 60.0  # allowance for a solver's first solve in a worker process (JIT)
    calibrate_each_job = false  # time the calibration kernel around every job (else once per worker)
    modes = ["cold", "warm"]
    accuracy = "default"    # verification profile, see ACCURACY
    export = ["npz"]        # problem files written to OUT/problems/ ("npz", "soth")
    solvers = ["*"]         # names, glob patterns ("cascade-*"), module:Class, external:NAME=CMD

    [[settings]]            # extra settings of a solver (every solver also runs "default")
    solver = "cascade-osqp"
    name = "tight"
    options = { eps_abs = 1e-9 }

    [[problems]]
    family = "equality"          # FAMILIES name or module:function
    params = { rows = 6 }              # fixed parameters
    grid = { n = [6, 12], depth = [2, 4] }   # Cartesian product
    seeds = [0, 1]
    solvers = ["hcod", "nullspace-*"]  # optional: restricts this group

Decisions (README, "Suites"):

* ``warm`` mode runs only for solvers with ``supports_warm_start`` (for the
  others it would time the same cold solve twice); external solvers run cold.
* A solver named explicitly but not installed is reported on stderr and in
  run.json (``skipped_solvers``) with its install hint, and gets no rows; a
  glob pattern matches installed solvers only.
* ``grid = { case = "*" }`` expands to every ``problems.generators.DEGENERATE_CASES``.
"""

from __future__ import annotations

import fnmatch
import itertools
import json
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from bench.problemset import ProblemSpec, load_object
from problems.errors import HikbenchError

__all__ = ["Suite", "SolverEntry", "Task", "load_suite", "builtin_suites", "resolve_solvers", "ACCURACY"]

SUITES_DIR = Path(__file__).with_name("suites")

#: verification profiles: name -> (rtol, atol) of problems.verify.verify
ACCURACY: dict[str, tuple[float, float]] = {
    "high": (1e-9, 1e-12),
    "default": (1e-6, 1e-9),
    "low": (1e-3, 1e-6),
}
_TOP_KEYS = {"description", "repeat", "warmup", "timeout", "first_solve_timeout", "calibrate_each_job", "modes",
             "accuracy", "export", "solvers", "settings", "problems"}
_GROUP_KEYS = {"family", "params", "grid", "seeds", "solvers"}


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
    warmup: int = 1
    timeout: float = 60.0
    first_solve_timeout: float = 60.0
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
                    from problems.generators import DEGENERATE_CASES
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
                "repeat": self.repeat, "warmup": self.warmup, "timeout": self.timeout,
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
    elif not p.exists():
        raise SuiteError(f"unknown suite {name_or_path!r}: not a file and not one of {', '.join(builtins)}")
    try:
        data = tomllib.loads(p.read_text())
    except tomllib.TOMLDecodeError as err:
        raise SuiteError(f"{p}: invalid TOML ({err})") from err
    _resolve_paths(data, p.parent)
    return suite_from_dict(data, name=p.stem, source=str(p))


def _resolve_paths(data: dict, base: Path) -> None:
    """``file.py:attr`` families and solvers given relative to the suite file
    are found next to it (when the file exists there)."""
    def fix(spec):
        if not isinstance(spec, str) or spec.startswith("external:"):
            return spec
        mod, sep, attr = spec.rpartition(":")
        if sep and mod.endswith(".py") and not Path(mod).is_absolute() and (base / mod).exists():
            return f"{(base / mod).resolve()}:{attr}"
        return spec

    data["solvers"] = [fix(s) for s in data.get("solvers", ["*"])]
    for g in data.get("problems", []):
        g["family"] = fix(g.get("family"))
        if "solvers" in g:
            g["solvers"] = [fix(s) for s in g["solvers"]]


def suite_from_dict(data: dict, name: str, source: str = "") -> Suite:
    bad = set(data) - _TOP_KEYS
    if bad:
        raise SuiteError(f"suite {name}: unknown key(s) {sorted(bad)}; expected some of {sorted(_TOP_KEYS)}")
    groups = data.get("problems", [])
    if not groups:
        raise SuiteError(f"suite {name}: no [[problems]] group")
    for i, g in enumerate(groups):
        if "family" not in g:
            raise SuiteError(f"suite {name}: problems group {i} has no 'family'")
        badg = set(g) - _GROUP_KEYS
        if badg:
            raise SuiteError(f"suite {name}: problems group {i}: unknown key(s) {sorted(badg)}; "
                             f"expected some of {sorted(_GROUP_KEYS)}")
    modes = tuple(data.get("modes", ["cold"]))
    for m in modes:
        if m not in ("cold", "warm"):
            raise SuiteError(f"suite {name}: mode {m!r}: expected 'cold' or 'warm'")
    acc = data.get("accuracy", "default")
    if acc not in ACCURACY:
        raise SuiteError(f"suite {name}: accuracy {acc!r}: expected one of {', '.join(ACCURACY)}")
    suite = Suite(name=name, description=data.get("description", ""), repeat=int(data.get("repeat", 5)),
                  warmup=int(data.get("warmup", 1)), timeout=float(data.get("timeout", 60.0)),
                  first_solve_timeout=float(data.get("first_solve_timeout", 60.0)),
                  calibrate_each_job=bool(data.get("calibrate_each_job", False)), modes=modes,
                  accuracy=acc, export=tuple(data.get("export", ["npz"])),
                  solvers=tuple(data.get("solvers", ["*"])), settings=list(data.get("settings", [])),
                  groups=groups, source=source)
    if suite.repeat < 1:
        raise SuiteError(f"suite {name}: repeat must be >= 1; got {suite.repeat}")
    return suite


def _entry_for_object(spec: str) -> SolverEntry:
    obj = load_object(spec)
    name = getattr(obj, "name", "") or spec.rpartition(":")[2]
    return SolverEntry(solver=name if isinstance(name, str) else spec, spec=spec, strict=bool(getattr(obj,
                                                                                                      "strict", True)),
                       warm=bool(getattr(obj, "supports_warm_start", False)))


def resolve_solvers(patterns, settings=()) -> tuple[list[SolverEntry], dict[str, str]]:
    """Solver entries for ``patterns`` (+ extra settings), and the skipped ones
    (name -> why). Order: as the patterns list them, registry order within a glob."""
    from solvers import registry

    avail = registry.available()
    entries: list[SolverEntry] = []
    skipped: dict[str, str] = {}
    seen = set()

    def add(e: SolverEntry):
        if (e.solver, e.settings) not in seen:
            seen.add((e.solver, e.settings))
            entries.append(e)

    for pat in patterns:
        if pat.startswith("external:"):
            from bench.external import parse_external
            add(parse_external(pat))
        elif ":" in pat:
            add(_entry_for_object(pat))
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
        else:
            hint = registry.missing().get(pat, "")
            skipped[pat] = f"not installed: {hint}" if hint else "unknown solver (see `hikbench list solvers`)"
    for s in settings:
        base = [e for e in entries if e.solver == s.get("solver") and e.settings == "default"]
        for e in base:
            add(SolverEntry(e.solver, e.spec, settings=str(s["name"]), options=dict(s.get("options", {})),
                            strict=e.strict, warm=e.warm))
    return entries, skipped


def expand(suite: Suite, solver_patterns=None) -> tuple[list[Task], dict[str, str]]:
    """Every task of the suite; ``solver_patterns`` (from --solvers) replaces
    the suite's and the groups' solver lists."""
    tasks: list[Task] = []
    skipped: dict[str, str] = {}
    cache: dict[tuple, list[SolverEntry]] = {}
    for spec, group_pats in suite.problems():
        pats = tuple(solver_patterns) if solver_patterns else (group_pats or suite.solvers)
        if pats not in cache:
            cache[pats], sk = resolve_solvers(pats, suite.settings)
            skipped.update(sk)
        for entry in cache[pats]:
            for mode in suite.modes:
                if mode == "warm" and not entry.warm:
                    continue
                tasks.append(Task(spec, entry, mode))
    return tasks, skipped
