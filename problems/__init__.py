"""What is solved: the hierarchy model, problem files, generators, robot task
stacks and closed-loop scenarios. Imports neither ``solvers`` nor ``bench``."""

from hikbench.problems.errors import (
    HikbenchError,
    InvalidHierarchyError,
    ProblemFileError,
    ProblemTooLargeError,
    UnknownFamilyError,
)
from hikbench.problems.hierarchy import Hierarchy, Level
from hikbench.problems.verify import (
    PROFILES,
    Verdict,
    compare_lexicographic,
    judge,
    level_gaps,
    level_norms,
    level_scales,
    verify,
    violation,
)

__all__ = [
    "Hierarchy", "HikbenchError", "InvalidHierarchyError", "Level", "ProblemFileError", "ProblemTooLargeError",
    "PROFILES", "UnknownFamilyError", "Verdict", "compare_lexicographic", "judge", "level_gaps", "level_norms",
    "level_scales", "verify", "violation",
]
