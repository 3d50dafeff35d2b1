"""numba's on-disk cache of hcod's kernels follows every hcod source file
(solvers/hcod/_cache.py): a kernel whose helper changed in another file is
compiled again, not loaded with the old helper inside; kernels are compiled by a
child process and loaded from the cache, so that every process computes the same
bits. docs/hcod.md, "Compiled kernels and numba's cache"."""

from __future__ import annotations

import importlib
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from hcod_checks import DATA
from numba.core.registry import CPUDispatcher

from hikbench.problems import generators as G  # noqa: F401 (in _BITS_PROBLEMS, evaluated)
from hikbench.problems.files import load_npz  # noqa: F401 (in _BITS_PROBLEMS, evaluated)
from hikbench.solvers.hcod import HcodSolver
from hikbench.solvers.hcod._cache import PACKAGE_DIR, PackageSourcesLocator, _closure, sources_digest

HCOD_MODULES = ["_basis", "_equality", "_explicit", "_factored", "_iterations", "_kernel", "_linalg",
                "_multipliers", "_rows", "_setup", "_warm", "_workspace"]
ROOT = Path(__file__).resolve().parents[3]


def _dispatchers(module_name: str):
    module = importlib.import_module(f"hikbench.solvers.hcod.{module_name}")
    return [(name, obj) for name, obj in vars(module).items()
            if isinstance(obj, CPUDispatcher) and obj.py_func.__module__ == module.__name__]


@pytest.mark.parametrize("module_name", HCOD_MODULES)
def test_every_cached_kernel_is_stamped_by_its_file_and_the_files_it_imports(module_name):
    found = _dispatchers(module_name)
    assert found, f"no compiled function found in hikbench.solvers.hcod.{module_name}"
    for name, d in found:
        cache = d._cache  # numba's FunctionCache (a NullCache without cache=True)
        locator = getattr(getattr(cache, "_impl", None), "locator", None)
        assert isinstance(locator, PackageSourcesLocator), f"{module_name}.{name}: locator {locator!r}"
        _inner, digest = locator.get_source_stamp()
        assert digest == sources_digest(PACKAGE_DIR, PACKAGE_DIR / f"{module_name}.py")


@pytest.mark.parametrize("module_name, imported", [
    ("_equality", ["_cache", "_equality", "_linalg"]),
    ("_kernel", ["_basis", "_cache", "_explicit", "_factored", "_iterations", "_kernel", "_layout", "_linalg",
                 "_multipliers", "_rows", "_setup", "_warm", "_workspace"]),
], ids=["equality", "kernel"])
def test_a_kernels_stamp_covers_the_files_its_module_imports(module_name, imported):
    """eq_run's stamp leaves out _kernel.py (an edit there does not compile it again);
    hcod_solve's covers every file it imports, through `from .x`, `from <package>.x`
    and `from <package> import x` alike."""
    assert [p.stem for p in _closure(PACKAGE_DIR / f"{module_name}.py")] == imported


def test_the_package_init_defines_no_compiled_function():
    """sources_digest leaves __init__.py out: nothing compiled may live there."""
    import hikbench.solvers.hcod as package

    assert not [name for name, obj in vars(package).items()  # (_eq_run: _equality's, bound here)
                if isinstance(obj, CPUDispatcher) and obj.py_func.__module__ == package.__name__]
    assert "@njit" not in (PACKAGE_DIR / "__init__.py").read_text()


def test_the_digest_follows_the_content_of_every_file(tmp_path):
    (tmp_path / "a.py").write_text("from .b import x\n")
    (tmp_path / "b.py").write_text("x = 1\n")
    before = sources_digest(tmp_path, tmp_path / "a.py")
    assert sources_digest(tmp_path, tmp_path / "a.py") == before
    (tmp_path / "b.py").write_text("x = 2\n")
    changed = sources_digest(tmp_path, tmp_path / "a.py")
    assert changed != before
    (tmp_path / "c.txt").write_text("not python")  # only the *.py files count
    (tmp_path / "__init__.py").write_text('"""a docstring"""\n')  # and not __init__.py
    assert sources_digest(tmp_path, tmp_path / "a.py") == changed


def test_a_modules_digest_follows_the_files_it_imports_alone(tmp_path):
    (tmp_path / "a.py").write_text("from .b import y\n")
    (tmp_path / "b.py").write_text("from pkg.c import z\n")
    (tmp_path / "c.py").write_text("z = 1\n")
    (tmp_path / "d.py").write_text("w = 1\n")
    before = sources_digest(tmp_path, tmp_path / "a.py")
    (tmp_path / "d.py").write_text("w = 2\n")  # (not imported by a)
    assert sources_digest(tmp_path, tmp_path / "a.py") == before
    (tmp_path / "c.py").write_text("z = 2\n")  # (imported by b, which a imports)
    assert sources_digest(tmp_path, tmp_path / "a.py") != before


