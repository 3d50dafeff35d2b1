"""Names of the blocks of the inequality kernel's workspaces and of its
parameter and output slots, shared by the kernel (:mod:`._kernel`), the code
that lays the workspaces out and fills them (:mod:`._setup`) and the solver
that reads the results (the package's ``__init__``).

The kernel takes two arrays: ``fw`` (floats) and ``iw`` (ints). ``iw`` starts
with a header of offsets (:func:`._setup.layout`): float block ``b`` is
``fw[iw[b]:iw[FEND0 + b]]``, int block ``b`` is ``iw[iw[IOFF0 + b]:iw[IOFF0 +
b + 1]]``, ``b`` one of the ``F_*`` / ``I_*`` constants below. These are plain
module-level ints: numba freezes them into the compiled code as constants, so
a block fetched by name costs what one fetched by a literal index did.

Shapes (n variables, mt rows with the min-norm stage's, D levels, mmax rows of
the largest level, ``mm = max(mmax, 1)``) are those of :func:`._setup.layout`.
"""

from __future__ import annotations

# ---- float blocks (fw) ------------------------------------------------------------------------
F_W = 0  #: Wt (n, n): the basis W = [Y_bar, Z] (eq. 23) by columns (factored: W0, see ._basis)
F_R = 1  #: R (n, n): the working rows' coordinates in W, upper triangular (C^T = W[:, :p] R)
F_U = 2  #: u (n,): the iterate, the solution at the end (u = f x, see ._setup.load)
F_PS = 3  #: ps (n,): the step of u (LSE step, eqs. 30-31; warm shift, eq. 46)
F_Z = 4  #: z (n,): scratch (the step in Z's coordinates; the jump point)
F_G = 5  #: g (n,): the level's gradient J_hat^T w (multipliers, eq. 39)
F_HV = 6  #: hv (n,): scratch of the multipliers and of the warm correction
F_NU = 7  #: nu (n,): the working rows' multipliers lambda (eq. 39)
F_Q = 8  #: q (n,): the reflector of a row entering W
F_UPREV = 9  #: uprev (n,): u at the start of the level (u_{k-1})
F_Y = 10  #: y (n,): the LSE solution in the COD's coordinates (eq. 30)
F_MR = 11  #: Mr (mm, n): the level's COD (19) of J_hat_k Z: its reflectors and L
F_BVEC = 12  #: bvec (mm,): the LSE right-hand side e - J u in pivot order (eq. 28)
F_DIAG = 13  #: diag (mm,): the diagonal of the COD's triangular factor
F_BETA = 14  #: beta (mm,): the coefficients of the COD's reflectors
F_LB = 15  #: Lb (mm * max(min(n, mm), 1)): scratch of the triangular solve
F_TARGET = 16  #: target (mt,): each active row's bound (e_i), or its value once frozen (eq. 36)
F_RNORM = 17  #: rnorm (mt,): the scaled rows' norms ||a_i||
F_BVAL = 18  #: bval (mt,): a bound row's coefficient (0 for other rows)
F_LNORM = 19  #: lnorm (D,): each scaled level's ||A_k||_F
F_HIST_DU = 20  #: hist_du (D, n): the steps Delta u_k of the last call (eq. 46)
F_MF = 21  #: Mf (mm, n): the level's objective rows projected, W^T a_j
F_QB = 22  #: Qb (n, n): scratch of the blocked insertion and of push_reflectors
F_BQ = 23  #: bq (n,): scratch of the blocked insertion
F_SV = 24  #: sv (2 n): two scratch vectors (n,) of the basis' products
F_A = 25  #: A (mt, n): the scaled problem's rows (._setup.load)
F_LO = 26  #: lo (mt,): its lower bounds
F_UP = 27  #: up (mt,): its upper bounds
F_PRM = 28  #: prm (N_PRM,): the float parameters, slots PRM_*
F_QV = 29  #: qv: the queue of the factored basis, floats (._factored)
F_BLOCKS = ("W", "R", "u", "ps", "z", "g", "hv", "nu", "q", "uprev", "y", "Mr", "bvec", "diag", "beta",
            "Lb", "target", "rnorm", "bval", "lnorm", "hist_du", "Mf", "Qb", "bq", "sv", "A", "lo", "up",
            "prm", "Qv")  #: their names, in the order of the constants

