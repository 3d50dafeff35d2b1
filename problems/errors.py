"""The exception family of hikbench.

Every error a user can cause derives from :class:`HikbenchError`, so a caller
(the CLI, the runner) can tell a user mistake from a bug with one ``except``.
"""

from __future__ import annotations


class HikbenchError(Exception):
    """Base of every error hikbench raises on purpose."""


class InvalidHierarchyError(HikbenchError, ValueError):
    """A hierarchy (or its file) is malformed.

    Attributes
    ----------
    level, row:
        The level and the row inside that level where the problem was found,
        or ``None`` when the error is not about one row (a shape, say).
    """

    def __init__(self, message: str, level: int | None = None, row: int | None = None):
        super().__init__(message)
        self.level = level
        self.row = row


class ProblemTooLargeError(HikbenchError, MemoryError):
    """A valid hierarchy that this machine cannot hold: its n x n matrices
    would not fit in memory (raised before anything is allocated)."""


class ProblemFileError(HikbenchError):
    """A problem file cannot be read or written (missing key, bad syntax)."""


class UnknownFamilyError(HikbenchError, KeyError):
    """A problem family name that the generators do not know."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0]) if self.args else ""
