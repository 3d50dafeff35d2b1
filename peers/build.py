"""Build the C++ peers SOTH, LexLS and NIPM-HLSP and hikbench's adapters to them (``make peers``).

    python peers/build.py [--src DIR] [--out DIR] [--march-native] [--jobs N]

Sources: ``--src`` (``make peers PEERS_SRC=DIR``), a folder holding the pinned
tarballs ``soth-d2485f4.tar.gz``, ``lexls-f13b6b6.tar.gz`` and
``nipm-hlsp-05d618d.tar.gz``; without it, a shallow clone of the public
repositories at the pinned commits (needs git and the network). Headers: Eigen
(cmeel-eigen), Boost (cmeel-boost) and pybind11 from PyPI (``pip install
'hikbench[peers]'``); the system C++ compiler (``$CXX``, else ``c++``). Output:
three Python extension modules, ``_hik_soth``, ``_hik_lexls`` and ``_hik_nipm``,
and ``peers.json`` (commits, compiler, flags, build time) in
``--out``, by default the folder :func:`hikbench.solvers.peers.peers_dir` reads
(``<environment>/lib/hikbench-peers``, or ``$HIKBENCH_PEERS_DIR``).

How each peer is built (docs/peers.md):

* SOTH: the library sources of its ``src/CMakeLists.txt`` (its CMake needs the
  jrl-cmakemodules submodule, which the pinned snapshot lacks) compiled directly,
  its debug/trace mode compiled out: the ``#define SOTH_DEBUG`` and
  ``#define SOTH_DEBUG_MODE`` lines at the top of four sources are dropped from
  the extracted copy, ``-DNDEBUG`` is added, and every source's preprocessed
  macros are checked before compiling (neither ``SOTH_DEBUG`` defined nor
  ``NDEBUG`` missing). ``Random.cpp`` (its unit tests' generator) is not built.
* LexLS: header-only; its cap on factorizations is a run-time parameter, which
  the adapter raises (``max_factorizations``, default 1000 where LexLS says 200).
* NIPM-HLSP: the sources ``nipm_hlsp/*.cpp`` compiled directly (its CMake only
  globs them). Its options are ``const`` members with in-class defaults in
  ``nipm_hlsp/options.h``; the extracted copy's initialisers of the four the
  adapter exposes (:data:`NIPM_OPTIONS`) are made to read a settings struct
  (:data:`NIPM_SETTINGS`, holding NIPM-HLSP's own defaults, parsed from that
  file) that the adapter sets before each solve. Two fixes of its memory
  handling are applied to the extracted copy (:data:`NIPM_FIXES`; its
  arithmetic is not touched): left as they are, every solve leaks its whole
  problem and workspace (3 to 7 MB on the peers suite's problems). The build
  stops if any of these lines is not found exactly once.

A missing compiler, source folder or header package is one line saying what to
do, exit status 2.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import shutil
import subprocess
import sys
import sysconfig
import tarfile
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

HERE = Path(__file__).resolve().parent
# name -> (public repository, pinned commit, tarball in PEERS_SRC, its top folder)
PINNED = {
    "soth": ("https://github.com/stack-of-tasks/soth", "d2485f4a29d2af65e4badd72b5a2fe7ae30792fc",
             "soth-d2485f4.tar.gz", "soth"),
    "lexls": ("https://github.com/jrl-umi3218/lexls", "f13b6b668146aabbf838b1e2fc3fe9b65d752db5",
              "lexls-f13b6b6.tar.gz", "lexls"),
    "nipm-hlsp": ("https://github.com/pfeiffer-kai/NIPM-HLSP", "05d618d478662939c143ee453eaabd6d562bffcc",
                  "nipm-hlsp-05d618d.tar.gz", "nipm-hlsp-05d618d"),
}
#: SOTH's library sources (its src/CMakeLists.txt), Random.cpp (unit tests only) left out
SOTH_SOURCES = ("Allocator.cpp", "Algebra.cpp", "Bound.cpp", "BaseY.cpp", "HCOD.cpp", "Givens.cpp", "debug.cpp",
                "Stage.cpp", "BasicStage.cpp")
#: the lines switching SOTH's debug/trace mode on, at the top of HCOD.cpp, Stage.cpp, BasicStage.cpp, Random.cpp
SOTH_DEBUG_LINE = re.compile(r"^[ \t]*#[ \t]*define[ \t]+SOTH_DEBUG(_MODE)?\b.*$", re.M)
#: NIPM-HLSP's library sources (what its CMakeLists globs, nipm_hlsp/*.cpp)
NIPM_SOURCES = ("data.cpp", "hlsp.cpp", "lagrangian.cpp", "level.cpp", "levelShared.cpp", "newton.cpp",
                "nipm_hlsp.cpp")
#: the NIPM-HLSP options (members of its ``options`` struct, nipm_hlsp/options.h) the adapter sets at run time
NIPM_OPTIONS = ("maxIter", "KKT_thres", "linearDependency", "activationThres")
NIPM_OPTION_LINE = re.compile(r"^([ \t]*)const (int|double) (" + "|".join(NIPM_OPTIONS) + r") = ([^;]+);", re.M)
#: (file, line as pinned, line as built, why): the fixes of NIPM-HLSP's memory handling (docs/peers.md)
NIPM_FIXES = (
    ("nipm_hlsp.cpp", "int nrIter = nwt->run(opt.maxIter);",
     "int nrIter = nwt->run(opt.maxIter); delete nwt;",
     "each level's Newton object is made with new and never deleted; it owns the level's Lagrangian, which "
     "owns the whole problem: every solve leaked it all"),
    ("hlsp.cpp", "make_shared<levelShared>(shared_ptr<hlsp>(this), p, n)",
     "make_shared<levelShared>(shared_ptr<hlsp>(this, [](hlsp*) {}), p, n)",
     "a second owner of the hlsp made from its this pointer: once the leak above is gone, it deletes the hlsp "
     "twice; the levelShared it owns now refers to it without owning it"),
)
#: where the patched options.h reads them: a struct of NIPM-HLSP's defaults, defined in nipm_adapter.cpp
NIPM_SETTINGS = "hik_nipm::settings()"
#: seconds to compile each unit on a 2-core machine, to start the longest first (make peers prints them)
COST = {"lexls_adapter.cpp": 71, "Stage.cpp": 58, "lagrangian.cpp": 35, "HCOD.cpp": 18, "soth_adapter.cpp": 18,
        "levelShared.cpp": 15, "nipm_adapter.cpp": 15, "newton.cpp": 13, "BaseY.cpp": 10, "BasicStage.cpp": 8,
        "Givens.cpp": 4, "nipm_hlsp.cpp": 4}
FLAGS = ("-O3", "-DNDEBUG", "-std=c++17", "-fPIC", "-fvisibility=hidden", "-w")


class BuildError(Exception):
    """What the user must do, in one line (exit status 2)."""


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="peers/build.py", description=__doc__.split("\n\n")[0])
    p.add_argument("--src", default=os.environ.get("PEERS_SRC") or None,
                   help="folder holding the pinned tarballs (default: a shallow clone of the public repositories)")
    p.add_argument("--out", default=None, help="where the modules go (default: hikbench.solvers.peers.peers_dir())")
    p.add_argument("--march-native", action="store_true", help="add -march=native (recorded in peers.json)")
    p.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="parallel compiler processes")
    args = p.parse_args(argv)
    if args.jobs < 1:
        print(f"make peers: --jobs (PEERS_JOBS) must be at least 1; got {args.jobs}", file=sys.stderr)
        return 2
    try:
        info = build(args.src, args.out, args.march_native, args.jobs)
    except BuildError as err:
        print(f"make peers: {err}", file=sys.stderr)
        return 2
    units = ", ".join(f"{k} {v:.0f} s" for k, v in sorted(info["compile_s"].items(), key=lambda kv: -kv[1]))
    print(f"make peers: built soth, lexls and nipm-hlsp in {info['build_time_s']:.0f} s ({info['jobs']} jobs; "
          f"{units}) into {info['dir']}")
    return 0


def build(src: str | None, out: str | None, march_native: bool, jobs: int) -> dict:
    t0 = time.perf_counter()
    cxx = find_compiler()
    for name in PINNED if src is not None else ():  # (what to fix first: the sources, then headers)
        check_tarball(src, PINNED[name][2])
    inc = header_dirs()
    if out is None:
        from hikbench.solvers.peers import peers_dir
        out = peers_dir()
    out = Path(out)
    flags = [*FLAGS, *(["-march=native"] if march_native else [])]
    with tempfile.TemporaryDirectory(prefix="hikbench-peers-") as tmp:
        tmp = Path(tmp)
        soth, lexls, nipm = (fetch_source(name, src, tmp) for name in PINNED)
        soth_inc = strip_soth_debug(soth, tmp)
        includes = [f"-I{d}" for d in (*inc.values(), sysconfig.get_paths()["include"])]
        soth_flags = [*flags, *includes, f"-I{soth_inc}"]
        check_soth_defines(cxx, soth_flags, soth_inc / "soth")
        suffix = sysconfig.get_config_var("EXT_SUFFIX")
        objects = [(cxx, soth_flags, soth_inc / "soth" / s, tmp / f"soth_{Path(s).stem}.o") for s in SOTH_SOURCES]
        objects.append((cxx, soth_flags, HERE / "soth_adapter.cpp", tmp / "soth_adapter.o"))
        lexls_flags = [*flags, *includes, f"-I{lexls / 'include'}"]
        objects.append((cxx, lexls_flags, HERE / "lexls_adapter.cpp", tmp / "lexls_adapter.o"))
        nipm_flags = [*flags, *includes, f"-I{patch_nipm(nipm)}"]
        objects += [(cxx, nipm_flags, nipm / "nipm_hlsp" / s, tmp / f"nipm_{Path(s).stem}.o") for s in NIPM_SOURCES]
        objects.append((cxx, nipm_flags, HERE / "nipm_adapter.cpp", tmp / "nipm_adapter.o"))
        objects.sort(key=lambda o: -COST.get(o[2].name, 1))  # longest first: the two cores end together
        with ThreadPoolExecutor(jobs) as pool:
            unit_s = dict(zip((o[2].name for o in objects), pool.map(lambda o: compile_one(*o), objects)))
        out.mkdir(parents=True, exist_ok=True)
        link(cxx, flags, [o[3] for o in objects if o[3].name.startswith("soth")], out / f"_hik_soth{suffix}")
        link(cxx, flags, [tmp / "lexls_adapter.o"], out / f"_hik_lexls{suffix}")
        link(cxx, flags, [o[3] for o in objects if o[3].name.startswith("nipm")], out / f"_hik_nipm{suffix}")
    info = {"dir": str(out), "compiler": compiler_version(cxx), "flags": flags, "march_native": march_native,
            "jobs": jobs, "machine": platform.machine(),
            "peers": {name: {"repository": repo, "commit": commit} for name, (repo, commit, *_) in PINNED.items()},
            "source": str(Path(src).resolve()) if src else "git clone",
            "eigen": inc["eigen"], "boost": inc["boost"],
            "build_time_s": round(time.perf_counter() - t0, 2),
            "compile_s": {k: round(v, 2) for k, v in unit_s.items()}}
    (out / "peers.json").write_text(json.dumps(info, indent=2) + "\n")
    return info


def find_compiler() -> str:
    for cand in (os.environ.get("CXX"), "c++", "g++", "clang++"):
        if cand and shutil.which(cand):
            return shutil.which(cand)
    raise BuildError("no C++ compiler found ($CXX, c++, g++, clang++): install one (e.g. `apt-get install g++`) "
                     "or set CXX")


def header_dirs() -> dict[str, str]:
    """Eigen's, Boost's and pybind11's include folders, from their PyPI packages."""
    found: dict[str, str] = {}
    for entry in map(Path, sys.path):
        prefix = entry / "cmeel.prefix" / "include"
        if "eigen" not in found and (prefix / "eigen3" / "Eigen" / "Core").is_file():
            found["eigen"] = str(prefix / "eigen3")
        if "boost" not in found and (prefix / "boost" / "version.hpp").is_file():
            found["boost"] = str(prefix)
    try:
        import pybind11
        found["pybind11"] = pybind11.get_include()
    except ModuleNotFoundError:
        pass
    lacking = [pkg for key, pkg in (("eigen", "cmeel-eigen"), ("boost", "cmeel-boost"), ("pybind11", "pybind11"))
               if key not in found]
    if lacking:
        raise BuildError(f"header package(s) {', '.join(lacking)} not installed in {sys.prefix}: run "
                         f"`{Path(sys.executable).name} -m pip install 'hikbench[peers]'` (or `make peers`)")
    return found


