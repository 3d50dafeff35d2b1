"""Task variables (Vijayakumar's kinematics lecture) and their levels.

Each task has a value ``e(q)`` and a Jacobian ``J = de/du`` with respect to the
velocity ``u`` (shape (d, nv)): ``e(q (+) u dt) = e(q) + J u dt + O(dt^2)``,
where ``(+)`` is ``pin.integrate``. An **equality** task turns into the rows of
a level by the exponential decrease of its error (ICRA 2010, eq. 47)::

    e_dot* = -lambda e + e_dot_ff   ->   J u = -lambda e + e_dot_ff

(``e_dot_ff`` a feed-forward term from a moving target, 0 for a fixed one).
Inequality tasks (``hikbench.problems.robots.limits``) give bounds instead.

Shapes: q (nq,), u (nv,), J (d, nv).
"""

from __future__ import annotations

import abc
from typing import ClassVar

import numpy as np
import pinocchio as pin

from hikbench.problems.robots.kinematics import KinematicState, TaskError, skew
from hikbench.problems.robots.models import Robot
from hikbench.problems.schema import Number, checked

__all__ = [
    "AlignmentTask",
    "ComTask",
    "DirectionTask",
    "MinimalVelocityTask",
    "OrientationTask",
    "PoseTask",
    "PositionTask",
    "PostureTask",
    "Task",
    "TaskError",
    "axes_index",
    "number",
    "placement",
    "rotation",
]


def axes_index(axes: str) -> np.ndarray:
    """``"xy"`` -> ``[0, 1]``; raises TaskError for anything but a subset of xyz."""
    if not isinstance(axes, str) or not axes or any(a not in "xyz" for a in axes) or len(set(axes)) != len(axes):
        raise TaskError(f"axes must be a non-empty subset of 'xyz' without repeats; got {axes!r}")
    return np.array(["xyz".index(a) for a in axes])


def _vector(v, size: int, what: str) -> np.ndarray:
    try:
        a = np.asarray(v, dtype=float).reshape(-1)
    except (TypeError, ValueError):  # strings, tables, ragged lists
        a = None
    if a is None or a.shape != (size,) or not np.all(np.isfinite(a)) or isinstance(v, (str, bool)):
        raise TaskError(f"{what} must be {size} finite numbers; got {v!r}")
    return a


def number(v, what: str, *, low: float = 0.0, low_open: bool = False) -> float:
    """``v`` as a float: a finite real number (not a bool, not a string) ``>= low``
    (``> low`` with ``low_open``); else TaskError ``WHAT must be a finite number >= 0; got V``."""
    return float(checked(Number(low, low_open=low_open), v, what, TaskError))


def rotation(v, what: str) -> np.ndarray:
    """A rotation matrix from a 3x3 nested list (orthonormal, det +1, to 1e-9) or a
    table ``{ rpy = [roll, pitch, yaw] }`` (rad, ``pin.rpy.rpyToMatrix``); shape (3, 3)."""
    if isinstance(v, dict):
        if set(v) - {"rpy"}:
            raise TaskError(f"{what}: unknown key(s) {sorted(set(v) - {'rpy'})}; expected {{ rpy = [r, p, y] }}")
        return np.array(pin.rpy.rpyToMatrix(*_vector(v.get("rpy", (0.0, 0.0, 0.0)), 3, f"{what} rpy")))
    R = _vector(v, 9, f"{what} (a 3x3 rotation matrix, or {{ rpy = [r, p, y] }})").reshape(3, 3)
    if not (np.allclose(R.T @ R, np.eye(3), rtol=0.0, atol=1e-9) and np.linalg.det(R) > 0):
        raise TaskError(f"{what} must be a rotation matrix (R^T R = I, det R = +1, to 1e-9); got {v!r}")
    return R


