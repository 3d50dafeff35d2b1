"""Every task Jacobian against central finite differences along pin.integrate.

d/dt e(q (+) t v) at t = 0 is estimated by (e(q (+) h v) - e(q (+) -h v)) / 2h with
h = 1e-6 on seeded random configurations within the limits; the tolerance
covers the O(h^2) truncation and round-off of values of order 1."""

import numpy as np
import pinocchio as pin
import pytest

from hikbench.problems.robots.kinematics import KinematicState
from hikbench.problems.robots.limits import FrameDistance, JointPositionLimits
from hikbench.problems.robots.tasks import (
    AlignmentTask,
    ComTask,
    DirectionTask,
    OrientationTask,
    PoseTask,
    PositionTask,
    PostureTask,
)

H = 1e-6
RTOL, ATOL = 1e-5, 1e-6
SEEDS = [0, 1, 2]
ROBOTS = ["talos", "panda", "romeo"]
HAND = {"talos": "right_hand", "panda": "ee", "romeo": "right_hand"}
OTHER = {"talos": "left_hand", "panda": "panda_link3", "romeo": "left_hand"}


def make_tasks(robot, target_state):
    """One task of each kinematic family, targets taken at another configuration."""
    hand, other = HAND[robot.name], OTHER[robot.name]
    tasks = [
        PositionTask(robot, "position", hand),
        PositionTask(robot, "position_xz", hand, axes="xz"),
        OrientationTask(robot, "orientation", hand),
        PoseTask(robot, "pose", hand),
        DirectionTask(robot, "direction", hand, vector=(1.0, 0.0, 0.0)),
        AlignmentTask(robot, "alignment", hand, vector=(0.0, 0.0, 1.0), reference=(0.3, -0.2, 0.9)),
        ComTask(robot, "com"),
        ComTask(robot, "com_xy", axes="xy"),
        PostureTask(robot, "posture"),
        PostureTask(robot, "posture_all", joints="all"),
        JointPositionLimits(robot),
        FrameDistance(robot, "distance", hand, other, d_min=0.05),
    ]
    for t in tasks:
        t.set_target_from(target_state)
    return tasks


def _cases():
    return [pytest.param(r, s, id=f"{r}-seed{s}") for r in ROBOTS for s in SEEDS]


@pytest.mark.parametrize("robot_name,seed", _cases())
def test_jacobian_matches_finite_differences(robot_name, seed):
    from hikbench.problems.robots.models import load_robot

    robot = load_robot(robot_name)
    rng = np.random.default_rng(seed)
    q = robot.random_configuration(rng)
    target = KinematicState(robot, robot.random_configuration(rng))
    tasks = make_tasks(robot, target)
    state = KinematicState(robot, q)
    for _ in range(3):
        v = rng.normal(size=robot.nv)
        qp = pin.integrate(robot.model, q, H * v)
        qm = pin.integrate(robot.model, q, -H * v)
        sp, sm = KinematicState(robot, qp), KinematicState(robot, qm)
        for task in tasks:
            fd = (task.value(sp) - task.value(sm)) / (2 * H)
            J = task.jacobian(state)
            assert J.shape == (len(task.value(state)), robot.nv), task.name
            np.testing.assert_allclose(J @ v, fd, rtol=RTOL, atol=ATOL * (1 + np.linalg.norm(v)),
                                       err_msg=f"{robot_name} seed {seed} task {task.name}")


@pytest.mark.parametrize("robot_name", ROBOTS)
def test_pose_feedforward_cancels_a_moving_target(robot_name):
    """e(q, T*) with T* moving at body velocity nu*: the rate -J_log Ad(M^-1) nu* at u = 0
    is what feedforward() returns with the sign flipped (FD on the target)."""
    from hikbench.problems.robots.models import load_robot

    robot = load_robot(robot_name)
    rng = np.random.default_rng(7)
    state = KinematicState(robot, robot.random_configuration(rng))
    task = PoseTask(robot, "pose", HAND[robot_name])
    task.set_target_from(KinematicState(robot, robot.random_configuration(rng)))
    nu = rng.normal(size=6)
    T0 = task.target
    task.target = T0 * pin.exp6(pin.Motion(H * nu))
    ep = task.value(state)
    task.target = T0 * pin.exp6(pin.Motion(-H * nu))
    em = task.value(state)
    task.target = T0
    task.target_velocity = nu
    np.testing.assert_allclose(task.feedforward(state), -(ep - em) / (2 * H), rtol=1e-5, atol=1e-6)


def test_rows_follow_eq47(talos):
    """Equality rows are J u = -lambda e (eq. 47)."""
    rng = np.random.default_rng(3)
    state = KinematicState(talos, talos.random_configuration(rng))
    task = ComTask(talos, "com", gain=2.5)
    task.set_target_from(KinematicState(talos, talos.random_configuration(rng)))
    A, lo, up = task.rows(state, dt=0.01)
    np.testing.assert_allclose(A, state.com_jacobian, rtol=0, atol=0)
    np.testing.assert_allclose(lo, -2.5 * task.value(state), rtol=1e-15, atol=0)
    np.testing.assert_array_equal(lo, up)


def test_joint_limit_rows_follow_eq48(talos):
    """q_l - q <= u dt <= q_u - q on the bounded coordinates; the free flyer is unbounded."""
    rng = np.random.default_rng(4)
    q = talos.random_configuration(rng)
    task = JointPositionLimits(talos)
    dt = 0.005
    A, lo, up = task.rows(KinematicState(talos, q), dt)
    assert not talos.bounded[:6].any() and talos.bounded[6:].all()
    assert A.shape == (talos.nv - 6, talos.nv)
    qb = q[talos.bounded_q]
    np.testing.assert_allclose(lo * dt, talos.lower - qb, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(up * dt, talos.upper - qb, rtol=1e-12, atol=1e-15)
    # one step at either bound lands exactly on the limit
    u = np.zeros(talos.nv)
    u[talos.bounded] = up
    np.testing.assert_allclose(pin.integrate(talos.model, q, u * dt)[talos.bounded_q], talos.upper,
                               rtol=0, atol=1e-12)
