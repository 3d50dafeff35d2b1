"""What the registry knows of a solver: :class:`SolverInfo`, derived from the
solver's class (:meth:`SolverInfo.of`) so that its name, flags and option
defaults are declared once, on the class and in its ``__init__`` signature."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from hikbench.solvers.base import Solver

__all__ = ["SolverInfo"]


@dataclass(frozen=True)
class SolverInfo:
    """A registered solver.

    Attributes
    ----------
    name : str
        Registry name, e.g. ``"hcod"`` or ``"cascade-osqp"``.
    description : str
        One line.
    factory : callable
        ``factory(**options) -> Solver``.
    supports_inequalities, supports_warm_start : bool
    strict : bool
        True for solvers of the strict hierarchy (judged against the
        lexicographic optimum); False for weighted / damped IK.
    options : dict
        Default options, shown by ``hikbench list solvers``.
    judged_on : callable or None
        ``judged_on(options) -> "rows" | "row-normalised"``: the hierarchy a
        solver built with ``options`` (defaults included) claims to solve
        (:attr:`hikbench.solvers.base.Solver.judged_on`); None: ``"rows"``.
    """

    name: str
    description: str
    factory: Callable[..., Solver]
    supports_inequalities: bool = False
    supports_warm_start: bool = False
    strict: bool = True
    options: dict = field(default_factory=dict)
    judged_on: Callable[[dict], str] | None = None

    @classmethod
    def of(cls, solver: type[Solver], *, judged_on: Callable[[dict], str] | None = None) -> SolverInfo:
        """The info of the Solver subclass ``solver``, read from it: ``name``,
        ``description``, ``supports_inequalities``, ``supports_warm_start``, ``strict``
        (class attributes) and ``options`` (:meth:`Solver.default_options`, the
        defaults of its ``__init__``); the class itself is the factory. ``judged_on``:
        for a solver whose claim depends on its options (daqp-hqp's ``normalised``)."""
        if not (isinstance(solver, type) and issubclass(solver, Solver)):
            raise TypeError(f"SolverInfo.of expects a hikbench.solvers.base.Solver subclass, got {solver!r}")
        if not solver.name:
            raise TypeError(f"{solver.__qualname__}: a registered solver needs a class attribute `name`")
        return cls(solver.name, solver.description, solver,
                   supports_inequalities=solver.supports_inequalities,
                   supports_warm_start=solver.supports_warm_start, strict=solver.strict,
                   options=solver.default_options(), judged_on=judged_on)
