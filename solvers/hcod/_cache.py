"""numba's on-disk cache of hcod's kernels, kept valid for every file they use.

numba (``cache=True``) keeps a compiled function while the source file that
defines it is unchanged (numba's "Notes on caching": changes in symbols
defined in another file are not recognised). hcod's kernels compile in
helpers of five other files (``_linalg``, ``_explicit``, ``_factored``,
``_basis``, ``_setup``): an edit of ``_linalg.py`` alone, or a ``git pull``
that changes only it, left ``_kernel.hcod_solve`` running the old helpers
from its cache -- stale code tested and timed, with nothing to show it (an
A/B timing of a changed ``_explicit.py`` measured the old code twice).

:func:`install` puts a cache locator in front of numba's own ones for the
functions of a package directory: it defers to the locator numba would have
picked (same cache directory and file names; ``NUMBA_CACHE_DIR`` is honoured)
and adds to its source stamp a digest of the function's file and of every
file of the directory it imports, directly or through another
(:func:`sources_digest`), so that a change in any of them compiles that
function again, once. A function can only call what its module imports, so
the digest covers every callee: an edit of ``_kernel.py`` compiles
``hcod_solve`` again (4 min) and loads ``eq_run`` (20 s to compile), whose
files ``_equality.py``, ``_linalg.py`` and ``_cache.py`` are unchanged.
(``NUMBA_CACHE_LOCATOR_CLASSES``, where set, replaces numba's list of
locators and with it this one.) This module installs it for ``solvers/hcod``
when imported; each hcod module that defines cached functions imports it.

:func:`load_kernels` makes a process *load* the kernels from that cache
(they are compiled by a child process when it lacks them), so that every
process runs the same machine code. numba links a function's non-inlined
callees into its own object with ``linkonce_odr`` linkage, and the process's
JIT resolves each such name to the first definition it loaded. A process
that compiles ``hcod_solve`` has loaded each callee's own object first (numba
compiles and loads callees as it types their caller) and runs those; a
process that loads ``hcod_solve`` from the cache runs the copies inside its
object, which LLVM optimised again with the caller (fastmath: other
vectorisation, other rounding). The two gave x differing in up to 260 of
300 entries by 4e-15 of ``|x|`` on IK-like problems, 1.6e-10 of ``|x|`` on
an ill-conditioned one (docs/hcod.md, "The kernels' cache").
Without fastmath LLVM could not change the rounding, but that code took
1.1-2.2x the time.
"""

from __future__ import annotations

import ast
import functools
import hashlib
import os
import subprocess
import sys
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import ClassVar

from numba.core import caching, event

__all__ = ["PACKAGE_DIR", "CacheMiss", "install", "load_kernels", "sources_digest"]

PACKAGE_DIR = Path(__file__).resolve().parent

# numba's class that picks a cached function's locator: CacheImpl in the numba installed here
# (0.68), _CacheImpl in older releases; the first class of its list that applies is used
_IMPL = getattr(caching, "CacheImpl", None) or caching._CacheImpl


@functools.lru_cache(maxsize=64)
def _digest(stats: tuple) -> str:
    h = hashlib.sha256()
    for path, _mtime, _size in stats:
        h.update(Path(path).name.encode())
        h.update(b"\0")
        h.update(Path(path).read_bytes())
    return h.hexdigest()


@functools.lru_cache(maxsize=64)
def _imports(path: str, _mtime: int, _size: int) -> frozenset[str]:
    """The module names that ``path`` imports (``import a.b``, ``from a.b import c``:
    ``a.b`` and ``a.b.c``; ``from .b import c``: ``.b`` and ``.b.c``)."""
    names = set()
    for node in ast.walk(ast.parse(Path(path).read_bytes(), path)):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            head = "." * node.level + (node.module or "")
            names.add(head)
            names.update(f"{head}.{a.name}" if node.module else f"{head}{a.name}" for a in node.names)
    return frozenset(names)


def _closure(module: Path) -> list[Path]:
    """``module`` and the ``*.py`` files of its folder (but ``__init__.py``) that it
    imports, directly or through one another, by ``from .x import``, ``from
    <package>.x import`` or ``from <package> import x``, whatever ``<package>``."""
    here = {p.stem: p for p in module.parent.glob("*.py") if p.name != "__init__.py"}
    found, todo = {module.stem: module}, [module]
    while todo:
        st = (p := todo.pop()).stat()
        for name in _imports(str(p), st.st_mtime_ns, st.st_size):
            stem = name.rsplit(".", 1)[-1]
            if stem in here and stem not in found and "." in name:  # (not a top-level module)
                found[stem] = here[stem]
                todo.append(here[stem])
    return sorted(found.values())


def sources_digest(package_dir: Path, module: Path) -> str:
    """SHA-256 over the names and contents of ``module`` and the files of
    ``package_dir`` it imports (:func:`_closure`; memoised on their mtimes and
    sizes). ``__init__.py`` is left out: it defines no compiled function (a
    test checks it for hcod), and its options and docstrings change more often
    than the kernels, which then took ~90 s to compile again for nothing."""
    files = _closure(Path(package_dir) / Path(module).name)
    return _digest(tuple((str(p), p.stat().st_mtime_ns, p.stat().st_size) for p in files))


