"""One-shot robot problems: a stack at a random configuration within the limits
with random reachable targets (the task values at another random configuration,
so every target is attained by some configuration), saved as ``.npz`` problem
files so that every solver, and the C++ peers, see exactly the same rows.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from hikbench.problems.errors import HikbenchError
from hikbench.problems.files import save_npz
from hikbench.problems.family import Family
from hikbench.problems.hierarchy import Hierarchy

__all__ = ["DEFAULT_SEEDS", "ROBOT_FAMILIES", "SHIPPED_STACKS", "save_test_set", "stack_problem"]

DEFAULT_SEEDS = tuple(range(5))
#: the stacks in problems/robots/stacks (kept here so listing families needs no pinocchio import)
SHIPPED_STACKS = ("arm_reach", "humanoid_reach", "humanoid_step", "humanoid_tasks", "quadruped_stance")


def stack_problem(stack_name: str, seed: int = 0, robot: str | None = None, srdf: str | None = None,
                  floating_base: bool | None = None, reference: str | None = None) -> Hierarchy:
    """The hierarchy (in u, n = nv) of stack ``stack_name`` at a random configuration.

    Parameters
    ----------
    stack_name : str
        A shipped stack (``hikbench.problems.robots.stacks.stack_names()``) or a TOML path.
    seed : int
        Seeds ``numpy.random.default_rng``: q first, then the target configuration.
    robot : str, optional
        Run the stack on another robot having the frame aliases it uses: a robot name or
        the path of a .urdf file (relative to the working directory).
    srdf, floating_base, reference : optional
        With a .urdf robot: its SRDF path, root joint and SRDF group_state
        (:mod:`hikbench.problems.robots.urdf`).
    """
    from hikbench.problems.robots.models import robot_source  # pinocchio is imported on first use only
    from hikbench.problems.robots.stacks import build_stack

    if robot is None and (srdf, floating_base, reference) != (None, None, None):
        raise HikbenchError("srdf, floating_base and reference apply with robot = the path of a .urdf file")
    if floating_base is not None and not isinstance(floating_base, bool):
        raise HikbenchError(f"floating_base must be true or false; got {floating_base!r}")
    ref = None if robot is None else robot_source(robot, srdf, floating_base, reference)
    stack = build_stack(stack_name, robot=ref)
    rng = np.random.default_rng(seed)
    q = stack.robot.random_configuration(rng)
    stack.set_targets_from(stack.robot.random_configuration(rng))
    return stack.hierarchy(q)


def save_test_set(out_dir: str | os.PathLike, stacks: list[str] | None = None,
                  seeds=DEFAULT_SEEDS) -> list[Path]:
    """Write ``<stack>-seed<k>.npz`` for every stack and seed; returns the paths."""
    from hikbench.problems.robots.stacks import stack_names

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for name in stacks or stack_names():
        for seed in seeds:
            path = out / f"{Path(name).stem}-seed{seed}.npz"
            save_npz(stack_problem(name, seed), path)
            paths.append(path)
    return paths


def _robot_stack(seed: int = 0, stack: str = "humanoid_reach", robot: str | None = None,
                 srdf: str | None = None, floating_base: bool | None = None, reference: str | None = None) -> Hierarchy:
    return stack_problem(stack, seed=seed, robot=robot, srdf=srdf, floating_base=floating_base,
                         reference=reference)


#: generator families (``hikbench.problems.generators.Family``) for the harness: merge them into
#: ``hikbench.problems.generators.FAMILIES`` to sweep the robot stacks by seed and stack name.
ROBOT_FAMILIES: dict[str, Family] = {f.name: f for f in (
    Family("robot-stack", "a robot task stack (problems/robots/stacks) at a random configuration within "
           "the limits with reachable targets; variables u (n = nv)", _robot_stack,
           {"stack": "humanoid_reach", "robot": None, "srdf": None, "floating_base": None, "reference": None},
           sweep={"stack": list(SHIPPED_STACKS)}),
)}