def check_tarball(src: str, tarball: str) -> Path:
    """``src/tarball``, or a BuildError saying what PEERS_SRC must hold."""
    path = Path(src) / tarball
    if not path.is_file():
        names = [t for _, _, t, _ in PINNED.values()]
        raise BuildError(f"{path} not found: PEERS_SRC must be a folder holding {', '.join(names[:-1])} and "
                         f"{names[-1]} (e.g. ../shared/third_party), or leave it unset to clone "
                         f"the public repositories")
    return path


def fetch_source(name: str, src: str | None, tmp: Path) -> Path:
    """The peer's source tree, extracted from its tarball in ``src`` or cloned at its pinned commit."""
    repo, commit, tarball, top = PINNED[name]
    if src is not None:
        path = check_tarball(src, tarball)
        with tarfile.open(path) as tar:
            tar.extractall(tmp, filter="data")
        tree = tmp / top
        if not tree.is_dir():
            raise BuildError(f"{path} does not hold a top folder {top}/: expected the pinned snapshot")
        return tree
    tree = tmp / top
    if shutil.which("git") is None:
        raise BuildError("no PEERS_SRC and no git to clone the peers: install git, or pass "
                         "PEERS_SRC=folder-with-the-tarballs")
    for cmd in (["git", "init", "-q", str(tree)], ["git", "-C", str(tree), "fetch", "-q", "--depth", "1", repo, commit],
                ["git", "-C", str(tree), "checkout", "-q", "FETCH_HEAD"]):
        done = subprocess.run(cmd, capture_output=True, text=True, check=False)
        if done.returncode:
            raise BuildError(f"cloning {repo} at {commit[:7]} failed ({done.stderr.strip().splitlines()[-1:]}): "
                             f"pass PEERS_SRC=folder-with-the-tarballs")
    return tree


