"""What is solved: the hierarchy model, problem files, generators, robot task
stacks and closed-loop scenarios. Imports neither ``solvers`` nor ``bench``."""

from problems.errors import (
    HikbenchError,
    InvalidHierarchyError,
    ProblemFileError,
    ProblemTooLargeError,
    SolverNotFoundError,
    SolverOptionError,
    UnknownFamilyError,
)
from problems.hierarchy import Hierarchy, Level
from problems.verify import Verdict, compare_lexicographic, level_norms, level_scales, verify, violation

__all__ = [
    "Hierarchy", "HikbenchError", "InvalidHierarchyError", "Level", "ProblemFileError", "ProblemTooLargeError",
    "SolverNotFoundError", "SolverOptionError", "UnknownFamilyError", "Verdict", "compare_lexicographic", "level_norms",
    "level_scales", "verify", "violation",
]
