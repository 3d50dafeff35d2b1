"""A solver's spelling, parsed once: :class:`SolverSpec`.

Wherever hikbench takes a solver (``run --solvers``, a suite's ``solvers`` and its
groups' and ``[[scenarios]]``' lists, ``solve --solver``, ``scenario --solver``, the job a
worker receives), it is one of these spellings, told apart from the text alone::

    hcod, cascade-daqp         REGISTRY    a registered solver (an earlier name: hikbench.solvers.registry.ALIASES)
    cascade-*, nullspace-?     PATTERN     a glob over the installed registry names
    pkg.module:Class           OBJECT      an importable class (or factory) with solve(hierarchy)
    path/to/file.py:Class      OBJECT      the same, from a file
    external:NAME=CMD          EXTERNAL    a program (bench/harness/external.py runs it);
    external:NAME[strict=false]=CMD        one that does not return the lexicographic optimum
    pink                       CONTROLLER  a scenario controller (``hikbench scenario`` only,
                                           bench/scenarios/controllers.py)

:meth:`SolverSpec.parse` checks an external program's spelling (its NAME, CMD's quotes,
placeholders and ``{out}``, the program on PATH) at once; a registry name or a
``module:Class`` is looked up or imported by :meth:`SolverSpec.info`, where a worker builds it.
:func:`warm_start_modes` gives the warm-start modes a solver runs in (the values of its
``warm_start`` option: hcod's none / stage / time).
"""

from __future__ import annotations

import difflib
import fnmatch
import importlib
import importlib.util
import inspect
import os
import re
import shlex
import shutil
import sys
import traceback
from dataclasses import dataclass
from pathlib import Path

from hikbench.problems.errors import HikbenchError
from hikbench.solvers import registry

__all__ = ["CONTROLLER", "EXTERNAL", "OBJECT", "PATTERN", "PLACEHOLDERS", "REGISTRY", "SPEC_KEYS", "ExternalSpec",
           "SolverSpec", "SolverSpecError", "command_argv", "external_command", "load_object", "located", "parse_spec",
           "raised_text", "solver_info", "warm_start_default", "warm_start_modes"]

#: the kinds of spelling (module docstring)
REGISTRY, PATTERN, OBJECT, EXTERNAL, CONTROLLER = "registry", "pattern", "object", "external", "controller"
_EXTERNAL = "external:"
_GLOB = "*?["


class SolverSpecError(HikbenchError, ValueError):
    """A solver spelling that cannot be used; the message starts with the spelling."""


@dataclass(frozen=True)
class ExternalSpec:
    """``external:NAME[strict=...]=CMD`` parsed: ``name`` (NAME), ``strict``, ``command`` (CMD)."""

    name: str
    strict: bool
    command: str


