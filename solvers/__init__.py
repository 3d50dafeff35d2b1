"""How it is solved: one module per solver family, one interface
(:class:`hikbench.solvers.base.Solver`), one result type (:class:`hikbench.solvers.base.SolveResult`)
and a registry (:mod:`hikbench.solvers.registry`). Imports ``problems``, never ``bench``."""

from hikbench.solvers.base import STATUSES, Solver, SolveResult
from hikbench.solvers.registry import SolverInfo, available, create, get

__all__ = ["STATUSES", "SolveResult", "Solver", "SolverInfo", "available", "create", "get"]