def strip_soth_debug(soth: Path, tmp: Path) -> Path:
    """An include folder ``<dir>/soth/`` holding SOTH's src/ with the debug-mode
    ``#define`` lines removed (SOTH's headers are included as ``soth/X.hpp``)."""
    inc = tmp / "soth-include"
    shutil.copytree(soth / "src", inc / "soth")
    for f in (inc / "soth").glob("*.cpp"):
        text = f.read_text()
        stripped = SOTH_DEBUG_LINE.sub("", text)
        if stripped != text:
            f.write_text(stripped)
    return inc


def patch_nipm(nipm: Path) -> Path:
    """Make the :data:`NIPM_OPTIONS` of NIPM-HLSP's extracted ``nipm_hlsp/options.h``
    run-time settings: each ``const T name = default;`` becomes ``const T name =
    hik_nipm::settings().name;``, and a struct ``hik_nipm::Settings`` holding those
    defaults is declared above (the adapter defines ``settings()`` and sets it before
    each solve); then apply :data:`NIPM_FIXES`. The include folder to compile with
    (NIPM-HLSP's root)."""
    path = nipm / "nipm_hlsp" / "options.h"
    text = path.read_text()
    found = {m.group(3): (m.group(2), m.group(4).strip()) for m in NIPM_OPTION_LINE.finditer(text)}
    if sorted(found) != sorted(NIPM_OPTIONS) or len(NIPM_OPTION_LINE.findall(text)) != len(NIPM_OPTIONS) \
            or "#pragma once" not in text:
        raise BuildError(f"NIPM-HLSP's nipm_hlsp/options.h does not declare each of {', '.join(NIPM_OPTIONS)} "
                         f"once as `const int|double NAME = VALUE;` (found {sorted(found)}): the pinned source "
                         f"changed; update peers/build.py")
    fields = " ".join(f"{t} {name} = {value};" for name, (t, value) in found.items())
    settings = (f"namespace hik_nipm {{  // (added by hikbench's peers/build.py: the adapter sets these)\n"
                f"struct Settings {{ {fields} }};\nSettings& settings();\n}}\n")
    text = NIPM_OPTION_LINE.sub(lambda m: f"{m.group(1)}const {m.group(2)} {m.group(3)} = "
                                          f"::{NIPM_SETTINGS}.{m.group(3)};", text)
    path.write_text(text.replace("#pragma once", "#pragma once\n" + settings, 1))
    for name, pinned, built, _why in NIPM_FIXES:
        path = nipm / "nipm_hlsp" / name
        text = path.read_text()
        if text.count(pinned) != 1:
            raise BuildError(f"NIPM-HLSP's nipm_hlsp/{name} does not hold `{pinned}` once: the pinned source "
                             f"changed; update NIPM_FIXES in peers/build.py")
        path.write_text(text.replace(pinned, built))
    return nipm


