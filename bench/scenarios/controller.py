"""The base of scenario controllers (:mod:`hikbench.bench.scenarios.controllers` names them
and builds them): its own module, so that a controller's module imports it without
importing the table that loads that module."""

from __future__ import annotations

import abc
from typing import ClassVar

import numpy as np

from hikbench.problems.errors import HikbenchError
from hikbench.problems.hierarchy import Hierarchy
from hikbench.problems.robots.stacks import Stack
from hikbench.solvers.base import SolveResult

__all__ = ["Controller", "ControllerError"]


class ControllerError(HikbenchError, ValueError):
    """A stack a controller cannot take (a task type it has no counterpart for) or a bad option."""


class Controller(abc.ABC):
    """Closed-loop IK on a stack's tasks.

    ``strict`` is False for a controller that weights the levels instead of
    prioritising them (its checks may fail where the priorities matter).
    Options are keyword arguments of ``__init__``; a wrong one raises
    :class:`ControllerError` at construction, as does a task it cannot take.
    """

    name: ClassVar[str] = ""
    description: ClassVar[str] = ""
    strict: ClassVar[bool] = False

    def __init__(self, stack: Stack):
        self.stack = stack

    @abc.abstractmethod
    def prepare(self, q: np.ndarray) -> None:
        """Take configuration q (shape (nq,)) and the stack's current task targets (untimed)."""

    @abc.abstractmethod
    def solve(self, hierarchy: Hierarchy) -> SolveResult:
        """u (shape (nv,)) at the prepared q; ``hierarchy`` is the stack's at q (for its size)."""
