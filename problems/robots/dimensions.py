"""A robot's own lengths, for scenario offsets given in units of the robot's size.

The length of a limb carrying frame F is the summed length of its links: the
distance from F to its parent joint's origin, plus the distance from each joint
of the limb to the next one up, up to the limb's root joint (the first joint,
going up from F, whose parent is the world or a joint with several child
joints: the torso of a humanoid, the base of a serial arm)::

    L(F) = ||p_F - p_{j_1}|| + sum_{i=1..k-1} ||p_{j_i} - p_{j_{i+1}}||,   j_k the root joint

Each term is a joint placement in its parent joint's frame, so L is the same at
every configuration (the stretched length of the limb, an upper bound of its
reach). The named lengths (:data:`LENGTHS`):

==============  =====================================================
``arm_length``  L(``right_hand``), or L(``ee``) on a robot without a right hand
``leg_length``  L(``right_foot``)
==============  =====================================================
"""

from __future__ import annotations

import numpy as np

from hikbench.problems.robots.models import Robot

__all__ = ["LENGTHS", "limb_length", "robot_length", "robot_lengths"]

#: length name -> the frame aliases whose limb measures it, in preference order
LENGTHS: dict[str, tuple[str, ...]] = {"arm_length": ("right_hand", "ee"), "leg_length": ("right_foot",)}


def limb_length(robot: Robot, frame: str) -> float:
    """L(frame) (m; module docstring); ``frame`` is an alias or a frame name of ``robot``."""
    model = robot.model
    f = model.frames[robot.frame_id(frame)]
    length = float(np.linalg.norm(f.placement.translation))
    children = np.bincount(np.asarray(model.parents[1:], dtype=int), minlength=model.njoints)
    j = int(f.parentJoint)
    while j > 0:
        parent = int(model.parents[j])
        if parent == 0 or children[parent] > 1:
            break
        length += float(np.linalg.norm(model.jointPlacements[j].translation))
        j = parent
    return length


def robot_length(robot: Robot, name: str) -> float | None:
    """The named length of :data:`LENGTHS` (m), or None when the robot has none of its frames."""
    for alias in LENGTHS[name]:
        if alias in robot.frames:
            return limb_length(robot, alias)
    return None


def robot_lengths(robot: Robot) -> dict[str, float]:
    """Every named length the robot has: name -> m."""
    out = {name: robot_length(robot, name) for name in LENGTHS}
    return {name: v for name, v in out.items() if v is not None}