def check_soth_defines(cxx: str, flags: list[str], src: Path) -> None:
    """Each SOTH source, preprocessed with the build's flags, defines NDEBUG and
    not SOTH_DEBUG (the trace mode that makes SOTH 150-330x slower)."""
    for name in SOTH_SOURCES:
        done = subprocess.run([cxx, *flags, "-dM", "-E", str(src / name)], capture_output=True, text=True,
                              check=False)
        if done.returncode:
            raise BuildError(f"preprocessing SOTH's {name} failed: {done.stderr.strip()[:300]}")
        macros = set(re.findall(r"^#define (\w+)", done.stdout, re.M))
        if "SOTH_DEBUG" in macros or "NDEBUG" not in macros:
            raise BuildError(f"SOTH's {name} still compiles its debug mode (SOTH_DEBUG defined or NDEBUG missing): "
                             f"the pinned source changed; update peers/build.py")


def compile_one(cxx: str, flags: list[str], src: Path, obj: Path) -> float:
    """Compile ``src`` into ``obj``; the seconds it took."""
    t0 = time.perf_counter()
    done = subprocess.run([cxx, *flags, "-c", str(src), "-o", str(obj)], capture_output=True, text=True,
                          check=False)
    if done.returncode:
        raise BuildError(f"compiling {src.name} failed:\n{done.stderr.strip()[-2000:]}")
    return time.perf_counter() - t0


def link(cxx: str, flags: list[str], objects: list[Path], target: Path) -> None:
    tmp_target = target.with_name(target.name + ".tmp")
    done = subprocess.run([cxx, *flags, "-shared", *map(str, objects), "-o", str(tmp_target)], capture_output=True,
                          text=True, check=False)
    if done.returncode:
        raise BuildError(f"linking {target.name} failed:\n{done.stderr.strip()[-2000:]}")
    tmp_target.replace(target)  # (atomic: a running process keeps the old file)


def compiler_version(cxx: str) -> str:
    done = subprocess.run([cxx, "--version"], capture_output=True, text=True, check=False)
    return (done.stdout.splitlines() or [cxx])[0]


if __name__ == "__main__":
    sys.exit(main())
