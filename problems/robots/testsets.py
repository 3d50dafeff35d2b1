"""One-shot robot problems: a stack at a random configuration within the limits
with random reachable targets (the task values at another random configuration,
so every target is attained by some configuration), saved as ``.npz`` problem
files so that every solver, and the C++ peers, see exactly the same rows.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from problems.files import save_npz
from problems.hierarchy import Hierarchy
from problems.robots.stacks import build_stack, stack_names

__all__ = ["stack_problem", "save_test_set", "DEFAULT_SEEDS"]

DEFAULT_SEEDS = tuple(range(5))


def stack_problem(stack_name: str, seed: int = 0, robot: str | None = None) -> Hierarchy:
    """The hierarchy (in u, n = nv) of stack ``stack_name`` at a random configuration.

    Parameters
    ----------
    stack_name : str
        A shipped stack (``problems.robots.stacks.stack_names()``) or a TOML path.
    seed : int
        Seeds ``numpy.random.default_rng``: q first, then the target configuration.
    robot : str, optional
        Run the stack on another robot having the frame aliases it uses.
    """
    stack = build_stack(stack_name, robot=robot)
    rng = np.random.default_rng(seed)
    q = stack.robot.random_configuration(rng)
    stack.set_targets_from(stack.robot.random_configuration(rng))
    return stack.hierarchy(q)


def save_test_set(out_dir: str | os.PathLike, stacks: list[str] | None = None,
                  seeds=DEFAULT_SEEDS) -> list[Path]:
    """Write ``<stack>-seed<k>.npz`` for every stack and seed; returns the paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for name in stacks or stack_names():
        for seed in seeds:
            path = out / f"{Path(name).stem}-seed{seed}.npz"
            save_npz(stack_problem(name, seed), path)
            paths.append(path)
    return paths