_HELPER = """
from numba import njit

@njit(cache=True)
def value():
    return {v}
"""
_MAIN = """
from numba import njit

from pkg.helper import value

@njit(cache=True)
def f():
    return value() + 10
"""
_RUN = """
import sys
from pathlib import Path
sys.path.insert(0, {root!r})
sys.path.insert(0, {tmp!r})
if {install}:
    from hikbench.solvers.hcod._cache import install
    install(Path({tmp!r}) / "pkg")
import pkg.main
v = pkg.main.f()
print(sum(pkg.main.f.stats.cache_hits.values()), v)
"""


def _package(tmp: Path) -> Path:
    pkg = tmp / "pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "helper.py").write_text(textwrap.dedent(_HELPER.format(v=1)))
    (pkg / "main.py").write_text(textwrap.dedent(_MAIN))
    return pkg


def _run(tmp: Path, install: bool, hits: bool = False) -> int | tuple[int, int]:
    """``pkg.main.f()`` in a new process; with ``hits``, (numba's cache hits of f, f())."""
    code = _RUN.format(root=str(ROOT), tmp=str(tmp), install=install)
    out = subprocess.run([sys.executable, "-c", code], check=False, capture_output=True, text=True, timeout=300,
                         env={"PATH": "/usr/bin:/bin", "NUMBA_CACHE_DIR": ""})
    assert out.returncode == 0, out.stderr
    got = tuple(int(w) for w in out.stdout.split()[-2:])
    return got if hits else got[1]


@pytest.mark.parametrize("install", [True, False], ids=["installed", "numba-alone"])
def test_a_change_in_a_helper_file_recompiles_its_caller(tmp_path, install):
    """``main.f`` (cached) calls ``helper.value`` from another file. After
    ``value`` changes, numba alone loads ``f`` from its cache with the old
    ``value`` inside (its documented limitation: the case this locator
    exists for; should numba lift it, the second case fails and the locator
    can go); with the package installed, ``f`` is compiled again."""
    pkg = _package(tmp_path)
    assert _run(tmp_path, install) == 11
    assert _run(tmp_path, install) == 11  # (from the cache)
    assert list((pkg / "__pycache__").glob("main.f-*.nbi")), "f was not cached"
    (pkg / "helper.py").write_text(textwrap.dedent(_HELPER.format(v=2)))
    assert _run(tmp_path, install) == (12 if install else 11)


def test_a_change_in_a_file_the_caller_does_not_import_keeps_it_cached(tmp_path):
    """An edit of ``other.py``, which ``main`` does not import, leaves ``f`` loaded
    from the cache; an edit of ``helper.py``, which it imports, compiles it again."""
    pkg = _package(tmp_path)
    (pkg / "other.py").write_text("w = 1\n")
    assert _run(tmp_path, True, hits=True) == (0, 11)
    (pkg / "other.py").write_text("w = 2\n")
    assert _run(tmp_path, True, hits=True) == (1, 11)
    (pkg / "helper.py").write_text(textwrap.dedent(_HELPER.format(v=2)))
    assert _run(tmp_path, True, hits=True) == (0, 12)


_LOAD = """
import sys, warnings
from pathlib import Path
sys.path.insert(0, {root!r})
sys.path.insert(0, {tmp!r})
warnings.simplefilter("error")  # (a RuntimeWarning of load_kernels fails the run unless expected)
if {expect_warning}:
    warnings.simplefilter("always")
from hikbench.solvers.hcod._cache import install, load_kernels
install(Path({tmp!r}) / "pkg")
import pkg.main
how = load_kernels(pkg.main.f, {child!r}, Path({tmp!r}) / "pkg")
print(how, "|", sum(pkg.main.f.stats.cache_hits.values()), "|", pkg.main.f())
"""


def _load(tmp: Path, child: str, expect_warning: bool = False) -> tuple[list[str], str]:
    code = _LOAD.format(root=str(ROOT), tmp=str(tmp), child=child, expect_warning=expect_warning)
    out = subprocess.run([sys.executable, "-c", code], check=False, capture_output=True, text=True, timeout=300,
                         env={"PATH": "/usr/bin:/bin", "NUMBA_CACHE_DIR": ""}, cwd=tmp)
    assert out.returncode == 0, out.stderr
    return [w.strip() for w in out.stdout.strip().splitlines()[-1].split("|")], out.stderr


