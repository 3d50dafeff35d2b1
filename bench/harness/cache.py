"""Content keys of a run's cached files (docs/running.md, "Cached problems and yardsticks").

* :func:`problem_hash`: the problem's identity by content, the first 16 hex
  digits of the SHA-256 of its arrays in a fixed layout
  (``hikbench-problem-v1``, then ``n``, ``depth``, ``rows`` as little-endian
  int64, ``A`` row-major, ``lower``, ``upper`` as little-endian float64,
  ``level`` as little-endian int64). The same arrays give the same hash on any
  machine; a family whose parameters or code changed gives another one.
* :func:`yardstick_code`: the version of the yardstick's code, the first 16
  hex digits of the SHA-256 of the source files of :data:`YARDSTICK_MODULES`
  (the modules that compute a yardstick's x). Any edit of them, a comment
  included, makes every cached yardstick be computed again: a change that
  alters the yardstick cannot be forgotten, as a constant to bump could be.
* ``OUT/yardstick/<problem_hash>.npz``, the cached yardstick of that problem by that
  code: hikbench.bench.harness.yardstick.
"""

from __future__ import annotations

import hashlib
import importlib.util
from pathlib import Path

import numpy as np

from hikbench.problems.hierarchy import Hierarchy

__all__ = ["YARDSTICK_MODULES", "problem_hash", "yardstick_code"]

#: the modules whose source computes a yardstick (the worker's yardstick job calls them); a module
#: added to that computation is added here, so that a change in it recomputes the cached yardsticks
#: (the worker's certify job decides that a certified yardstick is the certificate's x*; harness.yardstick
#: chooses among the candidate points)
YARDSTICK_MODULES: tuple[str, ...] = ("hikbench.solvers.yardstick", "hikbench.problems.exact",
                                      "hikbench.bench.harness.worker", "hikbench.bench.harness.yardstick")
_DIGITS = 16  # hex digits kept of a SHA-256: 64 bits, no collision in any realistic set of problems


def problem_hash(h: Hierarchy) -> str:
    """16 hex digits of the SHA-256 of ``h``'s arrays (A: rows x n, lower,
    upper: (rows,), level: (rows,), n, depth) in the fixed layout of the
    module docstring; names and x0 are not part of it."""
    d = hashlib.sha256(b"hikbench-problem-v1")
    d.update(np.array([h.n, h.depth, h.A.shape[0]], dtype="<i8").tobytes())
    for a, dtype in ((h.A, "<f8"), (h.lower, "<f8"), (h.upper, "<f8"), (h.level, "<i8")):
        d.update(np.ascontiguousarray(a, dtype=dtype).tobytes())
    return d.hexdigest()[:_DIGITS]


def _sources(module: str) -> list[Path]:
    """The source files of ``module`` (every ``.py`` below a package), sorted, without importing it."""
    spec = importlib.util.find_spec(module)
    if spec is None or spec.origin is None:
        raise ModuleNotFoundError(f"yardstick module {module!r} not found (hikbench.bench.harness.cache."
                                  f"YARDSTICK_MODULES)", name=module)
    if spec.submodule_search_locations:
        return sorted(p for d in spec.submodule_search_locations for p in Path(d).rglob("*.py"))
    return [Path(spec.origin)]


def yardstick_code(modules: tuple[str, ...] = YARDSTICK_MODULES) -> str:
    """16 hex digits of the SHA-256 of the source files of ``modules`` (names and bytes, in order)."""
    d = hashlib.sha256(b"hikbench-yardstick-v1")
    for m in modules:
        for p in _sources(m):
            d.update(f"{m}:{p.name}:".encode())
            d.update(p.read_bytes())
    return d.hexdigest()[:_DIGITS]
