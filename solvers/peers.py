"""The C++ peers SOTH, LexLS and NIPM-HLSP, registered as ``soth``, ``lexls`` and
``nipm-hlsp`` once built (``make peers``).

They solve the same sequence of LSIs as hcod (ICRA 2010, eqs. 33-36) on a
hierarchy ``lower_k <= A_k x <= upper_k``, in-process through hikbench's own
pybind11 adapters (``peers/soth_adapter.cpp``, ``peers/lexls_adapter.cpp``,
``peers/nipm_adapter.cpp``), built from the peers' pinned sources by
``peers/build.py`` into :func:`peers_dir`. SOTH and LexLS are active-set
methods; NIPM-HLSP (Pfeiffer, Escande et al., arXiv 2106.13602) is a primal-dual
interior-point method with no warm start: each of its solves is cold. Each
solver object of the first two keeps its peer's state between calls:

* ``soth``: one ``soth::HCOD``; a re-solve starts from the active set the last
  call left in its stages (SOTH's warm start).
* ``lexls``: one ``LexLSI``; a re-solve re-applies the last call's working set
  (the inequalities active at a bound, LexLS's warm start).

The state is kept while ``n``, the levels and the kind of every row stay the
same (option ``warm_start="time"``, the default); ``"none"`` starts every solve
from the equalities alone. Free rows and empty levels are not passed to the
peers (they constrain nothing). SOTH's cap (``throw 666`` after 1000
active-set iterations), LexLS's cap on factorizations and any exception come
back as statuses with reasons; so does a NIPM-HLSP level stopped at its cap of
Newton iterations, read from its summed KKT residual. Tolerances and build
flags: docs/peers.md.
"""

from __future__ import annotations

import importlib.machinery
import importlib.util
import json
import os
import sys
import sysconfig
from pathlib import Path

import numpy as np

from hikbench.problems.hierarchy import Hierarchy
from hikbench.solvers.base import ERROR, MAX_ITERATIONS, NUMERICAL_FAILURE, OPTIMAL, Solver, SolveResult
from hikbench.solvers.info import SolverInfo
from hikbench.solvers.options import check_choice, check_int, check_number

__all__ = ["MISSING", "SOLVERS", "LexlsSolver", "NipmSolver", "SothSolver", "build_info", "load_module",
           "peers_dir"]

NOT_BUILT = "not built: run `make peers` (docs/peers.md)"
WARM_STARTS = ("none", "time")
_STATUS = (OPTIMAL, MAX_ITERATIONS, NUMERICAL_FAILURE, ERROR)  # the adapters' codes 0..3
_NAN = float("nan")
_NONE = object()  # (matches no solve() argument)


def peers_dir() -> Path:
    """Where ``make peers`` puts the adapters: ``$HIKBENCH_PEERS_DIR``, else
    ``<environment prefix>/lib/hikbench-peers``."""
    env = os.environ.get("HIKBENCH_PEERS_DIR")
    return Path(env) if env else Path(sys.prefix) / "lib" / "hikbench-peers"


def _module_path(name: str) -> Path:
    return peers_dir() / f"_hik_{name}{sysconfig.get_config_var('EXT_SUFFIX')}"


def load_module(name: str):
    """The built adapter module ``_hik_<name>`` (``soth``, ``lexls`` or ``nipm``), or None when not built."""
    key = f"hikbench_peers._hik_{name}"
    if key in sys.modules:
        return sys.modules[key]
    path = _module_path(name)
    if not path.is_file():
        return None
    loader = importlib.machinery.ExtensionFileLoader(f"_hik_{name}", str(path))
    spec = importlib.util.spec_from_file_location(f"_hik_{name}", path, loader=loader)
    mod = importlib.util.module_from_spec(spec)
    loader.exec_module(mod)
    sys.modules[key] = mod
    return mod


def build_info() -> dict | None:
    """What ``make peers`` recorded (``peers.json``: commits, compiler, flags,
    build time), None when the peers are not built."""
    path = peers_dir() / "peers.json"
    if not path.is_file():
        return None
    return json.loads(path.read_text())