@pytest.mark.parametrize("helper_first", [False, True], ids=["fresh", "helper-cached"])
def test_load_kernels_compiles_in_a_child_and_loads(tmp_path, helper_first):
    """A process whose cache lacks the kernels has a child compile them and
    loads them from the cache (numba counts a cache hit); the next process
    loads them at once. Nothing of the package is compiled in either."""
    pkg = _package(tmp_path)
    if helper_first:  # the helper alone in the cache: f still has to be compiled (by the child)
        assert _run(tmp_path, install=True) == 11
        for f in (pkg / "__pycache__").glob("main.f-*"):
            f.unlink()
    child = (f"from pathlib import Path; from hikbench.solvers.hcod._cache import install; install(Path({str(pkg)!r})); "
             f"import pkg.main; pkg.main.f()")  # (its sys.path: the parent's)
    how, stderr = _load(tmp_path, child)
    assert how == ["compiled by a child process", "1", "11"], stderr
    how, stderr = _load(tmp_path, "raise SystemExit('the child must not run')")
    assert how == ["loaded", "1", "11"], stderr


def test_load_kernels_says_when_it_compiles_here(tmp_path):
    """A child that leaves the cache without the kernels (here: it compiles
    nothing) makes a RuntimeWarning, and the kernels are compiled here."""
    _package(tmp_path)
    how, stderr = _load(tmp_path, "pass", expect_warning=True)
    assert how == ["compiled here", "0", "11"]
    assert "RuntimeWarning" in stderr and "compiling them in this process" in stderr


def test_load_kernels_reports_a_failing_child(tmp_path):
    _package(tmp_path)
    code = _LOAD.format(root=str(ROOT), tmp=str(tmp_path), child="import sys; sys.exit('no compiler today')",
                        expect_warning=False)
    out = subprocess.run([sys.executable, "-c", code], check=False, capture_output=True, text=True, timeout=300,
                         env={"PATH": "/usr/bin:/bin", "NUMBA_CACHE_DIR": ""}, cwd=tmp_path)
    assert out.returncode != 0
    assert "failed (exit status 1)" in out.stderr and "no compiler today" in out.stderr


def test_load_kernels_stops_a_child_past_its_timeout(tmp_path):
    pkg = _package(tmp_path)
    code = (f"import sys; sys.path[:0] = [{str(ROOT)!r}, {str(tmp_path)!r}]\n"
            f"from pathlib import Path\nfrom hikbench.solvers.hcod._cache import install, load_kernels\n"
            f"install(Path({str(pkg)!r}))\nimport pkg.main\n"
            f"load_kernels(pkg.main.f, 'import time; time.sleep(60)', Path({str(pkg)!r}), timeout=2)\n")
    out = subprocess.run([sys.executable, "-c", code], check=False, capture_output=True, text=True, timeout=300,
                         env={"PATH": "/usr/bin:/bin", "NUMBA_CACHE_DIR": ""}, cwd=tmp_path)
    assert out.returncode != 0
    assert "took more than 2 s; it was killed" in out.stderr, out.stderr


# the problems of test_every_process_computes_the_same_bits, built in this process and in another
_BITS_PROBLEMS = ("[G.ik_like(n, s) for n in (20, 80) for s in range(3)]"
                  " + [G.equality_stack(120, 8, 12, seed=s) for s in range(2)]"
                  " + [load_npz(DATA / 'step_out_and_back.npz')]")
_BITS_RUN = """
import sys
from pathlib import Path
import numpy as np
sys.path.insert(0, {root!r})
from hikbench.problems import generators as G  # noqa: F401 (in _BITS_PROBLEMS, evaluated)
from hikbench.problems.files import load_npz  # noqa: F401 (in _BITS_PROBLEMS, evaluated)
from hikbench.solvers.hcod import WARM_STARTS, HcodSolver
DATA = Path({data!r})
np.save({out!r}, np.concatenate([HcodSolver(warm_start="none").solve(h).x for h in {problems}]))
"""


def test_every_process_computes_the_same_bits(tmp_path):
    """x to the last bit in this process and in a new one (both load the
    kernels from numba's cache: hikbench.solvers.hcod._cache.load_kernels). A
    process that compiled them would run each non-inlined helper's own object,
    one that loaded them the copies inside the kernel's: x would differ in up
    to 260 of 300 entries by 4e-15 of |x| on these IK-like problems, by 1.6e-10
    of |x| on step_out_and_back (a test passing in one kind of process and
    failing in the other). docs/hcod.md, "Compiled kernels and numba's cache"."""
    import subprocess
    import sys

    here = np.concatenate([HcodSolver(warm_start="none").solve(h).x for h in eval(_BITS_PROBLEMS)])
    out = tmp_path / "x.npy"
    code = _BITS_RUN.format(root=str(Path(__file__).resolve().parents[3]), data=str(DATA), out=str(out),
                            problems=_BITS_PROBLEMS)
    run = subprocess.run([sys.executable, "-c", code], check=False, capture_output=True, text=True, timeout=900)
    assert run.returncode == 0, run.stderr
    there = np.load(out)
    assert here.shape == there.shape == (3 * 20 + 3 * 80 + 2 * 120 + 57,)
    differ = np.flatnonzero(here != there)
    assert differ.size == 0, (f"{differ.size} entries differ, up to {np.max(np.abs(here - there)):.3g}: "
                              f"first at {differ[:5]}")
