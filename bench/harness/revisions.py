"""A base revision of the project, installed beside the working one, for
``hikbench regress``: the revision's tree is taken from git (``git archive``),
built and installed into a folder of its own (``pip install --target``,
no dependencies: it runs on the environment's installed ones), and its
``hikbench`` commands are run with that folder first on ``PYTHONPATH``.

hcod's numba kernels are cached next to their sources; the working tree's cache
is copied into the base's install, with the modification times (which numba's
index checks) of the hcod files that are the same on both sides, so the base
compiles only the kernels whose files differ.
"""

from __future__ import annotations

import io
import os
import shutil
import subprocess
import sys
import tarfile
from dataclasses import dataclass
from pathlib import Path

from hikbench.problems.errors import HikbenchError

__all__ = ["RevisionError", "Side", "install_revision", "working_side", "resolve_revision"]

#: BLAS/OpenMP thread counts pinned to 1 for timing (both sides)
_THREADS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS")


class RevisionError(HikbenchError):
    """The base revision cannot be found, installed or run (exit 2)."""


@dataclass(frozen=True)
class Side:
    """How to run one side's ``hikbench``: ``argv`` prefix, environment, working directory."""

    name: str
    label: str
    argv: tuple[str, ...]
    env: dict
    cwd: Path
    path_first: tuple[str, ...] = ()  # (folders first on PYTHONPATH: the base's install)

    def command(self, *args: str) -> list[str]:
        return [*self.argv, *args]


def _git(repo: Path, *args: str, binary: bool = False):
    try:
        done = subprocess.run(["git", "-C", str(repo), *args], capture_output=True, check=False)
    except FileNotFoundError:
        raise RevisionError("git is not installed: `hikbench regress` takes the base revision from git") from None
    if done.returncode:
        raise RevisionError(_last_line(done.stderr) or f"git {' '.join(args)} failed (exit {done.returncode})")
    return done.stdout if binary else done.stdout.decode().strip()


def _last_line(raw: bytes) -> str:
    lines = [ln.strip() for ln in raw.decode(errors="replace").splitlines() if ln.strip()]
    return lines[-1] if lines else ""


def resolve_revision(repo: Path, rev: str) -> str:
    """The commit id of ``rev`` in the git repository holding ``repo``."""
    try:
        _git(repo, "rev-parse", "--show-toplevel")
    except RevisionError as err:
        raise RevisionError(f"{repo} is not in a git repository ({err}): run `hikbench regress` "
                            f"from a clone of the project") from None
    try:
        return _git(repo, "rev-parse", "--verify", "--quiet", f"{rev}^{{commit}}")
    except RevisionError:
        raise RevisionError(f"--base {rev!r} is not a revision of the repository at {repo} "
                            f"(a branch, tag or commit, e.g. HEAD~1 or main)") from None


def _thread_env(env: dict) -> dict:
    return env | {k: "1" for k in _THREADS}


def working_side(work: Path) -> Side:
    """The installed ``hikbench`` (the working tree), run from ``work`` so that no
    folder of the current directory shadows it."""
    env = _thread_env({k: v for k, v in os.environ.items() if k != "PYTHONPATH"})
    return Side("change", "working tree", (sys.executable, "-P", "-m", "hikbench"), env, work)


def install_revision(repo: Path, rev: str, work: Path, progress=print) -> Side:
    """Install revision ``rev`` into ``work/<commit>/site`` (reused when already
    there) and return how to run it. Raises RevisionError (one line) when the
    revision does not exist, does not install or does not import from there."""
    sha = resolve_revision(repo, rev)
    home = work / sha[:12]
    site = home / "site"
    label = f"{rev} ({sha[:10]})"
    if not (home / "installed").exists():
        shutil.rmtree(home, ignore_errors=True)
        src = home / "src"
        src.mkdir(parents=True)
        with tarfile.open(fileobj=io.BytesIO(_git(repo, "archive", "--format=tar", sha, binary=True))) as tar:
            tar.extractall(src, filter="data")
        if not (src / "pyproject.toml").exists():
            raise RevisionError(f"base revision {label} has no pyproject.toml: it is not an installable "
                                f"revision of hikbench")
        progress(f"hikbench regress: installing base revision {label} into {site}")
        done = subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps",
                               "--no-build-isolation", "--target", str(site), str(src)],
                              capture_output=True, check=False, cwd=home)
        if done.returncode:
            raise RevisionError(f"base revision {label} does not install: {_last_line(done.stderr)}")
        (home / "installed").write_text(sha + "\n")
    env = _thread_env(os.environ | {"PYTHONPATH": os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")])
                                                  .rstrip(os.pathsep)})
    side = Side("base", label, (sys.executable, "-P", "-m", "hikbench"), env, home, (str(site),))
    where = subprocess.run(side.command("--version"), env=env, cwd=home, capture_output=True, check=False)
    probe = subprocess.run([sys.executable, "-P", "-c", "import hikbench; print(hikbench.__file__)"],
                           env=env, cwd=home, capture_output=True, check=False)
    if where.returncode or probe.returncode or not probe.stdout.decode().strip().startswith(str(site)):
        raise RevisionError(f"base revision {label} does not run from {site}: "
                            f"{_last_line(where.stderr or probe.stderr) or probe.stdout.decode().strip()}")
    same = share_numba_cache(site)
    if same:
        progress(f"hikbench regress: base {label} has {len(same)} of the working tree's hcod kernel source files "
                 f"({', '.join(same)}): the kernels compiled from these alone are shared")
    return side


def _hcod_dir(root: Path) -> Path:
    return root / "hikbench" / "solvers" / "hcod"


def share_numba_cache(site: Path) -> list[str]:
    """Copy the working tree's compiled hcod kernels into the base's install and give
    the base's hcod source files that are the working tree's byte for byte the
    working tree's modification times (numba's index checks them); the names of
    those files. hcod's cache locator (``solvers/hcod/_cache.py``) stamps each
    cached kernel with a digest of its file and of the files it imports, so the
    base loads a kernel whose files are all the same on both sides and compiles
    any other; ``__init__.py`` defines no kernel and does not count."""
    from hikbench.solvers import hcod

    mine, theirs = Path(hcod.__file__).parent, _hcod_dir(site)
    cache = sorted((mine / "__pycache__").glob("*.nb[ic]"))
    if not theirs.is_dir() or not cache:
        return []
    same = sorted(p.name for p in mine.glob("*.py") if p.name != "__init__.py"
                  and (theirs / p.name).is_file() and (theirs / p.name).read_bytes() == p.read_bytes())
    if not same:
        return []
    (theirs / "__pycache__").mkdir(exist_ok=True)
    for f in cache:
        shutil.copy2(f, theirs / "__pycache__" / f.name)
    for f in same:
        st = (mine / f).stat()
        os.utime(theirs / f, ns=(st.st_atime_ns, st.st_mtime_ns))
    return same