def placement(v, what: str) -> pin.SE3:
    """A pose target: a pin.SE3, or a table ``{ position = [x, y, z], rpy = [r, p, y] }``
    (both optional, default 0)."""
    if isinstance(v, pin.SE3):
        return pin.SE3(v)
    if not isinstance(v, dict) or set(v) - {"position", "rpy"}:
        raise TaskError(f"{what} must be a table {{ position = [x, y, z], rpy = [r, p, y] }}; got {v!r}")
    R = rotation({"rpy": v.get("rpy", (0.0, 0.0, 0.0))}, what)
    return pin.SE3(R, _vector(v.get("position", (0.0, 0.0, 0.0)), 3, f"{what} position"))


class Task(abc.ABC):
    """A task variable of one robot.

    Attributes
    ----------
    name : str
        Unique within a stack; the CSV column of its error.
    gain : float
        lambda of eq. (47), 1/s.
    relation : {"equality", "inequality"}
    """

    relation: ClassVar[str] = "equality"

    def __init__(self, robot: Robot, name: str, gain: float = 1.0):
        if not isinstance(name, str) or not name:
            raise TaskError(f"a task name must be a non-empty string; got {name!r}")
        self.robot = robot
        self.name = name
        self.gain = number(gain, f"task {name!r}: gain")
        self.target_velocity: np.ndarray | None = None  #: feed-forward e_dot_ff, shape (d,)

    @abc.abstractmethod
    def value(self, state: KinematicState) -> np.ndarray:
        """The task value e(q), shape (d,); for equality tasks the error (0 at the target)."""

    @abc.abstractmethod
    def jacobian(self, state: KinematicState) -> np.ndarray:
        """de/du, shape (d, nv)."""

    def set_target_from(self, state: KinematicState) -> None:
        """Make the current value of ``state`` the target (e = 0 there)."""

    def feedforward(self, state: KinematicState) -> np.ndarray:
        """e_dot_ff, the error rate the moving target alone causes, negated; shape (d,)."""
        e = self.value(state)
        return np.zeros_like(e) if self.target_velocity is None else self.target_velocity

    def rows(self, state: KinematicState, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Level rows ``lower <= A u <= upper``: eq. (47), ``J u = -lambda e + e_dot_ff``."""
        b = -self.gain * self.value(state) + self.feedforward(state)
        return self.jacobian(state), b, b.copy()

    def error_norm(self, state: KinematicState, u: np.ndarray | None = None) -> float | None:
        """||e(q)|| for reports (m, rad or mixed for 6D); a task of the velocity u (minimal
        velocity, velocity limits) returns its error of u, or None when u is not given."""
        return float(np.linalg.norm(self.value(state)))


class _FrameTask(Task):
    def __init__(self, robot: Robot, name: str, frame: str, gain: float = 1.0):
        super().__init__(robot, name, gain)
        if not isinstance(frame, str):
            raise TaskError(f"task {name!r}: frame must be a frame name (a string); got {frame!r}")
        self.frame = frame
        self.frame_id = robot.frame_id(frame)


class PositionTask(_FrameTask):
    """Position of a frame origin (lecture task 1): e = p(q) - p*, J = J_lwa[0:3] (world axes),
    restricted to ``axes`` (d = len(axes)). Target default: the origin at q0."""

    def __init__(self, robot: Robot, name: str, frame: str, target=None, axes: str = "xyz",
                 gain: float = 1.0):
        super().__init__(robot, name, frame, gain)
        self.axes = axes_index(axes)
        self.target = None if target is None else _vector(target, 3, f"task {name!r} target")

    def set_target_from(self, state):
        self.target = state.position(self.frame_id)

    def _target(self) -> np.ndarray:
        if self.target is None:
            raise TaskError(f"task {self.name!r} has no target; set one or call set_target_from")
        return self.target

    def value(self, state):
        return (state.position(self.frame_id) - self._target())[self.axes]

    def jacobian(self, state):
        return state.jacobian(self.frame_id)[:3][self.axes]

    def feedforward(self, state):
        if self.target_velocity is None:
            return np.zeros(len(self.axes))
        return np.asarray(self.target_velocity)[self.axes]


class OrientationTask(_FrameTask):
    """Orientation of a frame: e = log3(R*^T R), J = Jlog3(R*^T R) J_local[3:6] (d = 3)."""

    def __init__(self, robot: Robot, name: str, frame: str, target=None, gain: float = 1.0):
        super().__init__(robot, name, frame, gain)
        self.target = None if target is None else rotation(target, f"task {name!r} target")

    def set_target_from(self, state):
        self.target = np.array(state.placement(self.frame_id).rotation)

    def _error_rotation(self, state) -> np.ndarray:
        if self.target is None:
            raise TaskError(f"task {self.name!r} has no target orientation")
        return self.target.T @ state.placement(self.frame_id).rotation

    def value(self, state):
        return np.array(pin.log3(self._error_rotation(state)))

    def jacobian(self, state):
        return pin.Jlog3(self._error_rotation(state)) @ state.jacobian(self.frame_id, pin.LOCAL)[3:]


class PoseTask(_FrameTask):
    """6D pose of a frame: e = log6(T*^-1 T(q)) (linear, angular), J = Jlog6(T*^-1 T) J_local.

    A moving target with body velocity nu* (``target_velocity``, shape (6,), in the
    target frame) adds e_dot_ff = Jlog6 Ad(T^-1 T*) nu*, since the error placement
    M = T*^-1 T has body velocity J_local u - Ad(M^-1) nu*."""

    def __init__(self, robot: Robot, name: str, frame: str, target: pin.SE3 | None = None,
                 gain: float = 1.0):
        super().__init__(robot, name, frame, gain)
        self.target = None if target is None else placement(target, f"task {name!r} target")

    def set_target_from(self, state):
        self.target = pin.SE3(state.placement(self.frame_id))

    def _error_placement(self, state) -> pin.SE3:
        if self.target is None:
            raise TaskError(f"task {self.name!r} has no target placement")
        return self.target.actInv(state.placement(self.frame_id))

    def value(self, state):
        return np.array(pin.log6(self._error_placement(state)).vector)

    def jacobian(self, state):
        return pin.Jlog6(self._error_placement(state)) @ state.jacobian(self.frame_id, pin.LOCAL)

    def feedforward(self, state):
        if self.target_velocity is None:
            return np.zeros(6)
        M = self._error_placement(state)
        return pin.Jlog6(M) @ (M.inverse().toActionMatrix() @ np.asarray(self.target_velocity))

    def position_error(self, state) -> float:
        """||p - p*|| (m)."""
        return float(np.linalg.norm(state.position(self.frame_id) - self.target.translation))


class DirectionTask(_FrameTask):
    """Vector v attached to a frame (lecture task 2): e = R v - v* (world), J = -[R v]x J_w,
    J_w the angular rows of the world-aligned frame Jacobian (d = 3)."""

    def __init__(self, robot: Robot, name: str, frame: str, vector=(0.0, 0.0, 1.0), target=None,
                 gain: float = 1.0):
        super().__init__(robot, name, frame, gain)
        self.vector = _vector(vector, 3, f"task {name!r} vector")
        self.target = None if target is None else _vector(target, 3, f"task {name!r} target")

    def direction(self, state) -> np.ndarray:
        return state.placement(self.frame_id).rotation @ self.vector

    def set_target_from(self, state):
        self.target = self.direction(state)

    def value(self, state):
        if self.target is None:
            raise TaskError(f"task {self.name!r} has no target direction")
        return self.direction(state) - self.target

    def jacobian(self, state):
        return -skew(self.direction(state)) @ state.jacobian(self.frame_id)[3:]


class AlignmentTask(DirectionTask):
    """Alignment of an attached vector v with a world reference v* (lecture task 3):
    e = v*^T R v - 1 (0 when aligned, -2 anti-aligned), J = v*^T J_vec (d = 1).
    Note J vanishes at perfect alignment (e is at its maximum there)."""

    def __init__(self, robot: Robot, name: str, frame: str, vector=(0.0, 0.0, 1.0),
                 reference=(0.0, 0.0, 1.0), gain: float = 1.0):
        super().__init__(robot, name, frame, vector, None, gain)
        ref = _vector(reference, 3, f"task {name!r} reference")
        self.reference = ref / np.linalg.norm(ref)

    def set_target_from(self, state):
        """The reference is fixed by construction; nothing to set."""

    def value(self, state):
        return np.array([self.reference @ self.direction(state) - 1.0])

    def jacobian(self, state):
        return (self.reference @ super().jacobian(state))[None, :]


class ComTask(Task):
    """Centre of mass (lecture task 6): e = c(q) - c*, J = J_com[axes] (``axes="xy"``: its
    ground projection)."""

    def __init__(self, robot: Robot, name: str = "com", target=None, axes: str = "xyz",
                 gain: float = 1.0):
        super().__init__(robot, name, gain)
        mass = pin.computeTotalMass(robot.model)
        if not mass > 0:  # c = sum m_i c_i / sum m_i: undefined without masses
            raise TaskError(f"task {name!r}: robot {robot.name!r} has a total mass of {mass:g} kg (no <inertial> "
                            "in its URDF); expected link masses for a com task")
        self.axes = axes_index(axes)
        self.target = None if target is None else _vector(target, 3, f"task {name!r} target")

    def set_target_from(self, state):
        self.target = state.com.copy()

    def value(self, state):
        if self.target is None:
            raise TaskError(f"task {self.name!r} has no target")
        return (state.com - self.target)[self.axes]

    def jacobian(self, state):
        return state.com_jacobian[self.axes]

    def feedforward(self, state):
        if self.target_velocity is None:
            return np.zeros(len(self.axes))
        return np.asarray(self.target_velocity)[self.axes]


class PostureTask(Task):
    """Joint posture (lecture task 7, q itself): e = difference(q*, q)[S], J = d difference /
    d q (ARG1) [S], with S the joint coordinates (``joints="actuated"``: all but a free-flyer
    root; ``"all"``: every tangent coordinate)."""

    def __init__(self, robot: Robot, name: str = "posture", target=None, joints: str = "actuated",
                 gain: float = 1.0):
        super().__init__(robot, name, gain)
        if joints not in ("actuated", "all"):
            raise TaskError(f"task {name!r}: joints must be 'actuated' or 'all'; got {joints!r}")
        self.select = robot.actuated.copy() if joints == "actuated" else np.ones(robot.nv, dtype=bool)
        self.target = None if target is None else _vector(target, robot.nq, f"task {name!r} target")

    def set_target_from(self, state):
        self.target = state.q.copy()

    def value(self, state):
        if self.target is None:
            raise TaskError(f"task {self.name!r} has no target configuration")
        return pin.difference(self.robot.model, self.target, state.q)[self.select]

    def jacobian(self, state):
        return pin.dDifference(self.robot.model, self.target, state.q, pin.ARG1)[self.select]


class MinimalVelocityTask(Task):
    """Minimal velocity (the lowest level of ICRA 2010 sec. XII): rows S u = 0 (d = nv or the
    actuated part). Its value is not kinematic; its reported error is ||S u|| (rad/s)."""

    def __init__(self, robot: Robot, name: str = "velocity", joints: str = "actuated", gain: float = 0.0):
        super().__init__(robot, name, gain)
        if joints not in ("actuated", "all"):
            raise TaskError(f"task {name!r}: joints must be 'actuated' or 'all'; got {joints!r}")
        self.select = robot.actuated.copy() if joints == "actuated" else np.ones(robot.nv, dtype=bool)

    def value(self, state):
        return np.zeros(int(self.select.sum()))

    def jacobian(self, state):
        return np.eye(self.robot.nv)[self.select]

    def error_norm(self, state, u=None):
        return None if u is None else float(np.linalg.norm(np.asarray(u)[self.select]))
