"""The reference HCOD solver (Escande, Mansard, Wieber, ICRA 2010), registered
as ``hcod``.

Equality-only hierarchies (sec. V-VI, :mod:`._equality`)
    Per level, the rank-revealing COD (19) of the projected level
    ``J_k Z_{k-1}`` -- Householder QR with column pivoting of its transpose,
    then (rank-deficient levels only) a QR of the trapezoidal factor -- and
    the update ``u_k = u_{k-1} + Z_{k-1} Y_k L_k^-1 V_k^T (e_k - J_k u_{k-1})``
    (eqs. 30-31). The basis ``[Y_bar, Z]`` (eq. 23) is kept implicit: the
    level's reflectors are stored in its own rows and applied to a lower
    level's rows only when that level is reached with ``nf > 0``, so levels
    after saturation cost nothing (36 DOF, 24 levels x 6 rows: the same flops
    as 6 levels). ``x`` is the minimum-norm lexicographic solution (u_0 = 0
    and minimum-norm steps, eq. 28).

Inequalities at any level (sec. VII-X, :mod:`._kernel`)
    The LSIs (33)-(35) level by level by a primal active set on the HCOD: the
    LSE step (43)-(44) by the COD of the level's objective rows projected on
    ``Z``; step length to the first blocking row (higher levels' inactive rows
    and the level's own inactive rows); activation; deactivation by the sign
    of ``mu = w`` (38) and of ``lambda`` (39) from the triangular factor.
    Working rows enter the explicit orthonormal basis ``W = [Y_bar, Z]`` (kept
    by columns, ``W^T``, so that every update runs on contiguous vectors of
    length n) by a Householder update and leave it by Givens rotations (sec.
    IX); the rows a warm start re-activates enter together (one blocked
    Householder QR, then its reflectors applied to ``W`` at once); the
    projected objective rows ``J_hat_k Z`` are carried along the same updates
    across iterations (a new column or a reflector, not a new projection); the
    level's COD (19) is updated when only the level's own rows entered since
    the last iteration (one reflector per independent row: :func:`._linalg.cod_append`)
    and recomputed after a working row entered or left (``Z`` changed) or an
    objective row left. (An update through a change of ``Z`` needs ``Y_k``
    explicit, then about 2r Givens rotations on it and on ``L_k``, some
    ``8 r (nf + nO)`` multiply-adds, and gives up the column pivoting that
    reveals the rank; the COD from scratch is ``sum_{i<r} 2 (nO - i)(nf - i)``.
    Over the recomputations of cold IK-like solves, seeds 0-4, the update
    would cost 1.8-2.1x the COD at n = 20 and 0.62-0.92x at n = 80, where
    these CODs are 4-8 % of a solve's flops: not worth the pivoting.)
    At the end of a
    level its rows are frozen (eq. 36) through that COD: rows with a nonzero
    slack become equalities at their achieved value, zero-slack inequality
    rows stay (removable) inequality constraints. Each level starts from the
    previous optimum and working set, completed by (45). Handles equality rows
    inside inequality levels, two-sided rows (one side active at a time),
    free rows (never active), empty levels, infeasible levels (nonzero slack;
    status stays optimal), bound rows (one nonzero: O(1) products) and
    identity-like levels (posture ``x = x*`` and the min-norm stage: the LSE
    is a product with ``Z^T``; after such an equality level ``x`` is unique and
    the levels below are skipped).

Rank detection
    Each level is scaled by ``1 / ||A_k||_F`` (same minimisers, overflow-free
    reflectors for row norms from 1e-300 to 1e300; the factor is at most
    2^1023, which brings a level of subnormal rows of norm 3e-309 to 0.28:
    such levels are solved down to norms of ~1e-318, and read as zero rows
    from ~1e-320, scaled to ~1e-12). A pivot counts when its
    remaining norm exceeds ``rank_rtol`` (default 1e-10) times the norm of
    the *unprojected* level, like the reference's ``s_i > 1e-10 ||A_k||_2``
    (``||A_k||_2 <= ||A_k||_F <= sqrt(rank) ||A_k||_2``: a compatible,
    slightly more conservative rule). On a *wide* level of a problem with
    inequalities (row norms spread beyond ``MET_SPREAD`` = 1e3) the COD
    goes on past that threshold row by row: the next pivot is the row whose
    remaining norm is the largest fraction of its own unprojected norm, and
    counts while that fraction exceeds ``_linalg.ROW_RANK_RTOL`` = 1e-5 (or
    ``rank_rtol``, if larger; a projection's rounding can reach 1e-6 of its
    row at cond 1e6 and rows spread over 1e4). A row 1e-8 the size of its
    level's largest sees directions the level's threshold cuts; they were
    never descended, and the level ended up to 1.8 % above its optimum on
    ``badly_scaled`` n = 12 seeds 128, 1143, 1402, 1696 and 2876. A blocking row
    inserted in the working set obeys the test at its own norm on its
    component outside the span of the working rows. The equality-only
    kernel keeps the level's threshold on every level.

Tolerances (data, not options)
    multipliers: they are computed when ``||g|| > gtol`` and a working row is
    removed when ``lambda_j ||a_j|| < -gtol``, ``gtol = sum_j ||a_j|| delta_j``
    over the objective rows (the noise floor of the gradient ``g = J_k^T w``),
    ``delta_j`` the error of the residual ``w_j``: ``1e-2 f_j`` (a typical
    rounding of ``a_j u - e_j``, not a bound; ``f_j = 1e-13 (||a_j|| (1 +
    ||u||) + |e_j|)`` the row's rounding floor), plus,
    for a row met to within ``f_j``, its measured ``|w_j|`` (a met row's
    residual is u's error along it; when rows counted at their whole floor,
    the large rows of a badly scaled level, met or not, hid the force of its
    small unmet rows). A multiplier below ``-gtol_r`` (the rounding part of
    gtol alone) but above ``-gtol`` has the met rows held at their bounds as
    constraints and their multipliers fitted (``_kernel._met_force``; a met
    row's residual is u's error or the optimum's: either way), as has every
    level whose row norms span more than ``MET_SPREAD``; a multiplier below
    ``-1e-2 gtol_r`` but above ``-gtol_r`` is measured once more after one
    step more from ``u`` on the same working set, and the row leaves when it
    is below twice its change (iterative refinement, as for the objective
    rows below; one such step per level and working set);
    an objective inequality row leaves when its ``mu = w`` has the wrong
    sign beyond its floor ``f`` (``1e-13 (||a|| (1 + ||u||) + |e|)``), or
    beyond ``1e-2 f`` and twice its change under one more step from ``u``
    on the same working set (iterative refinement: the change measures u's
    error along the row; one such step per level and working set);
    a slack below ``1e-11 (...)`` counts as zero at a freeze; warm-start
    feasibility ``1e-9 (||a|| (1 + ||u||) + 1)``.
    The ``1 +`` and ``+ 1`` parts are absolute: made for bounds not far below
    1. A problem whose finite bounds (levels scaled as above) are all below
    2^-10 in magnitude is solved for ``u = f x``, its bounds times the
    power of 2 ``f`` that brings the largest into [1, 2) (exact; the same
    minimisers, since the problem is homogeneous in (x, bounds);
    ``info["bounds_scaled_by"]``). With bounds x 1e-9 a ``time`` re-solve of
    the same problem accepted shifted points violating level 0 by up to 7
    times the problem's size before (15 of 60 IK-like n=20 seeds). A
    ``time`` record follows a change of ``f`` (its ``Delta u`` keep their
    size in x).

Minimum norm with inequalities
    The active-set path can leave components in the null space of the final
    working set; with ``min_norm=True`` (default) one implicit last level
    ``x = 0`` removes them (its iterations are counted in ``iterations`` and
    reported in ``info["min_norm_iterations"]``). It is skipped after an
    identity-like equality level (x already unique).

Warm start (sec. XI), option ``warm_start``
    ``"none"``: each call cold, and each level starts from the previous
    optimum with only its frozen equality rows (not the previous active
    inequality set); ``"stage"``: sec. X, level to level within a call;
    ``"time"`` (default): also across calls on the same object -- each
    level's working set and ``Delta u`` (eq. 46) recorded at the last call are
    re-applied (``Delta^- A`` removed, ``Delta u`` projected on the current
    ``Z`` and shortened by tau to keep inactive rows feasible, ``Delta^+ A``
    inserted, then an LSE correction onto the inserted rows). A level whose
    corrected point violates a row above starts cold from the previous
    level's optimum instead (``info["warm_fallback_levels"]``). A call with a
    level whose optimum lies far from a warm point of it or of a level above
    (``||u_hat|| > 1e6 (1 + ||u_k||)``: a record of a huge step, the optimum
    back to O(1)) is done once more cold (``info["cold_after_warm"]``; the
    counters add both passes): the steps back cancel and leave ``eps
    ||u_hat||`` along the working rows, a violation of the levels above.
    Within a solve, in any mode: an LSE step through a pivot of the level's
    COD (19) near the rank threshold (within 10x: a direction of ``J_k Z``
    that may be rounding, a level in the span of the rows above) that is
    taken past ``1e6 (1 + ||u||)`` (``tau ||p||``, after the blocking rows)
    leaves out the pivots from that one on, solves the least squares of the
    ones before, and finds its step length again
    (``info["near_rank_steps_cut"]``, the number of such cuts; the equality
    recursion takes the level's rank as those pivots, so that the levels
    below get the directions back): its rounding, ``eps`` times the step
    along the working rows, would violate the levels above. And a level's
    optimum u_k with
    ``||u|| > 1e6 (1 + ||u_k||)`` at an earlier point of this level or one
    above (a step out and back) has the solve done again cold, each
    LSE step below working rows cut to ``1e6 (1 + ||u||)`` by leaving out the
    pivots from the first that takes it past (``info["steps_capped"]``; the
    counters add both passes). The cut level is left where its solvable
    pivots put it; the levels above keep their optimum. A run of
    levels run0..m-1 that met their objectives exactly (every objective row
    within its rounding floor) is marked in the record: a re-solve jumps at
    run0 to the last call's ``u_m`` (the sum of the run's ``Delta u``, level
    m's included) with level m's working set for the rows above each level
    of the run, when every row of those levels is met there (tested before
    the jump -- if not, the records as above -- and after the correction --
    if not, that level starts cold as above): each of them is then at a zero
    objective, and it no longer re-inserts rows that a level below deletes.
    A jumping call keeps the run's records (level m's ``Delta u`` absorbs its
    step). The test costs 1-5 % more flops on a problem that moved, where it
    fails; it pays on a re-solve of the same problem. The record is
    used whenever the new hierarchy has the same shape (a trajectory, or the
    benchmark's warm mode that re-solves the same problem); ``reset()``
    forgets it. Equality-only problems have no active set: warm == cold.

Result
    ``iterations`` counts LSE solves (active-set iterations; 1 per nonempty
    level for equality problems), ``iterations_per_level`` the same per level,
    ``activations`` / ``deactivations`` the active-set changes of the
    iterations: a blocking row entering, a row leaving by the sign of its
    multiplier (a two-sided row switching side counts as one of each); not
    counted: implied rows re-entering the decomposition after a deletion, and
    the rows a warm start's record brings in or drops before a level's first
    iteration (Delta+ / Delta-). ``flops`` the
    multiply-adds counted inside the kernels (see the test relating it to the
    26.9 Kflops of sec. VI). Statuses: ``optimal``; ``max_iterations`` when the
    cap (option ``max_iterations``, default ``100 + 10 (rows + n)``) is hit
    (x = last iterate, reason names the level); ``numerical_failure`` when x
    is not finite (x = None). A blocking row that cannot enter the
    decomposition (a combination of the working rows to the rank threshold)
    no longer blocks while they stay (see ``._kernel``).
    No exception escapes for a valid problem.

Compiled with numba (nopython, ``cache=True``); nothing compiles at import:
the first solve (or :func:`warmup`) loads the kernels from numba's cache,
whose entries are valid while every ``solvers/hcod/*.py`` file but this one
is unchanged (:mod:`._cache`; numba alone looks only at the file of the
function it caches, not at the helpers compiled into it). When the cache
lacks them, a child process compiles them (~90 s) and this one loads them:
a process that compiled them itself would run other copies of their
helpers and compute other last bits (:func:`._cache.load_kernels`). One
compiled call per solve (plus one to scale a new hierarchy), on workspaces
kept in the solver object; the kernels see them as unowned arrays (no
reference counting of their views, :func:`._linalg.unowned`) and test every
entry of ``x`` for finiteness themselves (``SolveResult(x_finite=True)``).
"""

