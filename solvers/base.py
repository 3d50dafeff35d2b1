"""The one solver interface and the one result type.

A solver is an object built with its options and called on a
:class:`~hikbench.problems.hierarchy.Hierarchy`; it may keep warm-start state between
calls (the benchmark's ``warm`` mode re-solves on the same object). It never
sees a robot, never raises for a valid problem (one too large for the
machine's memory excepted, :meth:`Solver.check_hierarchy`), never returns NaN
silently: failures come back as a status with a reason.
"""

from __future__ import annotations

import abc
import inspect
from dataclasses import InitVar, dataclass, field
from typing import Any, ClassVar

import numpy as np

from hikbench.problems.hierarchy import Hierarchy, check_fits_in_memory

__all__ = ["ERROR", "INFEASIBLE_LEVEL", "JUDGED_ON", "MAX_ITERATIONS", "NUMERICAL_FAILURE", "OPTIMAL",
           "ROWS", "ROW_NORMALISED", "STATUSES", "UNSUPPORTED", "SolveResult", "Solver", "checked_result"]

OPTIMAL = "optimal"                      #: every level solved to the solver's accuracy
MAX_ITERATIONS = "max_iterations"        #: an iteration cap was hit; x is the last iterate
INFEASIBLE_LEVEL = "infeasible_level"    #: a level could not be solved after freezing the ones above
NUMERICAL_FAILURE = "numerical_failure"  #: NaN / breakdown inside the solver
UNSUPPORTED = "unsupported"              #: the solver cannot handle this problem (e.g. inequalities)
ERROR = "error"                          #: an exception escaped from a backend

ROWS = "rows"                      #: a strict solver's levels are the rows as given
ROW_NORMALISED = "row-normalised"  #: ... the rows divided by their norms (problems.hierarchy.row_normalised)
JUDGED_ON = (ROWS, ROW_NORMALISED)

STATUSES = (OPTIMAL, MAX_ITERATIONS, INFEASIBLE_LEVEL, NUMERICAL_FAILURE, UNSUPPORTED, ERROR)


@dataclass
class SolveResult:
    """What one solve returns.

    Attributes
    ----------
    x : ndarray, shape (n,), or None
        The solution (None when the solver produced none; a result built with
        status ``optimal`` and x None becomes status ``error`` with a reason).
    status : str
        One of :data:`STATUSES`.
    reason : str
        Human-readable detail for any status other than ``optimal``
        (which level failed and why).
    iterations : int
        Total iterations (active-set iterations for HCOD, QP iterations summed
        over levels for cascades; 0 when not applicable).
    iterations_per_level : tuple of int
        Iterations of each level, shape (depth,), or () when not reported.
    activations, deactivations : int
        Active-set changes (active-set solvers only).
    flops : int or None
        Multiply-adds counted in the decomposition kernels, if the solver counts.
    build_time_s : float
        Time spent assembling matrices (cascades), NaN when not separated.
    solve_time_s : float
        Time measured by the solver itself, NaN when not measured.
    info : dict
        Solver-specific extras (kept out of the CSV unless the harness knows them).
    x_finite : bool, init only
        True when the solver's compiled code has already tested every entry of
        ``x`` with ``isfinite`` (and reported a failure status otherwise): the
        repeat of that test here is skipped (~0.5 us per solve). Default False:
        the test runs.
    """

    x: np.ndarray | None
    status: str
    reason: str = ""
    iterations: int = 0
    iterations_per_level: tuple[int, ...] = ()
    activations: int = 0
    deactivations: int = 0
    flops: int | None = None
    build_time_s: float = float("nan")
    solve_time_s: float = float("nan")
    info: dict[str, Any] = field(default_factory=dict)
    x_finite: InitVar[bool] = False

    def __post_init__(self, x_finite: bool) -> None:
        if self.status not in STATUSES:
            raise ValueError(f"status {self.status!r} is not one of {STATUSES}")
        if self.x is None and self.status == OPTIMAL:
            # an optimal status is a claim about x: without x it is a solver error (its row is not
            # recorded as optimal), as an external program's `"x": null` with status optimal is
            self.status = ERROR
            self.reason = (self.reason + "; " if self.reason else "") + ("status optimal with x None: expected x, "
                                                                          "shape (n,)")
        if self.x is not None and self.status == OPTIMAL and not x_finite and not np.isfinite(self.x).all():
            # never NaN silently: a non-finite x cannot be called optimal (np.isfinite, not a
            # faster x @ x, which overflows for a finite x with entries above 1e154; the solvers
            # whose solve costs a few microseconds test x in compiled code and pass x_finite)
            self.status = NUMERICAL_FAILURE
            self.reason = (self.reason + "; " if self.reason else "") + "x holds NaN or inf"

    @property
    def ok(self) -> bool:
        return self.status == OPTIMAL


