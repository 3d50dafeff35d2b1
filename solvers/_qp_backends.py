"""Per-backend option tables of the QP cascades (data, not code paths).

Every table is keyed by the qpsolvers backend name. A cascade maps its
options onto each backend's own parameter names through these tables only:

* :data:`ACCURACY` — the accuracy profiles ``high`` / ``default`` / ``low``.
  ``high`` is 1e-9 absolute with relative tolerances switched off (set to 0)
  wherever the backend has them; ``default`` passes nothing (the backend's
  own defaults, the out-of-the-box experience); ``low`` is 1e-5 absolute and
  relative. quadprog (Goldfarb-Idnani dual active set, exact up to round-off)
  has no tolerance parameter: its three profiles are the same. OSQP's
  ``high`` also raises ``max_iter`` to 100000 (ADMM needs many iterations to
  reach 1e-9; the default 4000 would make ``high`` mostly ``max_iterations``).
  OSQP's
  ``polish`` stays off: its C code prints "Polishing not needed" on stdout
  even when not verbose, which would corrupt ``hikbench solve --json``.
* :data:`NOMINAL_TOL` — the absolute accuracy each profile aims at, used
  for the ``relaxed`` freeze delta (1x) and for deciding which slacks are nonzero.
* :data:`MAX_ITER_NAME` — the name of the iteration cap, None when the
  backend has none.
* :data:`WARM_START` — whether the backend uses ``initvals`` (OSQP:
  ``warm_start(x=...)``, ProxQP: ``x=``, DAQP: ``primal_start``); the others
  ignore it (and qpsolvers warns), so the cascade does not pass it.
* :data:`SPARSE` — whether the backend takes CSC matrices (qpsolvers would
  convert otherwise); the conversion is part of the cascade's build time.
* :data:`SETTINGS` — per backend (and ``cvxpy``, the cascade modelled in
  cvxpy) and accuracy profile: the tolerance preset (a key of
  :data:`ACCURACY`), the freeze mode, the regularisation (the weight ``eps``
  of ``eps/2 ||x||^2`` added to each level's cost: it keeps the Hessian
  positive definite for quadprog and DAQP; its effect on the optimal slack is
  of order ``eps ||x||^2``) and the iteration cap (None: the backend's own, or :data:`DEFAULT_MAX_ITER`) that the sweep of
  docs/solvers.md ("Fair settings", ``hikbench.bench.analysis.settings_sweep``)
  chose: the most problems verified at that profile, then the fastest. A
  cascade's option ``accuracy`` picks the row; its options ``tolerances``,
  ``freeze``, ``regularization`` and ``max_iter`` override it.
* :data:`INSTALL` — pip hints for backends that are not installed.
"""

from __future__ import annotations

BACKENDS: tuple[str, ...] = ("osqp", "proxqp", "clarabel", "daqp", "quadprog", "piqp", "highs")
PROFILES: tuple[str, ...] = ("high", "default", "low")

ACCURACY: dict[str, dict[str, dict[str, float | bool]]] = {
    "osqp": {
        "high": {"eps_abs": 1e-9, "eps_rel": 0.0, "max_iter": 100_000},
        "default": {},
        "low": {"eps_abs": 1e-5, "eps_rel": 1e-5},
    },
    "proxqp": {
        "high": {"eps_abs": 1e-9, "eps_rel": 0.0},
        "default": {},
        "low": {"eps_abs": 1e-5, "eps_rel": 1e-5},
    },
    "clarabel": {
        "high": {"tol_gap_abs": 1e-9, "tol_gap_rel": 0.0, "tol_feas": 1e-9, "tol_ktratio": 1e-9},
        "default": {},
        "low": {"tol_gap_abs": 1e-5, "tol_gap_rel": 1e-5, "tol_feas": 1e-5},
    },
    "daqp": {
        "high": {"primal_tol": 1e-9, "dual_tol": 1e-9},
        "default": {},
        "low": {"primal_tol": 1e-5, "dual_tol": 1e-5},
    },
    "quadprog": {"high": {}, "default": {}, "low": {}},
    "piqp": {
        "high": {"eps_abs": 1e-9, "eps_rel": 0.0, "eps_duality_gap_abs": 1e-9, "eps_duality_gap_rel": 0.0},
        "default": {},
        "low": {"eps_abs": 1e-5, "eps_rel": 1e-5, "eps_duality_gap_abs": 1e-5, "eps_duality_gap_rel": 1e-5},
    },
    "highs": {
        "high": {"primal_feasibility_tolerance": 1e-9, "dual_feasibility_tolerance": 1e-9},
        "default": {},
        "low": {"primal_feasibility_tolerance": 1e-5, "dual_feasibility_tolerance": 1e-5},
    },
}

