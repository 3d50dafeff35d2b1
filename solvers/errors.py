"""Errors of the solver registry and of solver options."""

from hikbench.problems.errors import HikbenchError

__all__ = ["SolverNotFoundError", "SolverOptionError"]


class SolverNotFoundError(HikbenchError, KeyError):
    """A solver that is not registered or whose backend is not installed."""

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""


class SolverOptionError(HikbenchError, ValueError):
    """A solver option with a wrong name or value."""
