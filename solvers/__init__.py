"""How it is solved: one module per solver family, one interface
(:class:`solvers.base.Solver`), one result type (:class:`solvers.base.SolveResult`)
and a registry (:mod:`solvers.registry`). Imports ``problems``, never ``bench``."""

from solvers.base import STATUSES, Solver, SolveResult
from solvers.registry import SolverInfo, available, create, get

__all__ = ["STATUSES", "SolveResult", "Solver", "SolverInfo", "available", "create", "get"]
