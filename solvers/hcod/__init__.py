"""The HCOD solver (Escande, Mansard, Wieber, ICRA 2010), registered as ``hcod``.

A hierarchy of levels ``lower_k <= A_k x <= upper_k`` is solved as the
sequence of LSIs (eqs. 33-36): equality-only hierarchies by the hierarchical
COD recursion (sec. V-VI, eqs. 16-31, :mod:`._equality`), any other by a primal
active set on the decomposition (sec. VII-X, eqs. 37-39, 43-45, :mod:`._kernel`),
then the minimum-norm level ``x = 0`` (option ``min_norm``). Options:
``warm_start`` (``none`` | ``stage`` | ``time``, sec. XI, eq. 46; default
``time``: each call re-applies the last call's working sets while the
problem keeps its shape), ``max_iterations``, ``rank_rtol`` (default 1e-10,
relative to each level's norm). Statuses: ``optimal``, ``max_iterations``,
``numerical_failure``; no exception escapes for a valid problem.

The method, the rank rules, the tolerances, the warm start's behaviour and
the design of the kernels are documented in ``docs/hcod.md``. The kernels are
numba functions loaded from numba's cache (:func:`warmup`; :mod:`._cache`
keeps it valid for every file of this folder but this one).
"""

from __future__ import annotations

from itertools import pairwise

import numpy as np
from hikbench.problems.hierarchy import Hierarchy
from hikbench.solvers.base import MAX_ITERATIONS, NUMERICAL_FAILURE, OPTIMAL, Solver, SolveResult
from hikbench.solvers.info import SolverInfo
from hikbench.solvers.options import check_bool, check_choice, check_int, check_number

from ._layout import (
    N_OUT,
    N_PRM,
    O_ACT,
    O_CAPPED,
    O_COLD,
    O_DEACT,
    O_FLOPS,
    O_ITERS,
    O_LEVEL,
    O_NEARCUT,
    O_STATUS,
    O_WARMFAIL,
    PRM_DUAL_RTOL,
    PRM_FEAS_RTOL,
    PRM_FREEZE_RTOL,
    PRM_RANK_RTOL,
    WARM_MODES,
)

__all__ = ["SOLVERS", "WARM_STARTS", "HcodSolver", "warmup"]

WARM_STARTS = WARM_MODES  #: the option warm_start's values, in the order of ._layout's WARM_*
_NAN = float("nan")  # (build_time_s, solve_time_s: not separated)
_NONE = object()  # (matches no solve() argument, unlike None)
_STATUS = {0: OPTIMAL, 1: MAX_ITERATIONS, 2: NUMERICAL_FAILURE}
_eq_run = None  # hikbench.solvers.hcod._equality.eq_run, set by warmup() (the first solve calls it)
_ineq = None  # (._kernel.hcod_solve, ._setup), set with it
_entry = None  # hcod_solve's compiled entry point for the workspaces' types, found by the first _shape