NOMINAL_TOL: dict[str, float] = {"high": 1e-9, "default": 1e-6, "low": 1e-5}

MAX_ITER_NAME: dict[str, str | None] = {
    "osqp": "max_iter", "proxqp": "max_iter", "clarabel": "max_iter", "daqp": "iter_limit",
    "quadprog": None, "piqp": "max_iter", "highs": "qp_iteration_limit",
}

#: an iteration cap where the backend's own default has none: HiGHS's QP solver (qp_iteration_limit
#: 2^31 - 1) looped for more than 10 min on degenerate/badly_scaled seed 1 and the arm_reach robot
#: stack; with 10000 it answers in 0.03 s. The option max_iter replaces it.
DEFAULT_MAX_ITER: dict[str, int] = {"highs": 10_000}

WARM_START: dict[str, bool] = {
    "osqp": True, "proxqp": True, "clarabel": False, "daqp": True, "quadprog": False,
    "piqp": False, "highs": False,
}

SPARSE: dict[str, bool] = {
    "osqp": True, "proxqp": False, "clarabel": True, "daqp": False, "quadprog": False,
    "piqp": False, "highs": True,
}

#: the swept settings of each backend at each accuracy profile (module doc; docs/solvers.md, "Fair
#: settings"), as written by ``python -m hikbench.bench.analysis.settings_sweep choose``, except the rows
#: marked HLSP-1, where the sweep's choice verified fewer problems of the test set HLSP-1 than the
#: setting written here (docs/solvers.md, "Checked on HLSP-1"): keys
#: ``tolerances`` (a preset of ACCURACY), ``freeze``, ``regularization``, ``max_iter`` (None: the
#: backend's own cap, or DEFAULT_MAX_ITER). quadprog has no tolerance: its presets are the same.
SETTINGS: dict[str, dict[str, dict]] = {
    "clarabel": {  # (every row: HLSP-1's check, below the sweep's table in docs/solvers.md)
        "high": {"tolerances": "high", "freeze": "shift", "regularization": 1e-12, "max_iter": None},
        "default": {"tolerances": "high", "freeze": "shift", "regularization": 1e-12, "max_iter": None},
        "low": {"tolerances": "high", "freeze": "shift", "regularization": 1e-12, "max_iter": None},
    },
    "cvxpy": {
        "high": {"tolerances": "high", "freeze": "shift", "regularization": 1e-12, "max_iter": 2000},
        "default": {"tolerances": "high", "freeze": "relaxed", "regularization": 1e-12, "max_iter": None},
        "low": {"tolerances": "high", "freeze": "shift", "regularization": 1e-12, "max_iter": 2000},
    },
    "daqp": {
        "high": {"tolerances": "high", "freeze": "equality", "regularization": 1e-12, "max_iter": None},  # (HLSP-1)
        "default": {"tolerances": "high", "freeze": "shift", "regularization": 1e-12, "max_iter": None},
        "low": {"tolerances": "low", "freeze": "equality", "regularization": 1e-12, "max_iter": None},
    },
    "highs": {
        "high": {"tolerances": "default", "freeze": "equality", "regularization": 1e-12, "max_iter": None},
        "default": {"tolerances": "default", "freeze": "equality", "regularization": 1e-12, "max_iter": None},
        "low": {"tolerances": "high", "freeze": "shift", "regularization": 1e-08, "max_iter": 100000},
    },
    "osqp": {
        "high": {"tolerances": "high", "freeze": "shift", "regularization": 1e-12, "max_iter": None},
        "default": {"tolerances": "high", "freeze": "shift", "regularization": 1e-12, "max_iter": None},
        "low": {"tolerances": "high", "freeze": "shift", "regularization": 1e-12, "max_iter": None},
    },
    "piqp": {
        "high": {"tolerances": "high", "freeze": "shift", "regularization": 1e-12, "max_iter": None},
        "default": {"tolerances": "default", "freeze": "shift", "regularization": 1e-12, "max_iter": None},
        "low": {"tolerances": "high", "freeze": "equality", "regularization": 1e-10, "max_iter": 2500},
    },
    "proxqp": {
        "high": {"tolerances": "high", "freeze": "equality", "regularization": 1e-12, "max_iter": None},
        "default": {"tolerances": "high", "freeze": "equality", "regularization": 1e-12, "max_iter": None},
        "low": {"tolerances": "high", "freeze": "equality", "regularization": 1e-12, "max_iter": None},
    },
    "quadprog": {
        "high": {"tolerances": "high", "freeze": "relaxed", "regularization": 1e-12, "max_iter": None},
        "default": {"tolerances": "default", "freeze": "relaxed", "regularization": 1e-12, "max_iter": None},
        "low": {"tolerances": "low", "freeze": "relaxed", "regularization": 1e-12, "max_iter": None},
    },
}

