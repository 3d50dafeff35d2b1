"""The solver registry: names -> factories, filled from what imports cleanly.

Built-in solver modules are listed in ``_BUILTIN_MODULES``; each defines
``SOLVERS``, a list of :class:`~hikbench.solvers.info.SolverInfo` (``SolverInfo.of(TheClass)``).
Third-party packages add solvers through the entry-point group ``hikbench.solvers``
(an entry point resolving to such a list, or to a function returning one). A module whose optional backend
is missing (``ModuleNotFoundError`` for a package outside hikbench) is simply
not listed; asking for one of its solvers says how to install it. Any other
import error is a bug and propagates.

Importing this module imports no solver (nothing compiles at import time).
``SolverInfo`` and the option checks (``check_number``...: :mod:`hikbench.solvers.options`)
are importable from here too, as a solver's module outside hikbench does.
"""

from __future__ import annotations

import difflib
import importlib
import inspect
from importlib import metadata

from hikbench.extras import install_hint
from hikbench.solvers.base import Solver
from hikbench.solvers.errors import SolverNotFoundError, SolverOptionError
from hikbench.solvers.info import SolverInfo
from hikbench.solvers.options import check_bool, check_choice, check_int, check_number, check_numbers

__all__ = ["SolverInfo", "available", "build", "check_bool", "check_buildable", "check_choice", "check_int",
           "check_number", "check_numbers", "close_match", "create", "get", "missing", "option_names"]

_BUILTIN_MODULES: tuple[str, ...] = (
    "hikbench.solvers.yardstick",
    "hikbench.solvers.hcod",
    "hikbench.solvers.cascade",
    "hikbench.solvers.cascade_cvxpy",
    "hikbench.solvers.nullspace",
    "hikbench.solvers.damped",
    "hikbench.solvers.peers",
    "hikbench.solvers.daqp_hqp",
)
_OWN_PACKAGES = ("hikbench",)
#: other names of registered solvers: ``reference`` is the yardstick's earlier name
ALIASES = {"reference": "yardstick"}


_registry: dict[str, SolverInfo] | None = None
_missing: dict[str, str] = {}  # module or backend -> install hint


def _is_missing_dependency(err: ModuleNotFoundError) -> bool:
    root = (err.name or "").split(".")[0]
    return bool(root) and root not in _OWN_PACKAGES


def _load() -> dict[str, SolverInfo]:
    global _registry
    if _registry is not None:
        return _registry
    reg: dict[str, SolverInfo] = {}
    for modname in _BUILTIN_MODULES:
        try:
            mod = importlib.import_module(modname)
        except ModuleNotFoundError as err:
            if not _is_missing_dependency(err):
                raise
            _missing[modname] = f"{modname} needs {install_hint(err.name)}"
            continue
        for info in getattr(mod, "SOLVERS", ()):
            _add(reg, info)
        _missing.update(getattr(mod, "MISSING", {}))
    for ep in metadata.entry_points(group="hikbench.solvers"):
        obj = ep.load()
        infos = obj() if callable(obj) and not isinstance(obj, SolverInfo) else obj
        for info in ([infos] if isinstance(infos, SolverInfo) else infos):
            _add(reg, info)
    _registry = reg
    return reg


def _add(reg: dict[str, SolverInfo], info: SolverInfo) -> None:
    if info.name in reg:
        raise SolverOptionError(f"solver name {info.name!r} is registered twice")
    reg[info.name] = info


def available() -> dict[str, SolverInfo]:
    """Every solver that can run here, by name (sorted)."""
    return dict(sorted(_load().items()))


def missing() -> dict[str, str]:
    """Solvers or backends that are known but not installed -> install hint."""
    _load()
    return dict(_missing)