# ---- int blocks (iw, after the header) --------------------------------------------------------
I_STATE = 0  #: state (mt,): each row's state (INACTIVE, WORK, ... of ._kernel)
I_SIDE = 1  #: side (mt,): +1 upper bound, -1 lower bound, 0 equality or frozen
I_KIND = 2  #: kind (mt,): 0 equality, 1 inequality, 2 free (._setup.prepare)
I_BCOL = 3  #: bcol (mt,): a bound row's column, -1 for other rows
I_WIDX = 4  #: widx (n,): the working rows, in the order of R's columns
I_WSIDE = 5  #: wside (n,): their sides (0: an equality, never leaves)
I_OLIST = 6  #: Olist (mm,): the level's objective rows (J_hat_k, eq. 43)
I_HIST_STATE = 7  #: hist_state (D, mt): the states at the end of each level at the last call
I_HIST_SIDE = 8  #: hist_side (D, mt): the sides, likewise
I_HIST_VALID = 9  #: hist_valid (D,): 0 no record, 1 a record, 2 + m the start of a run met up to level m
I_OUT = 10  #: out (N_OUT + D): the output slots O_*, then the iterations per level
I_LEVID = 11  #: levid (D,): 0, 1 identity-like level, 2 identity-like equality level
I_PIV = 12  #: piv (mm,): the COD's row pivots
I_CAND = 13  #: cand (n,): the rows a warm start re-activates
I_COK = 14  #: cok (n,): their sort keys, then their accept flags
I_STARTS = 15  #: starts (D + 1,): the first row of each level
I_IP = 16  #: ip (N_IP,): the int parameters, slots IP_*
I_QI = 17  #: qi: the queue of the factored basis, ints (._factored)
I_BLOCKS = ("state", "side", "kind", "bcol", "widx", "wside", "Olist", "hist_state",
            "hist_side", "hist_valid", "out", "levid", "piv", "cand", "cok", "starts", "ip", "qi")

#: the int workspace starts with the offsets themselves: foff (starts of the float blocks and
#: the total, iw[:FEND0]), fend (ends of the float blocks, iw[FEND0:IOFF0]), ioff (iw[IOFF0:N_HEAD])
FEND0 = len(F_BLOCKS) + 1
IOFF0 = FEND0 + len(F_BLOCKS)
N_HEAD = IOFF0 + len(I_BLOCKS) + 1

# ---- int parameters (the "ip" block) ----------------------------------------------------------
IP_N = 0  #: n, the number of variables
IP_MT = 1  #: mt, the rows (the min-norm stage's included)
IP_D = 2  #: D, the levels (the min-norm stage included)
IP_MMAX = 3  #: mmax, the rows of the largest level
IP_MAX_ITER = 4  #: the cap on the iterations of one call
IP_WARM = 5  #: the warm start, one of WARM_*
IP_HAS_INEQ = 6  #: 1 when the problem has inequalities
N_IP = 7

# ---- warm-start modes (the "ip" block's IP_WARM slot; the option warm_start's values) ---------
WARM_NONE = 0  #: every level starts from its frozen equality rows only
WARM_STAGE = 1  #: level to level within a call (sec. X)
WARM_TIME = 2  #: also across calls, from the record of the last one (sec. XI)
WARM_MODES = ("none", "stage", "time")  #: the option's values, WARM_MODES[WARM_*]

# ---- float parameters (the "prm" block) -------------------------------------------------------
PRM_RANK_RTOL = 0  #: rank threshold, relative to ||A_k||_F
PRM_FEAS_RTOL = 1  #: feasibility tolerance of a warm point
PRM_DUAL_RTOL = 2  #: the rounding floor of a row's residual (multipliers' noise floor)
PRM_FREEZE_RTOL = 3  #: zero slack at the freeze
N_PRM = 4

# ---- output slots (the head of the "out" block) -----------------------------------------------
O_STATUS = 0  #: 0 optimal, 1 iteration cap, 2 u not finite
O_ITERS = 1  #: the iterations (LSE solves) of the call
O_ACT = 2  #: activations
O_DEACT = 3  #: deactivations
O_FLOPS = 4  #: multiply-adds
O_LEVEL = 5  #: the level where the cap was reached (-1: none)
O_WARMFAIL = 6  #: levels whose warm point was infeasible (started cold)
O_COLD = 7  #: 1: the call was done again cold (COLD_AFTER_WARM)
O_CAPPED = 8  #: 1: the call was done again with the LSE steps cut (CANCELLED)
O_NEARCUT = 9  #: LSE steps cut at a pivot near the rank threshold
N_OUT = 10  #: the output slots; the iterations per level follow them


def _check_names():
    """The constants follow the order of the name tuples (``F_`` or ``I_`` and the block's name
    in capitals): an edit of one without the other would shift every block."""
    g = globals()
    for prefix, names in (("F_", F_BLOCKS), ("I_", I_BLOCKS)):
        for b, name in enumerate(names):
            if g.get(prefix + name.upper()) != b:
                raise AssertionError(f"_layout: {prefix + name.upper()} is not {b}, the index of {name!r}")


_check_names()
