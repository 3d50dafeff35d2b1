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
* ``OUT/yardstick/<problem_hash>.npz`` holds ``x``, ``status``, ``reason``,
  ``kind`` (certified, reference-only, none), ``kind_reason``,
  ``certify_budget``, ``problem_hash`` and ``code``: a file that cannot be
  read, holds a yardstick of another size, of another problem or of other
  code is computed again (hikbench.bench.harness.runner).
"""

from __future__ import annotations

import hashlib
import importlib.util
import sys
import zipfile
from pathlib import Path

import numpy as np

from hikbench.bench.harness.regular import open_regular
from hikbench.problems.errors import HikbenchError
from hikbench.problems.files import check_zip_members
from hikbench.problems.hierarchy import Hierarchy

__all__ = ["CERTIFIED", "NO_YARDSTICK", "REFERENCE_ONLY", "YARDSTICK_MODULES", "load_yardstick", "problem_hash", "save_yardstick", "yardstick_code",
           "yardstick_path"]

#: the modules whose source computes a yardstick (the worker's yardstick job calls them); a module
#: added to that computation is added here, so that a change in it recomputes the cached yardsticks
#: (the worker's certify job decides that a certified yardstick is the certificate's x*)
YARDSTICK_MODULES: tuple[str, ...] = ("hikbench.solvers.yardstick", "hikbench.problems.exact",
                                      "hikbench.bench.harness.worker")
#: what a row's yardstick is (column ``yardstick``): certified by the exact certificate, a
#: reference point the certificate did not accept (or did not reach in its budget), none at all
CERTIFIED, REFERENCE_ONLY, NO_YARDSTICK = "certified", "reference-only", "none"
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


def yardstick_path(out: Path, phash: str) -> Path:
    """``OUT/yardstick/<problem_hash>.npz``."""
    return Path(out) / "yardstick" / f"{phash}.npz"


def load_yardstick(path: Path, n: int):
    """``((x or None, status, reason, kind, kind_reason, certify_budget), (problem_hash, code))``
    cached in ``path``, or None, said on stderr in one line naming the file, when it
    cannot be read or holds no yardstick of ``n`` variables (a damaged file:
    the caller computes it again, as it does for a key other than its own). A file
    without ``kind`` (written before yardsticks were certified) has the code ``""``."""
    try:
        with open_regular(path) as f:  # (a FIFO is not waited on, a folder not read)
            with zipfile.ZipFile(f) as zf:  # (no member encrypted, compressed otherwise, or larger than x)
                check_zip_members(path, zf, 8 * int(n) + _MEMBER_BYTES)
            f.seek(0)
            with np.load(f, allow_pickle=False) as z:
                x, status, reason = z["x"], str(z["status"]), str(z["reason"])
                key = (str(z["problem_hash"]), str(z["code"]) if "kind" in z.files else "")
                kind = (str(z["kind"]), str(z["kind_reason"]), float(z["certify_budget"])) if "kind" in z.files \
                    else (NO_YARDSTICK, "", 0.0)
        if x.dtype.kind != "f" or x.shape not in ((0,), (n,)):
            raise ValueError(f"x of dtype {x.dtype} and shape {x.shape}: expected float64 of shape ({n},)")
        if kind[0] not in (CERTIFIED, REFERENCE_ONLY, NO_YARDSTICK):
            raise ValueError(f"kind {kind[0]!r}: expected {CERTIFIED}, {REFERENCE_ONLY} or {NO_YARDSTICK}")
    except (OSError, EOFError, KeyError, ValueError, zipfile.BadZipFile, HikbenchError) as err:
        print(f"hikbench run: {path} cannot be read ({type(err).__name__}: {' '.join(str(err).split())}); "
              f"computing the yardstick again", file=sys.stderr)
        return None
    return ((x if x.size else None), status, reason, *kind), key


_MEMBER_BYTES = 1 << 16  # of a cached yardstick's member beyond 8 bytes a variable (its header, a reason)


def save_yardstick(path: Path, ref: tuple, phash: str, code: str) -> None:
    """Write the yardstick ``ref`` (x, status, reason, kind, kind_reason, certify_budget) of
    the problem ``phash`` computed by yardstick code ``code`` (atomically); certify_budget > 0:
    its certification stopped at that budget (a run with a larger one tries again)."""
    x, status, reason, kind, kind_reason, budget = ref
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    with open(tmp, "wb") as f:
        np.savez(f, x=np.zeros(0) if x is None else np.asarray(x, float), status=status, reason=reason,
                 kind=kind, kind_reason=kind_reason, certify_budget=float(budget), problem_hash=phash, code=code)
    tmp.replace(path)
