"""numba's on-disk cache of hcod's kernels, kept valid for every file they use.

numba (``cache=True``) keeps a compiled function while the source file that
defines it is unchanged (numba's "Notes on caching": changes in symbols
defined in another file are not recognised). hcod's kernels compile in
helpers of five other files (``_linalg``, ``_explicit``, ``_factored``,
``_basis``, ``_setup``): an edit of ``_linalg.py`` alone, or a ``git pull``
that changes only it, left ``_kernel.hcod_solve`` running the old helpers
from its cache -- stale code tested and timed, with nothing to show it (seen
in the forty-fourth session: an A/B timing of a changed ``_explicit.py``
measured the old code twice).

:func:`install` puts a cache locator in front of numba's own ones for the
functions of a package directory: it defers to the locator numba would have
picked (same cache directory and file names; ``NUMBA_CACHE_DIR`` is honoured)
and adds to its source stamp a digest of every ``*.py`` file of the
directory but ``__init__.py`` (:func:`sources_digest`), so that a change in
any of them compiles all its cached functions again, once.
(``NUMBA_CACHE_LOCATOR_CLASSES``, where set, replaces numba's list of
locators and with it this one.) This module installs it for ``solvers/hcod``
when imported; each hcod module that defines cached functions imports it.
"""

from __future__ import annotations

import functools
import hashlib
from pathlib import Path
from typing import ClassVar

from numba.core import caching

__all__ = ["PACKAGE_DIR", "install", "sources_digest"]

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


def sources_digest(package_dir: Path) -> str:
    """SHA-256 over the names and contents of the ``*.py`` files of
    ``package_dir`` but ``__init__.py`` (memoised on their mtimes and sizes).
    ``__init__.py`` is left out: it defines no compiled function (a test
    checks it for hcod), and its options and docstrings change more often
    than the kernels, which then took ~90 s to compile again for nothing."""
    files = sorted(p for p in Path(package_dir).glob("*.py") if p.name != "__init__.py")
    return _digest(tuple((str(p), p.stat().st_mtime_ns, p.stat().st_size) for p in files))


class PackageSourcesLocator(caching._CacheLocator):
    """The locator numba would pick for a function of an installed package
    directory, with that directory's :func:`sources_digest` in its stamp."""

    dirs: ClassVar[set[Path]] = set()  #: the package directories installed

    def __init__(self, inner, package_dir: Path):
        self._inner = inner
        self._dir = package_dir

    def ensure_cache_path(self):
        self._inner.ensure_cache_path()

    def get_cache_path(self):
        return self._inner.get_cache_path()

    def get_source_stamp(self):
        return (self._inner.get_source_stamp(), sources_digest(self._dir))

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
                return cls(inner, package_dir)
        return None


def install(package_dir: Path) -> None:
    """Cache stamps of the functions defined in ``package_dir`` from now on
    cover every ``*.py`` file there (functions decorated before the call are
    not affected)."""
    PackageSourcesLocator.dirs.add(Path(package_dir).resolve())
    if PackageSourcesLocator not in _IMPL._locator_classes:
        _IMPL._locator_classes.insert(0, PackageSourcesLocator)


install(PACKAGE_DIR)