class PackageSourcesLocator(caching._CacheLocator):
    """The locator numba would pick for a function of an installed package
    directory, with the :func:`sources_digest` of its file in its stamp."""

    dirs: ClassVar[set[Path]] = set()  #: the package directories installed

    def __init__(self, inner, package_dir: Path, py_file: Path):
        self._inner = inner
        self._dir = package_dir
        self._file = py_file

    def ensure_cache_path(self):
        self._inner.ensure_cache_path()

    def get_cache_path(self):
        return self._inner.get_cache_path()

    def get_source_stamp(self):
        return (self._inner.get_source_stamp(), sources_digest(self._dir, self._file))

    def get_disambiguator(self):
        return self._inner.get_disambiguator()

    @classmethod
    def from_function(cls, py_func, py_file):
        package_dir = Path(py_file).resolve().parent
        if package_dir not in cls.dirs:
            return None
        for other in _IMPL._locator_classes:
            if other is cls:
                continue
            inner = other.from_function(py_func, py_file)
            if inner is not None:
                return cls(inner, package_dir, Path(py_file).resolve())
        return None


def install(package_dir: Path) -> None:
    """Cache stamps of the functions defined in ``package_dir`` from now on
    cover their files and the files there that these import (functions
    decorated before the call are not affected)."""
    PackageSourcesLocator.dirs.add(Path(package_dir).resolve())
    if PackageSourcesLocator not in _IMPL._locator_classes:
        _IMPL._locator_classes.insert(0, PackageSourcesLocator)


install(PACKAGE_DIR)


class CacheMiss(RuntimeError):
    """A function of an installed package directory was about to be compiled
    in a process that must load it from numba's cache (:func:`load_kernels`)."""


class _RefuseCompile(event.Listener):
    """Raises :class:`CacheMiss` when numba starts compiling a function
    defined in ``package_dir`` (its ``numba:compile`` event comes after the
    cache lookup failed and before anything is compiled)."""

    def __init__(self, package_dir: Path):
        self._dir = package_dir

    def on_start(self, ev):
        func = ev.data["dispatcher"].py_func
        if Path(func.__code__.co_filename).resolve().parent == self._dir:
            raise CacheMiss(f"{func.__module__}.{func.__qualname__}{tuple(ev.data['args'])} is not in numba's cache")

    def on_end(self, ev):
        pass


def _run_loading(run: Callable[[], None], package_dir: Path) -> CacheMiss | None:
    """``run()`` with numba's compiler refused for the functions of
    ``package_dir``; the :class:`CacheMiss` that stopped it, or None."""
    try:
        with event.install_listener("numba:compile", _RefuseCompile(package_dir)):
            run()
    except CacheMiss as miss:  # (raised before numba compiled anything)
        return miss
    return None


def load_kernels(run: Callable[[], None], child_code: str, package_dir: Path = PACKAGE_DIR,
                 timeout: float = 1800.0) -> str:
    """Call ``run`` -- the calls that bring the kernels of ``package_dir`` into
    this process, always in the same order -- with every kernel loaded from
    numba's cache, none compiled here (see the module docstring: a process
    that compiles them computes other last bits than one that loads them).

    When a kernel is missing from the cache, ``python -c child_code`` (this
    interpreter, this ``sys.path``, the same environment) compiles them and
    writes the cache, and ``run`` is called again. When the cache still
    lacks one after that (numba could not write it), a RuntimeWarning says
    so and ``run`` compiles them here. Returns how they came:
    ``"loaded"``, ``"compiled by a child process"`` or ``"compiled here"``.
    A child that fails or outlasts ``timeout`` seconds raises RuntimeError
    with its exit status and the end of its stderr."""
    package_dir = Path(package_dir).resolve()
    if _run_loading(run, package_dir) is None:
        return "loaded"
    path = os.pathsep.join(p for p in sys.path if p)
    try:
        child = subprocess.run([sys.executable, "-c", child_code], env={**os.environ, "PYTHONPATH": path},
                               capture_output=True, text=True, timeout=timeout, check=False)
    except subprocess.TimeoutExpired:
        raise RuntimeError(f"compiling the kernels of {package_dir} in a child process took more than "
                           f"{timeout:g} s; it was killed") from None
    if child.returncode != 0:
        raise RuntimeError(f"compiling the kernels of {package_dir} in a child process failed (exit status "
                           f"{child.returncode}):\n{child.stderr[-4000:]}")
    miss = _run_loading(run, package_dir)
    if miss is None:
        return "compiled by a child process"
    warnings.warn(f"{miss} after a child process compiled the kernels of {package_dir} (numba could not write "
                  f"its cache?): compiling them in this process, whose results may differ from those of other "
                  f"processes in the last bits", RuntimeWarning, stacklevel=2)
    run()
    return "compiled here"
