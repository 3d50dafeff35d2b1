"""Kinematics of one configuration, computed once and shared by every task."""

from __future__ import annotations

import functools

import numpy as np
import pinocchio as pin

from hikbench.problems.errors import HikbenchError
from hikbench.problems.robots.models import Robot

__all__ = ["KinematicState", "TaskError", "skew"]


class TaskError(HikbenchError, ValueError):
    """A task or configuration with a bad parameter (shape, axis name, missing target)."""


def skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrix: ``skew(a) @ b == np.cross(a, b)``, shape (3, 3)."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


class KinematicState:
    """Placements and Jacobians of a robot at configuration q (shape (nq,)).

    Forward kinematics and the joint Jacobians are computed at construction
    (``pin.computeJointJacobians`` + ``pin.updateFramePlacements``); the centre
    of mass and its Jacobian on first use.
    """

    def __init__(self, robot: Robot, q: np.ndarray):
        self.robot = robot
        self.model = robot.model
        self.q = np.array(q, dtype=float)
        if self.q.shape != (robot.nq,) or not np.all(np.isfinite(self.q)):
            raise TaskError(f"robot {robot.name!r}: q must be {robot.nq} finite numbers; got shape "
                            f"{self.q.shape}" + ("" if np.all(np.isfinite(self.q)) else " with NaN/inf"))
        self.data = self.model.createData()
        pin.computeJointJacobians(self.model, self.data, self.q)
        pin.updateFramePlacements(self.model, self.data)

    def placement(self, frame_id: int) -> pin.SE3:
        """World placement oMf of a frame."""
        return self.data.oMf[frame_id]

    def position(self, frame_id: int) -> np.ndarray:
        return np.array(self.data.oMf[frame_id].translation)

    def jacobian(self, frame_id: int, reference=pin.LOCAL_WORLD_ALIGNED) -> np.ndarray:
        """Frame Jacobian, shape (6, nv): linear rows then angular rows, in ``reference``
        (LOCAL: the frame's axes; LOCAL_WORLD_ALIGNED: world axes at the frame origin)."""
        return pin.getFrameJacobian(self.model, self.data, frame_id, reference)

    @functools.cached_property
    def _com(self) -> tuple[np.ndarray, np.ndarray]:
        data = self.model.createData()
        J = np.array(pin.jacobianCenterOfMass(self.model, data, self.q, False))
        return np.array(data.com[0]), J

    @property
    def com(self) -> np.ndarray:
        """Centre of mass in the world, shape (3,)."""
        return self._com[0]

    @property
    def com_jacobian(self) -> np.ndarray:
        """d com / d u, shape (3, nv)."""
        return self._com[1]