class Solver(abc.ABC):
    """Base of every solver.

    Subclasses set the class attributes and implement :meth:`solve`, which
    starts with ``self.check_hierarchy(hierarchy)`` (a TypeError for anything
    but a Hierarchy passed from Python). Options are
    keyword arguments of ``__init__``; a wrong option raises
    :class:`~hikbench.solvers.errors.SolverOptionError` at construction.

    ``strict`` is the solver's claim: True, it returns the lexicographic
    optimum (the strict hierarchy: judged against the yardstick); False, it
    solves another problem (weighted, damped, stacked least squares) and is
    reported by its real times and its per-level gap to the yardstick.

    ``judged_on`` says which hierarchy a strict solver's levels are:
    ``"rows"`` (the rows as given) or ``"row-normalised"`` (each row and its
    bounds divided by the row's norm, the same minimisers wherever no level
    conflicts; DAQP's hierarchical QP): its x is judged against the
    yardstick of that hierarchy.
    """

    name: ClassVar[str] = ""
    description: ClassVar[str] = ""
    supports_inequalities: ClassVar[bool] = False
    supports_warm_start: ClassVar[bool] = False
    strict: ClassVar[bool] = True
    judged_on: str = ROWS

    @classmethod
    def default_options(cls) -> dict:
        """The options a solver built without any takes: the defaults of ``__init__``'s
        keyword parameters, e.g. ``{"warm_start": "time", "rank_rtol": 1e-10}``
        (``hikbench list solvers``, :meth:`hikbench.solvers.info.SolverInfo.of`)."""
        params = inspect.signature(cls).parameters.values()
        return {p.name: p.default for p in params
                if p.default is not p.empty and p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)}

    @abc.abstractmethod
    def solve(self, hierarchy: Hierarchy) -> SolveResult:
        """Solve the hierarchy; never raises for a valid problem."""

    def reset(self) -> None:
        """Forget warm-start state (the next solve is cold)."""

    def settings(self) -> dict:
        """The settings the solver runs with, its defaults resolved, as JSON-able values
        (results.csv column ``solver_settings``). Default: none reported ({})."""
        return {}

    def warmup(self) -> None:
        """Compile or load everything any later solve of this process may need
        (JIT kernels, caches); cheap once done. The benchmark's worker calls it
        before each job's untimed first solve, within the first-solve
        allowance: a solver whose kernels depend on the problem (hcod:
        equality-only or with inequalities) would otherwise compile inside a
        later job's timeout. Default: nothing."""

    def check_hierarchy(self, hierarchy: object) -> None:
        """The type check at the start of :meth:`solve`: ``hierarchy`` must be a
        :class:`~hikbench.problems.hierarchy.Hierarchy` (every CLI path builds one; a
        call from Python may pass anything). Raises TypeError naming the
        solver, the expected type and the type it got.

        Also refuses, with :class:`~hikbench.problems.errors.ProblemTooLargeError`, a
        hierarchy whose ``n`` makes one ``n x n`` matrix of doubles larger
        than this machine's memory
        (:func:`~hikbench.problems.hierarchy.check_fits_in_memory`)."""
        who = self.name or type(self).__name__
        if not isinstance(hierarchy, Hierarchy):
            t = type(hierarchy)
            got = t.__qualname__ if t.__module__ == "builtins" else f"{t.__module__}.{t.__qualname__}"
            raise TypeError(f"{who}.solve expects a hikbench.problems.hierarchy.Hierarchy "
                            f"(e.g. Hierarchy.from_levels), got {got}")
        check_fits_in_memory(hierarchy.n, who)

    def unsupported(self, hierarchy: Hierarchy, why: str) -> SolveResult:
        return SolveResult(x=None, status=UNSUPPORTED, reason=f"{self.name}: {why}",
                           iterations_per_level=(0,) * hierarchy.depth)


def checked_result(res, h: Hierarchy, solver) -> SolveResult:
    """``res``, what ``solver.solve(h)`` returned, when it keeps the solve
    contract (a SolveResult whose x is None or real numbers of shape (n,)); otherwise a
    SolveResult with status ``error`` whose reason names the solver (its
    ``name``, or its class), what came back and what was expected. The harness applies it
    to every solver's answer: a user's ``file.py:Class`` returning an ndarray,
    or x of the wrong length, costs its row (or scenario run), not the run."""
    who = getattr(solver, "name", type(solver).__name__)
    if not isinstance(res, SolveResult):
        return SolveResult(None, ERROR, reason=f"{who}: solve() returned {type(res).__name__}: expected a "
                                                f"hikbench.solvers.base.SolveResult")
    if res.x is not None and np.shape(res.x) != (h.n,):
        return SolveResult(None, ERROR, reason=f"{who}: solve() returned x of shape {np.shape(res.x)}: expected "
                                                f"({h.n},), one value per variable")
    if res.x is not None and np.asarray(res.x).dtype.kind not in "biuf":
        dtype = np.asarray(res.x).dtype
        what = "complex numbers" if dtype.kind == "c" else f"dtype {dtype}"
        return SolveResult(None, ERROR, reason=f"{who}: solve() returned x of {what} ({dtype}): expected real "
                                                f"numbers (float64); x is not cast")
    return res