INSTALL: dict[str, str] = {
    "osqp": "pip install osqp", "proxqp": "pip install proxsuite", "clarabel": "pip install clarabel",
    "daqp": "pip install daqp", "quadprog": "pip install quadprog", "piqp": "pip install piqp",
    "highs": "pip install highspy",
}

#: cvxpy solver name -> accuracy profiles in that solver's own parameter names
CVXPY_ACCURACY: dict[str, dict[str, dict[str, float | bool]]] = {
    "CLARABEL": ACCURACY["clarabel"],
    "OSQP": ACCURACY["osqp"],
    "PIQP": ACCURACY["piqp"],
    "PROXQP": ACCURACY["proxqp"],
    "SCS": {"high": {"eps_abs": 1e-9, "eps_rel": 0.0, "max_iters": 100_000}, "default": {},
            "low": {"eps_abs": 1e-5, "eps_rel": 1e-5}},
}


def status_outcome(backend: str, sol) -> tuple[str, str]:
    """Classify a qpsolvers Solution that was not ``found``.

    Returns ``(outcome, text)`` with outcome one of ``"inaccurate"`` (the backend
    stopped close to a solution, e.g. OSQP "solved inaccurate", Clarabel
    "AlmostSolved"), ``"max_iterations"``, ``"infeasible"``, ``"numerical"``
    (Clarabel NumericalError / InsufficientProgress, PIQP_NUMERICS),
    ``"unknown"`` (e.g. DAQP, quadprog, HiGHS, whose status qpsolvers does
    not pass on), and text the backend's own status.
    """
    text = _status_text(backend, sol)
    low = text.lower()
    if ("inaccurate" in low and "infeas" not in low) or "almostsolved" in low:
        return "inaccurate", text
    if "iter" in low:
        return "max_iterations", text
    if "infeas" in low or "no solution" in low:
        return "infeasible", text
    if "numer" in low or "insufficientprogress" in low:
        return "numerical", text
    return "unknown", text


def _status_text(backend: str, sol) -> str:
    extras = getattr(sol, "extras", None) or {}
    info = extras.get("info")
    if backend == "clarabel" and "status" in extras:
        return str(extras["status"])
    if info is not None:
        for attr in ("status", "status_val"):
            if hasattr(info, attr):
                return str(getattr(info, attr))
    return "not reported by qpsolvers"


def iterations(backend: str, sol) -> int:
    """Iterations reported by the backend through qpsolvers, 0 when it reports none."""
    extras = getattr(sol, "extras", None) or {}
    info = extras.get("info")
    if info is not None and hasattr(info, "iter"):
        return int(info.iter)
    if backend == "quadprog" and "iterations" in extras:
        return int(extras["iterations"][0])
    return 0
