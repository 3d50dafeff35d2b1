"""Fixtures shared by the CLI tests."""

from __future__ import annotations

import numpy as np
import pytest

from doubles import DECLINING_SUITE

from hikbench.bench.cli import main
from hikbench.problems import Hierarchy, Level
from hikbench.problems.files import save_npz


@pytest.fixture
def problem(tmp_path):
    """(h, path of h saved as .npz): level 0: x0 + x1 = 2 and x1 <= 0.5 (named 'reach');
    level 1: x0 = 3 (conflicts with level 0)."""
    h = Hierarchy.from_levels([Level([[1.0, 1.0], [0.0, 1.0]], [2.0, -np.inf], [2.0, 0.5], "reach"),
                               Level.equality([[1.0, 0.0]], [3.0], "posture")])
    path = tmp_path / "p.npz"
    save_npz(h, path)
    return h, str(path)


@pytest.fixture(scope="session")
def declining_run(tmp_path_factory):
    """A small run where nullspace-svd declines ik-like (inequalities) and solves the
    equality rows; shared by the report and summary tests (copy it before editing it)."""
    d = tmp_path_factory.mktemp("decl")
    (d / "s.toml").write_text(DECLINING_SUITE)
    assert main(["run", "--quiet", "--suite", str(d / "s.toml"), "--out", str(d / "out")]) == 0
    return d / "out"
