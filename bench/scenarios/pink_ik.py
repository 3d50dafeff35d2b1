"""``pink``: pin-pink's weighted differential IK on a stack's tasks (a scenario controller).

pink (https://github.com/stephane-caron/pink) solves one QP per step::

    min_dq  1/2 sum_tasks ||W (J dq + alpha e)||^2 + damping/2 ||dq||^2   s.t.  G dq <= h (limits)

with dq = u dt (:func:`pink.solve_ik` returns u = dq / dt). Each level of the
stack becomes pink tasks with the cost (W) of its level, the limits level
becomes pink's limits (hard constraints):

====================  =========================================================
stack task            pink
====================  =========================================================
pose                  ``FrameTask(frame, position_cost=w_j, orientation_cost=w_j)``
position (xyz)        ``FrameTask(position_cost=w_j, orientation_cost=0)``, target
                      orientation: the frame's own at q (its error is then the
                      position error in the frame's axes)
orientation           ``FrameTask(position_cost=0, orientation_cost=w_j)``, target
                      position: the frame's own at q
com                   ``ComTask(cost)``: w_j on the task's axes, 0 on the others
posture (actuated)    ``PostureTask(cost=w_j)``
velocity (actuated)   ``DampingTask(cost=w_j)``; ``joints = "all"``: solve_ik's
                      ``damping`` (every coordinate) += w_j^2
joint_limits          ``ConfigurationLimit(model, config_limit_gain=lambda dt)``
                      (1 for the default lambda = 1/dt of eq. 48)
velocity_limits       ``VelocityLimit`` of a model copy whose ``velocityLimit`` is
                      the task's ``scale * v_max``
direction, alignment, no counterpart in pink: ControllerError naming the task
distance
====================  =========================================================

**Weights.** Level j counts the levels that hold a weighted task (0: the
highest of them); its cost is ``w_j = level_factor ** -j`` (``level_factor`` >= 1,
default :data:`LEVEL_FACTOR`), so each level weighs ``level_factor**2`` times the
next one in the objective.

**Gains.** pink's task dynamics are ``J dq = -alpha e`` (its ``gain`` alpha);
ours ``J u = -lambda e``: with dq = u dt they agree for ``alpha = lambda dt``.
pink's pose error is ``log6(T_b^-1 T*)`` with Jacobian ``-Jlog6(T*^-1 T_b) J_b``,
the negatives of :class:`~hikbench.problems.robots.tasks.PoseTask`'s, so
``J dq + alpha e = -dt (J u + lambda e)`` row by row (tests/bench/test_scenario_pink.py
checks every mapped task): the objective is ``dt^2/2 sum_j w_j^2 ||A_j u - b_j||^2``,
the weighted least squares of the hierarchy's equality rows. Two differences:
pink's tasks have no feed-forward ``e_dot_ff`` (a moving target is followed by
feedback alone, lagging it by about its speed / lambda), and the position task's
Jacobian is that of log6's linear part (rows off by a term of order ||e|| ||omega||).

Timing: :meth:`PinkController.prepare` (untimed) runs pink's forward kinematics
(``Configuration.update``) and sets the targets; the timed call is
``solve_ik``: the tasks' errors and Jacobians, the QP's assembly and its solve
through qpsolvers (``qp_solver``, default daqp). A hierarchy solver's timed call
leaves out the hierarchy's assembly (``Stack.hierarchy``).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pink
import qpsolvers
from pink.exceptions import NoSolutionFound, NotWithinConfigurationLimits
from pink.limits import ConfigurationLimit, VelocityLimit
from pink.tasks import ComTask, DampingTask, FrameTask, PostureTask
from pink.utils import get_root_joint_dim

from hikbench.bench.scenarios.controller import Controller, ControllerError
from hikbench.problems.hierarchy import Hierarchy
from hikbench.problems.robots import limits, tasks
from hikbench.problems.robots.stacks import Stack
from hikbench.solvers.base import ERROR, NUMERICAL_FAILURE, OPTIMAL, SolveResult
from hikbench.solvers.registry import check_choice, check_number

__all__ = ["DAMPING", "LEVEL_FACTOR", "PinkController", "level_costs"]

#: cost ratio of a level to the next (docs/robots.md, "pink": the reach scenario on talos
#: with factors 3 to 1000)
LEVEL_FACTOR = 10.0
DAMPING = 1e-12  #: solve_ik's Tikhonov damping, its default
_UNSUPPORTED = {tasks.DirectionTask: "direction", tasks.AlignmentTask: "alignment", limits.FrameDistance: "distance"}


def level_costs(stack: Stack, level_factor: float) -> list[float | None]:
    """Per level of ``stack``: the cost ``level_factor ** -j`` of its tasks, j counting
    the levels that hold a weighted (equality) task from 0; None for a level of limits only."""
    out, j = [], 0
    for level in stack.levels:
        if any(t.relation == "equality" for t in level):
            out.append(level_factor ** -j)
            j += 1
        else:
            out.append(None)
    return out


class PinkController(Controller):
    """pin-pink on the stack's tasks (module docstring)."""

    name = "pink"
    description = ("pin-pink: the stack's levels as tasks weighted level_factor^-j, limits as QP "
                   "constraints, one solve_ik per step (not strict)")
    strict = False

    def __init__(self, stack: Stack, level_factor: float = LEVEL_FACTOR, qp_solver: str = "daqp",
                 damping: float = DAMPING):
        super().__init__(stack)
        self.level_factor = check_number(self.name, "level_factor", level_factor, low=1.0)
        self.qp_solver = check_choice(self.name, "qp_solver", qp_solver, qpsolvers.available_solvers)
        self.damping = check_number(self.name, "damping", damping, low=0.0)
        self.dt = stack.dt
        robot = stack.robot
        self.model = robot.model
        root_nv = get_root_joint_dim(self.model)[1]
        if root_nv != (6 if robot.floating_base else 0):
            raise ControllerError(f"pink: robot {robot.name!r}: pink finds a floating base by its joint name "
                                  f"'root_joint'; expected the free flyer named so (its root joint is "
                                  f"{self.model.names[1]!r})")
        self.pairs: list[tuple[tasks.Task, object]] = []  # (stack task, pink task) with a target to copy
        self.pink_tasks: list = []
        self.limits: list = []
        for cost, level in zip(level_costs(stack, self.level_factor), stack.levels):
            for task in level:
                self._add(task, cost)
        self.configuration = pink.Configuration(self.model, self.model.createData(), robot.q0)

    def _add(self, task: tasks.Task, cost: float | None) -> None:
        """The pink counterpart of ``task`` at level cost ``cost`` (module docstring)."""
        kind = _UNSUPPORTED.get(type(task))
        if kind is not None:
            raise ControllerError(f"pink: task {task.name!r} of type {kind!r} has no counterpart in pink; expected "
                                  f"pose, position, orientation, com, posture, velocity, joint_limits or "
                                  f"velocity_limits tasks")
        if isinstance(task, limits.JointPositionLimits):
            self.limits.append(self._configuration_limit(task))
        elif isinstance(task, limits.JointVelocityLimits):
            self.limits.append(self._velocity_limit(task))
        elif isinstance(task, tasks.MinimalVelocityTask):
            if task.select.all() and self.stack.robot.floating_base:  # joints = "all"
                self.damping += cost ** 2
            else:
                self.pink_tasks.append(DampingTask(cost=cost))
        else:
            pt = self._task(task, cost)
            pt.gain = task.gain * self.dt
            self.pairs.append((task, pt))
            self.pink_tasks.append(pt)

    def _task(self, task: tasks.Task, cost: float):
        frame = self.model.frames[task.frame_id].name if hasattr(task, "frame_id") else None
        if isinstance(task, tasks.PoseTask):
            return FrameTask(frame, position_cost=cost, orientation_cost=cost)
        if isinstance(task, tasks.OrientationTask):
            return FrameTask(frame, position_cost=0.0, orientation_cost=cost)
        if isinstance(task, tasks.PositionTask):
            if list(task.axes) != [0, 1, 2]:
                raise ControllerError(f"pink: position task {task.name!r} on axes "
                                      f"{''.join('xyz'[i] for i in task.axes)!r}: pink's FrameTask weighs the "
                                      f"frame's axes, not the world's; expected axes = 'xyz'")
            return FrameTask(frame, position_cost=cost, orientation_cost=0.0)
        if isinstance(task, tasks.ComTask):
            return ComTask(cost=[cost if i in task.axes else 0.0 for i in range(3)])
        if isinstance(task, tasks.PostureTask):
            if self.stack.robot.floating_base and task.select.all():
                raise ControllerError(f"pink: posture task {task.name!r} with joints = 'all': pink's PostureTask "
                                      f"leaves out the floating base; expected joints = 'actuated'")
            return PostureTask(cost=cost)
        raise ControllerError(f"pink: task {task.name!r} of type {type(task).__name__} has no counterpart in pink")

    def _configuration_limit(self, task: limits.JointPositionLimits) -> ConfigurationLimit:
        gain = 1.0 if task.gain_is_one_over_dt else task.gain * self.dt  # lambda dt
        if not 0.0 < gain <= 1.0:
            raise ControllerError(f"pink: task {task.name!r}: gain x dt = {gain:g}; pink's config_limit_gain "
                                  f"is in (0, 1]: expected a gain <= 1/dt = {1 / self.dt:g}")
        limit = ConfigurationLimit(self.model, config_limit_gain=gain)
        self._same_joints(limit, task.select, task.name)
        return limit

    def _velocity_limit(self, task: limits.JointVelocityLimits) -> VelocityLimit:
        model = pin.Model(self.model)  # (a copy: pink reads the bounds from model.velocityLimit)
        vmax = np.zeros(model.nv)
        vmax[task.select] = task.vmax
        model.velocityLimit = vmax
        limit = VelocityLimit(model)
        self._same_joints(limit, task.select, task.name)
        return limit

    def _same_joints(self, limit, select: np.ndarray, name: str) -> None:
        """pink's limit bounds the coordinates the stack's task bounds (ControllerError otherwise)."""
        ours = np.flatnonzero(select)
        if not np.array_equal(np.sort(np.asarray(limit.indices, dtype=int)), ours):
            diff = sorted(set(ours) ^ set(np.asarray(limit.indices, dtype=int).tolist()))
            raise ControllerError(f"pink: task {name!r}: pink's {type(limit).__name__} bounds other coordinates "
                                  f"than the stack's (they differ at tangent indices {diff})")

    def prepare(self, q: np.ndarray) -> None:
        """Forward kinematics at q and the stack's targets of the step (position and
        orientation tasks take the frame's own orientation / position at q)."""
        conf = self.configuration
        conf.update(q)
        for task, pt in self.pairs:
            if isinstance(task, tasks.PoseTask):
                pt.set_target(task.target)
            elif isinstance(task, tasks.OrientationTask):
                pt.set_target(pin.SE3(task.target, conf.get_transform_frame_to_world(pt.frame).translation))
            elif isinstance(task, tasks.PositionTask):
                pt.set_target(pin.SE3(conf.get_transform_frame_to_world(pt.frame).rotation, task.target))
            else:  # com, posture
                pt.set_target(np.asarray(task.target, dtype=float))

    def solve(self, hierarchy: Hierarchy) -> SolveResult:
        """``pink.solve_ik`` at the prepared configuration: u, shape (nv,)."""
        try:
            u = pink.solve_ik(self.configuration, self.pink_tasks, self.dt, solver=self.qp_solver,
                              damping=self.damping, limits=self.limits)
        except NoSolutionFound as err:
            return SolveResult(None, NUMERICAL_FAILURE, reason=f"pink: {err} (qp_solver {self.qp_solver})")
        except NotWithinConfigurationLimits as err:
            return SolveResult(None, ERROR, reason=f"pink: {err}")
        return SolveResult(np.asarray(u, dtype=float), OPTIMAL)
