"""Inequality tasks: joint position limits (ICRA 2010 eq. 48), joint velocity
limits, minimum distance between two frames (lecture task 5, as a constraint).

Each gives bounds ``lower <= J u <= upper`` on the velocity u (shape (nv,)).
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np
import pinocchio as pin

from hikbench.problems.robots.models import Robot
from hikbench.problems.robots.tasks import Task, TaskError, number

__all__ = ["INEQUALITY_TASKS", "FrameDistance", "JointPositionLimits", "JointVelocityLimits"]


class _Inequality(Task):
    relation: ClassVar[str] = "inequality"

    def __init__(self, robot: Robot, name: str, gain: float | None = None):
        # gain None: 1/dt, i.e. the whole remaining margin in one step (eq. 48)
        super().__init__(robot, name, 0.0 if gain is None else gain)
        self.gain_is_one_over_dt = gain is None

    def _lambda(self, dt: float) -> float:
        return 1.0 / dt if self.gain_is_one_over_dt else self.gain


class JointPositionLimits(_Inequality):
    """Joint position limits as velocity bounds (eq. 48), on the bounded coordinates S only::

        q_l - q <= u dt <= q_u - q      ->   lambda d_l <= S u <= lambda d_u,

    d_l = difference(q, q_l)[S], d_u = difference(q, q_u)[S] (configuration-space
    difference; q_l, q_u are q with the bounded coordinates at their limits) and
    lambda = 1/dt (eq. 48) unless a gain is given. The free flyer and continuous
    joints are unbounded. ``value`` is q[S] (its Jacobian is S); the reported error
    is the total violation ``sum max(q_l - q, 0) + max(q - q_u, 0)`` (rad or m).
    """

    def __init__(self, robot: Robot, name: str = "joint_limits", gain: float | None = None):
        super().__init__(robot, name, gain)
        self.select = robot.bounded.copy()

    def value(self, state):
        return state.q[self.robot.bounded_q]

    def jacobian(self, state):
        return np.eye(self.robot.nv)[self.select]

    def rows(self, state, dt):
        model = self.robot.model
        q_l, q_u = state.q.copy(), state.q.copy()
        q_l[self.robot.bounded_q] = self.robot.lower
        q_u[self.robot.bounded_q] = self.robot.upper
        lam = self._lambda(dt)
        d_l = pin.difference(model, state.q, q_l)[self.select]
        d_u = pin.difference(model, state.q, q_u)[self.select]
        return self.jacobian(state), lam * d_l, lam * d_u

    def error_norm(self, state, u=None):
        m = self.robot.limit_margin(state.q)
        return float(np.sum(np.maximum(-m, 0.0)))


class JointVelocityLimits(_Inequality):
    """|u_i| <= min(scale * v_max_i, cap) on the coordinates with a finite velocity
    limit (``model.velocityLimit``; the free flyer has none); ``cap`` (rad/s or m/s,
    default none) bounds every coordinate alike, whatever its URDF limit. Not a
    function of q: ``value`` is empty and the reported error is the total excess (rad/s) of the
    velocity u; None without u (an error of u, not of q)."""

    def __init__(self, robot: Robot, name: str = "velocity_limits", scale: float = 1.0,
                 cap: float | None = None):
        super().__init__(robot, name, 0.0)
        scale = number(scale, f"task {name!r}: scale", low_open=True)
        vmax = np.asarray(robot.model.velocityLimit, dtype=float)
        self.select = np.isfinite(vmax) & (vmax > 0) & (vmax < 1e10)
        self.vmax = scale * vmax[self.select]
        if cap is not None:
            self.vmax = np.minimum(self.vmax, number(cap, f"task {name!r}: cap", low_open=True))

    def value(self, state):
        return np.zeros(0)

    def jacobian(self, state):
        return np.eye(self.robot.nv)[self.select]

    def rows(self, state, dt):
        return self.jacobian(state), -self.vmax, self.vmax.copy()

    def error_norm(self, state, u=None):
        if u is None:
            return None
        return float(np.sum(np.maximum(np.abs(np.asarray(u)[self.select]) - self.vmax, 0.0)))


class FrameDistance(_Inequality):
    """Minimum distance between two frame origins a, b (d = 1)::

        d(q) = ||p_a - p_b||,   J = n^T (J_a - J_b)[0:3],  n = (p_a - p_b) / d,
        d_dot >= -lambda (d - d_min)   ->   -lambda (d - d_min) <= J u <= +inf

    (lambda = 1/dt: d + J u dt >= d_min after one step). ``value`` is d (m); the
    reported error is the violation max(d_min - d, 0)."""

    def __init__(self, robot: Robot, name: str, frame_a: str, frame_b: str, d_min: float,
                 gain: float | None = None):
        super().__init__(robot, name, gain)
        d_min = number(d_min, f"task {name!r}: d_min")
        for frame in (frame_a, frame_b):
            if not isinstance(frame, str):
                raise TaskError(f"task {name!r}: frame_a and frame_b must be frame names (strings); got {frame!r}")
        self.frame_a, self.frame_b = frame_a, frame_b
        self.id_a, self.id_b = robot.frame_id(frame_a), robot.frame_id(frame_b)
        if self.id_a == self.id_b:
            raise TaskError(f"task {name!r}: the two frames are the same ({frame_a!r})")
        self.d_min = float(d_min)

    def _delta(self, state) -> np.ndarray:
        return state.position(self.id_a) - state.position(self.id_b)

    def value(self, state):
        return np.array([np.linalg.norm(self._delta(state))])

    def jacobian(self, state):
        delta = self._delta(state)
        d = np.linalg.norm(delta)
        if d == 0.0:
            raise TaskError(f"task {self.name!r}: frames {self.frame_a!r} and {self.frame_b!r} "
                            "coincide; the distance gradient is undefined")
        n = delta / d
        Ja = state.jacobian(self.id_a)[:3]
        Jb = state.jacobian(self.id_b)[:3]
        return (n @ (Ja - Jb))[None, :]

    def rows(self, state, dt):
        d = self.value(state)
        return self.jacobian(state), -self._lambda(dt) * (d - self.d_min), np.array([np.inf])

    def error_norm(self, state, u=None):
        return float(max(self.d_min - self.value(state)[0], 0.0))


INEQUALITY_TASKS = (JointPositionLimits, JointVelocityLimits, FrameDistance)
