"""The distribution: one import namespace (``hikbench.*``), its version, the
package list of pyproject.toml, and the one-line error of a missing extra."""

from __future__ import annotations

import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest

import hikbench
from hikbench.extras import EXTRA_OF, extra_for, install_hint

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())


def _python(code: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], cwd=cwd, capture_output=True, text=True, timeout=300)


@pytest.mark.parametrize("name", ["hikbench.bench", "hikbench.solvers", "hikbench.problems",
                                  "hikbench.bench.harness.runner", "hikbench.solvers.hcod"])
def test_the_subpackages_import_under_hikbench(name, tmp_path):
    done = _python(f"import {name}", tmp_path)
    assert done.returncode == 0, done.stderr


@pytest.mark.parametrize("name", ["problems", "solvers", "bench"])
def test_no_generic_top_level_package_is_installed(name, tmp_path):
    """Outside the checkout (whose folders are on sys.path only from its root)."""
    done = _python(f"import {name}", tmp_path)
    assert done.returncode == 1 and f"No module named '{name}'" in done.stderr


def test_version_is_the_distributions(capsys):
    from importlib.metadata import version

    from hikbench.bench.cli import main

    assert hikbench.__version__ == version("hikbench") == PYPROJECT["project"]["version"]
    assert main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"hikbench {hikbench.__version__}"


def _package_folders() -> set[str]:
    """hikbench.* names of the folders under bench/, solvers/, problems/ that hold
    Python modules or data files (TOML)."""
    names = {"hikbench"}
    for top in ("bench", "solvers", "problems"):
        for d in [ROOT / top, *(p for p in (ROOT / top).rglob("*") if p.is_dir())]:
            if d.name == "__pycache__" or not any(f.suffix in (".py", ".toml") for f in d.iterdir()):
                continue
            names.add(".".join(["hikbench", *d.relative_to(ROOT).parts]))
    return names


def test_pyproject_lists_every_package_folder():
    assert set(PYPROJECT["tool"]["setuptools"]["packages"]) == _package_folders()


@pytest.mark.slow
def test_the_wheel_holds_only_the_hikbench_namespace(tmp_path):
    """The wheel's top_level.txt names hikbench alone, and every module is under hikbench/."""
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--quiet", "--no-deps", "--no-build-isolation",
                    "-w", str(tmp_path), str(ROOT)], check=True, timeout=600, capture_output=True)
    (wheel,) = tmp_path.glob("hikbench-*.whl")
    with zipfile.ZipFile(wheel) as z:
        names = z.namelist()
        top = next(n for n in names if n.endswith("top_level.txt"))
        assert z.read(top).decode().split() == ["hikbench"]
    modules = [n for n in names if n.endswith(".py")]
    assert modules and all(n.startswith("hikbench/") for n in modules)
    assert "hikbench/bench/suites/quick.toml" in names and "hikbench/problems/robots/stacks/arm_reach.toml" in names
    # the test set and its URDF arm (docs/testset.md): hikbench run --suite hlsp-1 from a wheel
    assert "hikbench/problems/testset/hlsp-1/manifest.json" in names and "hikbench/problems/robots/arm7.urdf" in names
    from hikbench.problems.testset import TestSet

    npz = [n for n in names if n.startswith("hikbench/problems/testset/hlsp-1/") and n.endswith(".npz")]
    assert len(npz) == len(TestSet.read("hlsp-1"))


@pytest.mark.parametrize("module, extra", sorted(EXTRA_OF.items()), ids=sorted(EXTRA_OF))
def test_every_optional_module_names_an_extra_of_pyproject(module, extra):
    extras = PYPROJECT["project"]["optional-dependencies"]
    assert extra_for(f"{module}.sub") == extra and extra in extras
    assert f"hikbench[{extra}]" in install_hint(module)
    assert "all" in extras and f"hikbench[{','.join(e for e in ('robots', 'cvxpy', 'dask'))}]" in extras["all"]


# A module made missing in a child process: ``sys.modules[name] = None`` makes ``import name``
# raise ModuleNotFoundError, as it does where the extra is not installed.
_WITHOUT = ("import sys\nfor m in {mods!r}: sys.modules[m] = None\n"
            "from hikbench.bench.cli import main\nsys.exit(main({argv!r}))\n")


@pytest.mark.parametrize("mods, argv, extra", [
    (["pinocchio"], ["scenario", "reach", "--steps", "1"], "robots"),
    (["pinocchio"], ["list", "robots"], "robots"),
    (["example_robot_data"], ["generate", "robot-stack", "--out", "p.npz"], "robots"),
    (["distributed", "dask"], ["run", "--suite", "ci", "--workers", "2", "--out", "out"], "dask"),
], ids=["scenario", "list-robots", "robot-family", "dask-workers"])
def test_a_command_needing_a_missing_extra_says_which(tmp_path, mods, argv, extra):
    done = _python(_WITHOUT.format(mods=mods, argv=argv), tmp_path)
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2 and len(lines) == 1, done.stderr
    assert f"pip install 'hikbench[{extra}]'" in lines[0] and lines[0].startswith(f"hikbench {argv[0]}: error: ")


def test_a_missing_cvxpy_leaves_its_solver_out_and_says_how_to_install_it(tmp_path):
    code = ("import sys\nsys.modules['cvxpy'] = None\nfrom hikbench.solvers import registry\n"
            "print('cascade-cvxpy' in registry.available(), registry.missing()['cascade-cvxpy'])\n")
    done = _python(code, tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "False cvxpy is not installed (extra 'cvxpy'): pip install 'hikbench[cvxpy]'"