class HcodSolver(Solver):
    """HCOD hierarchical active-set solver.

    Parameters
    ----------
    warm_start : {"none", "stage", "time"}
        See the module docstring; default "time".
    max_iterations : int or None
        Cap on the total active-set iterations (LSE solves) of one call;
        None -> ``100 + 10 * (rows + n)``. Hitting it returns status
        ``max_iterations`` with the last iterate.
    rank_rtol : float
        Relative rank threshold (see the module docstring), default 1e-10.
    min_norm : bool
        Append the implicit level ``x = 0`` when the problem has inequalities.
    """

    name = "hcod"
    description = "HCOD hierarchical active set (Escande-Mansard-Wieber 2010), numba"
    supports_inequalities = True
    supports_warm_start = True

    def __init__(self, warm_start: str = "time", max_iterations: int | None = None,
                 rank_rtol: float = 1e-10, min_norm: bool = True):
        self.warm_start = check_choice("hcod", "warm_start", warm_start, WARM_STARTS)
        self.max_iterations = check_int("hcod", "max_iterations", max_iterations, none_ok=True)
        self.rank_rtol = check_number("hcod", "rank_rtol", rank_rtol, low=0, high=1, low_open=True,
                                      high_open=True)
        self.min_norm = check_bool("hcod", "min_norm", min_norm)
        # the kernel's "prm" block: rank, feasibility (warm start), multiplier noise floor, zero slack
        # at the freeze
        self._prm = prm = np.empty(N_PRM)
        prm[PRM_RANK_RTOL] = self.rank_rtol
        prm[PRM_FEAS_RTOL] = 1e-9
        prm[PRM_DUAL_RTOL] = 1e-13
        prm[PRM_FREEZE_RTOL] = 1e-11
        # the hierarchy bound to the workspaces (see _bind) and the last equality-only one (skips
        # the checks on a re-solve); _NONE until then, so that solve(None) meets the type check
        self._h = _NONE
        self._n = self._st = None  # its shape: the warm-start record is kept while it stays the same
        self._ws = None  # (fw, iw): the kernel's workspaces for that shape (see _shape)
        self._eq_h = _NONE
        self._run = None  # closure solving the hierarchy loaded into the workspaces (see _shape)

    def reset(self) -> None:
        """Forget the warm-start record (the next solve is cold)."""
        if self._ws is not None:
            from hikbench.solvers.hcod._setup import iblock

            iblock(self._ws[1], "hist_valid")[:] = 0

    # -- equality-only hierarchies: the implicit-basis recursion (_equality.py) -------------------
    def _solve_equality(self, h: Hierarchy) -> SolveResult:
        """One compiled call (workspaces allocated inside it)."""
        try:
            x, itl, fl, cuts = _eq_run(h.A, h.lower, h.starts, self.rank_rtol)
        except (ZeroDivisionError, FloatingPointError, ValueError, IndexError) as err:  # breakdown
            return SolveResult(x=None, status=NUMERICAL_FAILURE, reason=f"hcod: {type(err).__name__}: {err}",
                               iterations_per_level=(0,) * h.depth)
        it = itl.tolist()
        if fl < 0:
            return SolveResult(x=None, status=NUMERICAL_FAILURE, reason="hcod: x is not finite",
                               iterations=sum(it), iterations_per_level=tuple(it))
        # (x_finite: eq_solve tested every entry of x with isfinite, fl = -1 otherwise)
        return SolveResult(x=x, status=OPTIMAL, iterations=sum(it), iterations_per_level=tuple(it), flops=fl,
                           info={"near_rank_steps_cut": cuts} if cuts else {}, x_finite=True)

    # -- hierarchies with inequalities: the active set (_kernel.py) -------------------------------
    def _bind(self, h: Hierarchy):
        """h written into the workspaces scaled (:func:`._setup.load`); the
        workspaces and the closure running one solve on them are made anew
        only when the shape (n, level sizes) changes: the warm-start record
        survives, and a new problem of the same shape (a control loop) costs
        the load alone."""
        n = h.n
        st = h.starts.tolist()
        fresh = n != self._n or st != self._st  # (None before the first bind)
        if fresh:
            self._shape(n, st)
        fw, iw = self._ws
        f = _ineq[1].load(fw, iw, h.A, h.lower, h.upper, h.starts, self.min_norm, fresh)
        fbox = self._fbox
        if f != fbox[0]:
            # the kernel solves for u = f x (._setup.load); the record's steps Delta u (eq. 46)
            # follow the new factor (powers of 2: exact)
            _ineq[1].fblock(fw, iw, "hist_du")[:] *= f / fbox[0]
            fbox[0] = f
        self._h = h
        return self._run

    def _shape(self, n: int, st: list[int]) -> None:
        """Workspaces for a problem of n variables and levels ``starts = st``
        (:func:`._setup.workspaces`), and the closure ``self._run`` solving
        the problem loaded into them."""
        if _ineq is None:
            warmup()
        hcod_solve, setup = _ineq
        mn = self.min_norm  # (n > 0 here)
        depth = len(st) - 1
        D = depth + mn
        mt = st[-1] + n * mn
        mmax = max(max(b - a for a, b in pairwise(st)), n * mn)
        cap = self.max_iterations if self.max_iterations is not None else 100 + 10 * (mt + n)
        ip = setup.int_params(n, mt, D, mmax, cap, WARM_MODES.index(self.warm_start), True)
        fw, iw, xv, outv = setup.workspaces(ip, self._prm)
        self._ws = (fw, iw)
        # the compiled kernel for these two arrays' types (1-d contiguous float64 and int64, always:
        # ._setup.workspaces): a call to it skips the dispatcher's typing of the arguments (~0.1-0.2
        # us a solve). Looked up once per process: Dispatcher.compile takes ~50 us even when the
        # kernel is loaded, which a cold solve of 20 us on a fresh solver must not pay
        global _entry
        if _entry is None:
            from numba import typeof

            _entry = hcod_solve.compile((typeof(fw), typeof(iw)))
        kernel = _entry
        # the factor of the bounds in the workspaces (._setup.load: u = f x), in a list that run
        # shares: run must not hold self (a cycle keeps a dropped solver and its workspaces alive
        # until the collector runs; the benchmark times with it off: cold IK-like n=80 went from
        # 187 to 411 us, every solve's workspaces fresh pages)
        fbox = self._fbox = [1.0]
        self._n, self._st = n, st
        extra = D > depth
        it0, it1 = N_OUT, N_OUT + depth

        def run() -> SolveResult:
            try:
                kernel(fw, iw)
            except (ZeroDivisionError, FloatingPointError, ValueError, IndexError) as err:  # breakdown
                return SolveResult(x=None, status=NUMERICAL_FAILURE, reason=f"hcod: {type(err).__name__}: {err}",
                                   iterations_per_level=(0,) * depth)
            o = outv.tolist()  # the counters (slots ._layout.O_*), then the iterations per level
            info = {"min_norm_iterations": o[it1]} if extra else {}
            if o[O_WARMFAIL]:
                info["warm_fallback_levels"] = o[O_WARMFAIL]
            if o[O_COLD]:
                info["cold_after_warm"] = True
            if o[O_CAPPED]:
                info["steps_capped"] = True
            if o[O_NEARCUT]:
                info["near_rank_steps_cut"] = o[O_NEARCUT]
            x = xv.copy()
            f = fbox[0]
            if f != 1.0:
                x /= f  # (a power of 2: exact)
                info["bounds_scaled_by"] = f
            status = _STATUS[o[O_STATUS]]
            reason = ""
            if status == MAX_ITERATIONS:
                where = "the min-norm stage" if o[O_LEVEL] >= depth else f"level {o[O_LEVEL]}"
                reason = f"hcod: iteration cap {cap} reached at {where}"
            elif status == NUMERICAL_FAILURE:
                reason = "hcod: numerical breakdown (x not finite)"
                x = None
            # (x_finite: the kernel tested every entry of u with isfinite, status 2 otherwise).
            # Positional, in the order of SolveResult's fields: eleven keywords cost ~0.35 us
            # more per call, 3% of a warm re-solve at n = 20 (test_solve_result_fields_in_order)
            return SolveResult(x, status, reason, o[O_ITERS], tuple(o[it0:it1]), o[O_ACT], o[O_DEACT],
                               o[O_FLOPS], _NAN, _NAN, info, True)

        self._run = run

    def warmup(self) -> None:
        """Compile or load both kernels (:func:`warmup`)."""
        warmup()

    def solve(self, hierarchy: Hierarchy) -> SolveResult:
        if hierarchy is self._h:
            return self._run()
        if hierarchy is self._eq_h:
            return self._solve_equality(hierarchy)
        self.check_hierarchy(hierarchy)  # (after the re-solve paths: they hold a Hierarchy)
        if hierarchy.n == 0 or hierarchy.rows == 0:
            return SolveResult(x=np.zeros(hierarchy.n), status=OPTIMAL, flops=0,
                               iterations_per_level=(0,) * hierarchy.depth)
        if not hierarchy.has_inequalities:
            if _eq_run is None:
                warmup()
            self._eq_h = hierarchy
            return self._solve_equality(hierarchy)
        self._eq_h = _NONE
        return self._bind(hierarchy)()