class _PeerSolver(Solver):
    """A peer's adapter object behind the Solver interface (see the module docstring)."""

    supports_inequalities = True
    supports_warm_start = True
    _module = ""

    def __init__(self, warm_start: str):
        self.warm_start = check_choice(self.name, "warm_start", warm_start, WARM_STARTS)
        self._start_from_last = self.warm_start == "time"  # (each solve starts from the last active set)
        self._h = _NONE
        mod = load_module(self._module)
        if mod is None:  # (the registry lists the solver only when built: a stale import of this class)
            raise RuntimeError(f"{self.name}: {NOT_BUILT}")
        self._peer = self._make(mod)

    def _make(self, mod):
        raise NotImplementedError

    def reset(self) -> None:
        """Forget the active set (the next solve is cold)."""
        self._peer.reset()

    def solve(self, hierarchy: Hierarchy) -> SolveResult:
        if hierarchy is not self._h:
            self.check_hierarchy(hierarchy)
            self._peer.load(hierarchy.A, hierarchy.lower, hierarchy.upper, hierarchy.starts)
            self._h = hierarchy
        return self._result(*self._peer.solve(self._start_from_last))

    def _result(self, x, code, act, deact, iters, info, msg) -> SolveResult:
        status = _STATUS[code]
        if status != OPTIMAL:
            x = None
        # (x_finite: the adapter tested every entry of x with isfinite, status 2 otherwise)
        return SolveResult(x, status, msg, iters, (), act, deact, None, _NAN, _NAN, info, True)


class SothSolver(_PeerSolver):
    """SOTH (Escande, Mansard; stack-of-tasks/soth), the HCOD of the ICRA 2010 paper, in C++.

    Parameters
    ----------
    warm_start : {"none", "time"}
        ``time`` (default): a solve starts from the last call's active set while the
        problem keeps its shape; ``none``: from the equalities alone.
    epsilon : float or None
        SOTH's ``Stage::EPSILON`` (absolute): its rank threshold in the
        decompositions, also its threshold on multipliers and bound violations.
        None: SOTH's default, 1e-8. A static of SOTH, set before each solve.
    """

    name = "soth"
    description = "SOTH, the C++ HCOD of Escande-Mansard (stack-of-tasks/soth), built by `make peers`"
    _module = "soth"

    def __init__(self, warm_start: str = "time", epsilon: float | None = None):
        self.epsilon = check_number("soth", "epsilon", epsilon, low=0, high=1, low_open=True, high_open=True,
                                    none_ok=True)
        super().__init__(warm_start)

    def _make(self, mod):
        return mod.Peer(mod.default_epsilon if self.epsilon is None else self.epsilon)

    def solve(self, hierarchy: Hierarchy) -> SolveResult:
        if hierarchy is not self._h:
            self.check_hierarchy(hierarchy)
            self._peer.load(hierarchy.A, hierarchy.lower, hierarchy.upper, hierarchy.starts)
            self._h = hierarchy
        x, code, act, deact, msg = self._peer.solve(self._start_from_last)
        # (SOTH does not report its iterations: 0)
        return self._result(x, code, act, deact, 0, {}, msg)


class LexlsSolver(_PeerSolver):
    """LexLS (Dimitrov, Sherikov, Wieber; jrl-umi3218/lexls), lexicographic least squares, in C++.

    Parameters
    ----------
    warm_start : {"none", "time"}
        ``time`` (default): a solve re-applies the last call's working set while
        the problem keeps its shape; ``none``: starts from the equalities alone.
    tol_linear_dependence : float or None
        LexLS's rank threshold (absolute, on the pivots of its l-QR). None: LexLS's default, 1e-12.
    max_factorizations : int
        LexLS's cap on factorizations (one per active-set iteration); default
        1000 (LexLS's own default, 200, stops some deep inequality stacks).
        Reaching it returns ``max_iterations``.
    """

    name = "lexls"
    description = "LexLS, lexicographic least squares of Dimitrov-Sherikov-Wieber (jrl-umi3218/lexls), " \
                  "built by `make peers`"
    _module = "lexls"

    def __init__(self, warm_start: str = "time", tol_linear_dependence: float | None = None,
                 max_factorizations: int = 1000):
        self.tol_linear_dependence = check_number("lexls", "tol_linear_dependence", tol_linear_dependence, low=0,
                                                  high=1, low_open=True, high_open=True, none_ok=True)
        self.max_factorizations = check_int("lexls", "max_factorizations", max_factorizations)
        super().__init__(warm_start)

    def _make(self, mod):
        tol = mod.default_tol_linear_dependence if self.tol_linear_dependence is None else self.tol_linear_dependence
        return mod.Peer(tol, self.max_factorizations)

    def solve(self, hierarchy: Hierarchy) -> SolveResult:
        if hierarchy is not self._h:
            self.check_hierarchy(hierarchy)
            self._peer.load(hierarchy.A, hierarchy.lower, hierarchy.upper, hierarchy.starts)
            self._h = hierarchy
        x, code, act, deact, facts, cycling, msg = self._peer.solve(self._start_from_last)
        return self._result(x, code, act, deact, facts, {"cycling_counter": cycling} if cycling else {}, msg)