def get(name: str) -> SolverInfo:
    """The :class:`SolverInfo` of ``name``; raises SolverNotFoundError with the
    list of available solvers and, for a known backend, how to install it."""
    reg = _load()
    name = ALIASES.get(name, name)
    if name in reg:
        return reg[name]
    hint = _missing.get(name)
    found = ", ".join(reg)
    if hint:
        raise SolverNotFoundError(f"solver {name!r} is not available: {hint} (found solvers: {found})")
    near = close_match(name, [*reg, *(m for m in _missing if "." not in m)])  # (not backend modules)
    raise SolverNotFoundError(f"unknown solver {name!r}{near} (found solvers: {found})")


def close_match(name: str, known) -> str:
    """``"; did you mean 'hcod'?"`` for a misspelt solver name ``name`` (the closest of
    ``known`` by :func:`difflib.get_close_matches`, ratio >= 0.6), ``""`` when none is close."""
    best = difflib.get_close_matches(name, list(dict.fromkeys(known)), n=1)
    return f"; did you mean {best[0]!r}?" if best else ""


def option_names(info: SolverInfo) -> tuple[str, ...] | None:
    """Keyword options accepted by ``info.factory`` (from its signature), or
    None when it takes ``**kwargs`` (then the factory validates them itself)."""
    return _names(_signature(info))


def _signature(info: SolverInfo) -> inspect.Signature | None:
    """The factory's signature; None for a builtin without one (cannot tell)."""
    try:
        return inspect.signature(info.factory)
    except (TypeError, ValueError):
        return None


def _names(sig: inspect.Signature | None) -> tuple[str, ...] | None:
    params = () if sig is None else sig.parameters.values()
    if sig is None or any(p.kind is p.VAR_KEYWORD for p in params):
        return None
    return tuple(p.name for p in params if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY))


def create(name: str, **options) -> Solver:
    """Build a fresh solver object of the registered solver ``name`` (:func:`build`)."""
    return build(get(name), **options)


def build(info: SolverInfo, **options) -> Solver:
    """Build a fresh solver object from ``info`` (registered, or made for a
    ``module:Class`` spec), its default options overridden by ``options``.

    Option names are checked against the factory's signature (unless it takes
    ``**kwargs``): an unknown one raises SolverOptionError naming it and the
    allowed ones; options that leave a required argument of the factory
    unbound, or a factory returning no solver, raise SolverOptionError too.
    Errors raised by the factory itself propagate unchanged (a wrong option
    *value* should raise SolverOptionError there)."""
    name = info.name
    opts = check_buildable(info, **options)
    solver = info.factory(**opts)
    if not callable(getattr(solver, "solve", None)):
        raise SolverOptionError(f"solver {name!r}: its factory returned {type(solver).__name__}: expected a "
                                f"solver, an object with a solve(hierarchy) method (a hikbench.solvers.base.Solver)")
    return solver


def check_buildable(info: SolverInfo, **options) -> dict:
    """The options :func:`build` would call ``info.factory`` with (its defaults
    overridden by ``options``), after checking them against the factory's
    signature without calling it: SolverOptionError for an unknown option or a
    required argument left unbound (e.g. a ``module:Class`` whose constructor
    needs an argument no option gives)."""
    opts = {**info.options, **options}
    sig = _signature(info)
    allowed = _names(sig)
    if allowed is not None:
        unknown = [k for k in opts if k not in allowed]
        if unknown:
            listed = ", ".join(allowed) if allowed else "none"
            raise SolverOptionError(
                f"solver {info.name!r}: unknown option(s) {', '.join(map(repr, unknown))}; "
                f"allowed options: {listed}")
    _check_binds(info, sig, opts)
    return opts


def _check_binds(info: SolverInfo, sig: inspect.Signature | None, opts: dict) -> None:
    """SolverOptionError when the factory cannot be called with ``opts`` alone
    (a required argument missing: a solver's factory takes keyword options only);
    without a signature (``sig`` None) the call itself decides."""
    if sig is None:
        return
    try:
        sig.bind(**opts)
    except TypeError as err:
        given = ", ".join(map(repr, opts)) or "none"
        raise SolverOptionError(f"solver {info.name!r}: cannot be built with the options given ({given}): "
                                f"{err}; a solver's factory is called with keyword options only") from err