@dataclass(frozen=True)
class SolverSpec:
    """One solver spelling: ``text`` as given (what a worker's job carries), its ``kind``
    (:data:`REGISTRY`, :data:`PATTERN`, :data:`OBJECT`, :data:`EXTERNAL`, :data:`CONTROLLER`)
    and, for an external program, its parsed ``external``."""

    text: str
    kind: str
    external: ExternalSpec | None = None

    @classmethod
    def parse(cls, text: str, *, controllers: bool = False) -> SolverSpec:
        """The spec of ``text`` (a registry alias becomes the current name); ``controllers``:
        a scenario controller's name is one (``hikbench scenario``). SolverSpecError
        ``'TEXT': what is wrong`` for an external spelling that cannot run (:func:`parse_spec`)."""
        if text.startswith(_EXTERNAL):
            try:
                return cls(text, EXTERNAL, parse_spec(text))
            except ValueError as err:
                raise SolverSpecError(f"{text!r}: {err}") from None
        if ":" in text:
            return cls(text, OBJECT)
        if controllers:
            from hikbench.bench.scenarios.controllers import is_controller
            if is_controller(text):
                return cls(text, CONTROLLER)
        if any(c in text for c in _GLOB):
            return cls(text, PATTERN)
        return cls(registry.ALIASES.get(text, text), REGISTRY)

    def __str__(self) -> str:
        return self.text

    @property
    def name(self) -> str:
        """The name of its rows where the text decides it: a registry name, ``external:NAME``;
        an object's is its attribute ``name`` (hikbench.bench.suites), a pattern has none."""
        return f"{_EXTERNAL}{self.external.name}" if self.external else self.text

    def located(self, base: Path | None = None) -> SolverSpec:
        """This spec with a relative ``file.py`` made absolute (:func:`located`)."""
        return self if self.kind != OBJECT else SolverSpec(located(self.text, base), OBJECT)

    def matches(self, names) -> list[str]:
        """The names of ``names`` (in their order) this PATTERN matches."""
        return [n for n in names if fnmatch.fnmatchcase(n, self.text)]

    def info(self, name: str = "") -> registry.SolverInfo:
        """The :class:`~hikbench.solvers.registry.SolverInfo` of a REGISTRY name
        (SolverNotFoundError when unknown or not installed, as for a PATTERN), or one made
        for an OBJECT (its factory the object, named ``name`` or the text, no default
        options; HikbenchError when it cannot be imported or is no solver)."""
        if self.kind == OBJECT:
            obj = load_object(self.text)
            if not callable(obj) or (isinstance(obj, type) and not callable(getattr(obj, "solve", None))):
                raise HikbenchError(f"{self.text!r} is not a solver: expected a class with a solve(hierarchy) "
                                    f"method (a hikbench.solvers.base.Solver subclass) or a factory returning one")
            return registry.SolverInfo(name or self.text, "", obj, strict=bool(getattr(obj, "strict", True)))
        if self.kind == EXTERNAL:
            raise HikbenchError(f"{self.text!r}: an external program is no solver object (`hikbench run --solvers` "
                                f"runs it): expected a registry name or module:Class")
        if self.kind == CONTROLLER:
            raise HikbenchError(f"{self.text!r}: a controller is no solver object (`hikbench scenario --solver` "
                                f"runs it): expected a registry name or module:Class")
        return registry.get(self.text)  # (a pattern too: no solver is named so, SolverNotFoundError says which are)

    def factory(self, options: dict):
        """A zero-argument callable building a fresh solver with ``options``
        (:func:`hikbench.solvers.registry.build`: option names checked against the factory)."""
        info = self.info()
        return lambda: registry.build(info, **options)


def located(text: str, base: Path | None = None) -> str:
    """``text`` (a solver's or a family's spelling) with the relative ``file.py`` of a
    ``file.py:attr`` made absolute: found in ``base`` (a suite file's folder) when it
    exists there, else unchanged; ``base`` None: against the current directory (the
    workers may run in another one). Every other spelling unchanged."""
    mod, sep, attr = text.rpartition(":")
    if text.startswith(_EXTERNAL) or not sep or not mod.endswith(".py") or Path(mod).is_absolute():
        return text
    if base is not None and not (base / mod).exists():
        return text
    return f"{(Path(mod) if base is None else base / mod).resolve()}:{attr}"


def solver_info(text: str, name: str = "") -> registry.SolverInfo:
    """``SolverSpec.parse(text).info(name)``: the SolverInfo of a registry name or a ``module:Class``."""
    return SolverSpec.parse(text).info(name)


def warm_start_default(info: registry.SolverInfo) -> str | None:
    """The default warm-start mode of a solver with the HCOD modes (none / stage /
    time): its registered option, or, for a ``module:Class`` solver, the default
    of the factory's ``warm_start`` parameter; None for a solver without one."""
    if "warm_start" in info.options:
        return str(info.options["warm_start"])
    if "warm_start" not in (registry.option_names(info) or ()):
        return None
    param = inspect.signature(info.factory).parameters["warm_start"]
    if param.default is param.empty:
        raise HikbenchError(f"solver {info.name!r}: its warm_start parameter has no default value; "
                            f"expected one (none, stage or time)")
    return str(param.default)