class NipmSolver(_PeerSolver):
    """NIPM-HLSP (Pfeiffer, Escande et al., arXiv 2106.13602; pfeiffer-kai/NIPM-HLSP), in C++.

    A primal-dual interior-point method (Newton's method with Mehrotra's predictor-corrector)
    run on each level in turn, the constraints it finds active on a level kept as equalities
    below. No warm start: every solve builds a new NIPM-HLSP object (cold), so the benchmark
    times it in ``cold`` mode only.

    Parameters
    ----------
    max_iterations : int
        NIPM-HLSP's ``maxIter``: its cap on Newton iterations per level; default 20
        (NIPM-HLSP's own 10 stops some random inequality stacks that 20 solves,
        docs/peers.md). A level stopping at it gives ``max_iterations`` (x kept).
    kkt_tolerance : float or None
        ``KKT_thres``: a level has converged when the norm of its KKT residual is below it.
        None: NIPM-HLSP's default, 1e-12.
    linear_dependence : float or None
        ``linearDependency``: at the pinned commit the floor below which an inequality's
        scaling term ``1 + omega / (w - omega)`` counts as 0 (its QR decompositions use
        Eigen's default rank threshold). None: NIPM-HLSP's default, 1e-12.
    activation_threshold : float or None
        ``activationThres``: the slack / multiplier threshold at which an inequality is
        kept active, as an equality, for the levels below. None: NIPM-HLSP's default, 1e-8.
    """

    name = "nipm-hlsp"
    description = "NIPM-HLSP, the interior-point HLSP solver of Pfeiffer-Escande (pfeiffer-kai/NIPM-HLSP), " \
                  "built by `make peers`"
    supports_warm_start = False
    _module = "nipm"

    def __init__(self, max_iterations: int = 20, kkt_tolerance: float | None = None,
                 linear_dependence: float | None = None, activation_threshold: float | None = None):
        self.max_iterations = check_int("nipm-hlsp", "max_iterations", max_iterations)
        self.kkt_tolerance, self.linear_dependence, self.activation_threshold = (
            check_number("nipm-hlsp", key, value, low=0, high=1, low_open=True, high_open=True, none_ok=True)
            for key, value in (("kkt_tolerance", kkt_tolerance), ("linear_dependence", linear_dependence),
                               ("activation_threshold", activation_threshold)))
        super().__init__("none")

    def _make(self, mod):
        def pick(value, key):
            return getattr(mod, "default_" + key) if value is None else value
        return mod.Peer(self.max_iterations, pick(self.kkt_tolerance, "kkt_tolerance"),
                        pick(self.linear_dependence, "linear_dependence"),
                        pick(self.activation_threshold, "activation_threshold"))

    def reset(self) -> None:
        """Nothing to forget: every solve is cold."""

    def solve(self, hierarchy: Hierarchy) -> SolveResult:
        if hierarchy is not self._h:
            self.check_hierarchy(hierarchy)
            self._peer.load(hierarchy.A, hierarchy.lower, hierarchy.upper, hierarchy.starts)
            self._h = hierarchy
        x, code, iters, kkt, msg = self._peer.solve()
        status = _STATUS[code]
        # (max_iterations keeps x, NIPM-HLSP's last iterate, finite: tested by the adapter)
        return SolveResult(x if status in (OPTIMAL, MAX_ITERATIONS) else None, status, msg, iters, (), 0, 0, None,
                           _NAN, _NAN, {"kkt_residual": kkt}, True)


def _registered() -> tuple[list[SolverInfo], dict[str, str]]:
    solvers, missing = [], {}
    for cls in (SothSolver, LexlsSolver, NipmSolver):
        if _module_path(cls._module).is_file():
            solvers.append(SolverInfo.of(cls))
        else:
            missing[cls.name] = NOT_BUILT
    return solvers, missing


SOLVERS, MISSING = _registered()