def warmup() -> str:
    """Bring the kernels into this process, loaded from numba's cache (a
    child process compiles them first when the cache lacks them:
    :func:`._cache.load_kernels`), by solving two tiny problems, one
    equality-only and one with inequalities: the same kernels in the same
    order in every process, so that every process computes the same x to
    the last bit. Once per process; the first solve calls it, and the
    benchmark's worker before every job. Returns how they came: ``"loaded"``,
    ``"compiled by a child process"``, ``"compiled here"`` or
    ``"already in this process"``."""
    global _eq_run, _ineq
    if _ineq is not None:
        return "already in this process"
    from hikbench.solvers.hcod import _cache

    _import_kernels()
    try:
        return _cache.load_kernels(_tiny_solves, "import hikbench.solvers.hcod as h; h._compile_kernels()")
    except BaseException:
        _eq_run = _ineq = None  # (not loaded: the next solve tries again)
        raise


def _import_kernels() -> None:
    """The kernels' modules imported (nothing compiles or loads yet) and
    bound to ``_eq_run`` and ``_ineq``."""
    global _eq_run, _ineq
    from hikbench.solvers.hcod import _setup
    from hikbench.solvers.hcod._equality import eq_run
    from hikbench.solvers.hcod._kernel import hcod_solve

    _eq_run, _ineq = eq_run, (hcod_solve, _setup)


def _tiny_solves() -> None:
    from hikbench.problems.hierarchy import Level

    h_eq = Hierarchy.from_levels([Level.equality(np.eye(2), np.ones(2))], n=2)
    h_in = Hierarchy.from_levels([Level(np.eye(2), -np.ones(2), np.ones(2)),
                                  Level.equality(np.ones((1, 2)), [3.0])], n=2)
    s = HcodSolver()
    s.solve(h_eq)
    s.solve(h_in)


def _compile_kernels() -> None:
    """What :func:`warmup`'s child process runs: the two tiny solves, which
    compile the kernels here and write numba's cache."""
    _import_kernels()
    _tiny_solves()


SOLVERS = [SolverInfo.of(HcodSolver)]