from __future__ import annotations

from itertools import pairwise

import numpy as np

from problems.hierarchy import Hierarchy
from solvers.base import MAX_ITERATIONS, NUMERICAL_FAILURE, OPTIMAL, Solver, SolveResult
from solvers.registry import SolverInfo, check_bool, check_choice, check_int, check_number

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
)

__all__ = ["SOLVERS", "WARM_STARTS", "HcodSolver", "warmup"]

WARM_STARTS = ("none", "stage", "time")
_NAN = float("nan")  # (build_time_s, solve_time_s: not separated)
_NONE = object()  # (matches no solve() argument, unlike None)
_STATUS = {0: OPTIMAL, 1: MAX_ITERATIONS, 2: NUMERICAL_FAILURE}
_eq_run = None  # solvers.hcod._equality.eq_run, set by warmup() (the first solve calls it)
_ineq = None  # (._kernel.hcod_solve, ._setup), set with it


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
            from solvers.hcod._setup import iblock

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
        ip = (n, mt, D, mmax, cap, WARM_STARTS.index(self.warm_start), 1)  # (slots ._layout.IP_*)
        fw, iw, xv, outv = setup.workspaces(ip, self._prm)
        self._ws = (fw, iw)
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
                hcod_solve(fw, iw)
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


def warmup() -> None:
    """Bring the kernels into this process, loaded from numba's cache (a
    child process compiles them first when the cache lacks them:
    :func:`._cache.load_kernels`), by solving two tiny problems, one
    equality-only and one with inequalities: the same kernels in the same
    order in every process, so that every process computes the same x to
    the last bit. Once per process; the first solve calls it, and the
    benchmark's worker before every job."""
    global _eq_run, _ineq
    if _ineq is not None:
        return
    from solvers.hcod import _cache

    _import_kernels()
    try:
        _cache.load_kernels(_tiny_solves, "import solvers.hcod as h; h._compile_kernels()")
    except BaseException:
        _eq_run = _ineq = None  # (not loaded: the next solve tries again)
        raise


def _import_kernels() -> None:
    """The kernels' modules imported (nothing compiles or loads yet) and
    bound to ``_eq_run`` and ``_ineq``."""
    global _eq_run, _ineq
    from solvers.hcod import _setup
    from solvers.hcod._equality import eq_run
    from solvers.hcod._kernel import hcod_solve

    _eq_run, _ineq = eq_run, (hcod_solve, _setup)


def _tiny_solves() -> None:
    from problems.hierarchy import Level

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


SOLVERS = [SolverInfo("hcod", HcodSolver.description, HcodSolver, supports_inequalities=True,
                      supports_warm_start=True,
                      options={"warm_start": "time", "max_iterations": None, "rank_rtol": 1e-10, "min_norm": True})]