def warm_start_modes(info: registry.SolverInfo, asked=(), option=None) -> list:
    """The warm-start modes a solver runs in, one run each: ``[None]`` for a solver without
    a ``warm_start`` option; else the modes ``asked`` (``--warm-start``, a ``[[scenarios]]``'s
    ``warm_start``), or the one ``option`` (a ``warm_start`` the solver's options set),
    or its default (:func:`warm_start_default`)."""
    default = warm_start_default(info)
    if default is None:
        return [None]
    if asked:
        return list(asked)
    return [default if option is None else option]


# ---- module:attr and file.py:attr -------------------------------------------------------------


def load_object(spec: str):
    """Import ``module.path:attr`` or ``/path/to/file.py:attr`` (a solver's or a family's)."""
    modname, sep, attr = spec.rpartition(":")
    if not sep or not modname or not attr:
        raise HikbenchError(f"{spec!r}: expected 'module:attribute' or 'file.py:attribute'")
    if modname.endswith(".py"):
        path = Path(modname)
        if not path.exists():
            raise HikbenchError(f"{spec!r}: no such file {path}")
        mod = _load_file(spec, path)
    else:
        try:
            mod = importlib.import_module(modname)
        except ModuleNotFoundError as err:
            hint = (f"; the current directory is not searched: give the file ({modname.replace('.', '/')}.py:"
                    f"{attr}) or set PYTHONPATH" if Path(modname.replace(".", "/") + ".py").exists() else "")
            raise HikbenchError(f"{spec!r}: cannot import module {modname!r} ({err}){hint}") from err
        except Exception as err:  # noqa: BLE001 - the user's module failed at import: name it, no traceback
            raise HikbenchError(f"{spec!r}: importing module {modname!r} raised {raised_text(err)}") from err
    try:
        return getattr(mod, attr)
    except AttributeError as err:
        raise HikbenchError(f"{spec!r}: module {modname!r} has no attribute {attr!r}") from err


def _load_file(spec: str, path: Path):
    """The module of a user's ``file.py``, imported once per process as
    ``_hikbench_user_<path>``, with its directory on ``sys.path`` meanwhile (as
    ``python file.py`` has it: a sibling module imports). An exception at import
    is a HikbenchError naming the file and line, and leaves no half-made module."""
    name = "_hikbench_user_" + re.sub(r"\W", "_", str(path.resolve()))
    mod = sys.modules.get(name)
    if mod is not None:
        return mod
    s = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(s)
    sys.modules[name] = mod
    where = str(path.resolve().parent)
    sys.path.insert(0, where)
    try:
        s.loader.exec_module(mod)
    except BaseException as err:
        del sys.modules[name]
        if not isinstance(err, Exception):  # KeyboardInterrupt, SystemExit: not the file's answer
            raise
        raise HikbenchError(f"{spec!r}: importing {path} raised {raised_text(err)}") from err
    finally:
        sys.path.remove(where)
    return mod


def raised_text(err: Exception) -> str:
    """``Type: message at file:line`` of an exception from a user's code."""
    tb = traceback.extract_tb(err.__traceback__)
    where = f" at {os.path.basename(tb[-1].filename)}:{tb[-1].lineno}" if tb else ""
    return f"{type(err).__name__}: {err}" + ("" if isinstance(err, SyntaxError) else where)  # (names its line)


# ---- external:NAME[strict=...]=CMD ------------------------------------------------------------

#: the declarations an external spec takes in brackets, ``external:NAME[strict=false]=CMD``
SPEC_KEYS = ("strict",)
_BOOLS = {"true": True, "false": False}
#: the placeholders CMD may hold (replaced by paths for every solve)
PLACEHOLDERS = ("{problem}", "{problem_soth}", "{out}")
# a word in braces, not a shell's ${NAME}: what a placeholder looks like, known or misspelt
_PLACEHOLDER = re.compile(r"(?<!\$)\{([A-Za-z_][A-Za-z0-9_]*)\}")


def parse_spec(text: str) -> ExternalSpec:
    """Parse ``external:NAME=CMD`` or ``external:NAME[strict=true|false]=CMD``;
    ValueError naming what is wrong (NAME missing, CMD without ``{out}``, an
    unknown key in the brackets with its closest known one, a strict value
    other than true or false, CMD's program not found)."""
    name, decl, cmd = _split(text)
    if not name or not cmd.strip():
        raise ValueError("expected external:NAME=CMD, e.g. external:mysolver='./mysolver {problem} {out}'")
    if "{out}" not in cmd:
        raise ValueError("CMD must contain the placeholder {out} (where x is written)")
    strict = _declarations(decl)
    _check_program(command_argv(cmd))
    return ExternalSpec(name, strict, cmd)


def external_command(text: str) -> str:
    """CMD of ``external:NAME[...]=CMD`` as written (not checked: :func:`parse_spec` did that)."""
    return _split(text)[2]


def command_argv(cmd: str) -> list[str]:
    """CMD split like a shell command line (no shell), every word in braces one of
    :data:`PLACEHOLDERS`; ValueError naming an unbalanced quote or an unknown
    placeholder (with its closest known one) otherwise."""
    try:
        argv = shlex.split(cmd)
    except ValueError as err:  # shlex: "No closing quotation", "No escaped character"
        raise ValueError(f"CMD {_clip(cmd)!r} cannot be split like a shell command line ({err}): "
                         f"expected its quotes closed") from None
    if not argv:
        raise ValueError("CMD is empty after splitting: expected a program and its arguments")
    for m in _PLACEHOLDER.finditer(cmd):
        if m.group(0) not in PLACEHOLDERS:
            close = difflib.get_close_matches(m.group(0), PLACEHOLDERS, n=1)
            hint = f" (did you mean {close[0]}?)" if close else ""
            raise ValueError(f"unknown placeholder {m.group(0)}{hint} in CMD: expected "
                             f"{', '.join(PLACEHOLDERS)}")
    return argv


def _check_program(argv: list[str]) -> None:
    """ValueError when CMD's program (``argv[0]``, a path or a name looked up on PATH)
    cannot be run: checked once, before the first job, not once per row."""
    program = argv[0]
    if any(ph in program for ph in PLACEHOLDERS):
        return  # (the program is one of the problem's files: nothing to check yet)
    if shutil.which(program) is not None:
        return
    if os.sep in program or (os.altsep and os.altsep in program):
        why = ("is a directory" if os.path.isdir(program) else
               "is not executable (chmod +x, or name its interpreter first)" if os.path.exists(program) else
               "does not exist")
        raise ValueError(f"program {program!r} {why} (relative to {os.getcwd()})")
    raise ValueError(f"program {program!r} is not found on PATH: expected a program's name on PATH or its path")


def _clip(text: str, keep: int = 120) -> str:
    return text if len(text) <= keep else text[:keep] + "..."


def _split(text: str) -> tuple[str, str, str]:
    """(NAME, the declaration in brackets, CMD) of ``external:NAME[...]=CMD``
    (CMD empty when there is no '='); ValueError for brackets not closed by ']='."""
    body = text[len(_EXTERNAL):] if text.startswith(_EXTERNAL) else text
    head, _, cmd = body.partition("=")
    if "[" not in head:
        return head, "", cmd
    name, _, rest = body.partition("[")  # (the brackets hold '=': the command starts after the matching ']=')
    decl, close, after = rest.partition("]")
    if not close or not after.startswith("="):
        raise ValueError("expected external:NAME[strict=true|false]=CMD: no ']=' after the declaration")
    return name, decl, after[1:]


def _declarations(decl: str) -> bool:
    """The ``strict`` of the declaration ``strict=false`` (empty: True)."""
    strict = True
    for item in filter(None, (d.strip() for d in decl.split(","))):
        key, eq, value = (p.strip() for p in item.partition("="))
        if key not in SPEC_KEYS:
            close = difflib.get_close_matches(key, SPEC_KEYS, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise ValueError(f"unknown declaration {key!r}{hint} in [...]: expected strict=true or strict=false")
        if not eq or value not in _BOOLS:
            raise ValueError(f"strict={value}: expected strict=true (the program returns the lexicographic "
                             f"optimum) or strict=false (it does not: weighted, damped)")
        strict = _BOOLS[value]
    return strict
