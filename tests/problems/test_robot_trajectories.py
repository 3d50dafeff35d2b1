"""Sixth-order polynomial trajectories (Boutin et al.): end conditions, via point, continuity."""

import numpy as np
import pinocchio as pin
import pytest

from hikbench.problems.robots.trajectories import (
    PointSegment,
    PoseSegment,
    TrajectoryError,
    bump,
    progress,
    sixth_order,
)


@pytest.mark.parametrize("p0,p1,tau,pv", [(0.0, 1.0, 0.5, 0.5), (0.0, 0.0, 0.3, 1.0), (2.0, -1.0, 0.7, 0.4)],
                         ids=["progress", "bump-0.3", "generic"])
def test_sixth_order_meets_its_seven_conditions(p0, p1, tau, pv):
    p = sixth_order(p0, p1, tau, pv)
    np.testing.assert_allclose([p(0.0), p(1.0), p(tau)], [p0, p1, pv], atol=1e-12)
    for k in (1, 2):  # zero velocity and acceleration at both ends (evaluated just inside)
        np.testing.assert_allclose([p(1e-9, k), p(1 - 1e-9, k)], [0.0, 0.0], atol=1e-6)


def test_progress_and_bump_shapes():
    assert progress()(0.5) == pytest.approx(0.5, rel=1e-12)
    b = bump(0.5)
    assert b(0.5) == pytest.approx(1.0, rel=1e-12) and max(b(t) for t in np.linspace(0, 1, 101)) == pytest.approx(
        1.0, rel=1e-12)


def test_via_point_must_be_inside():
    with pytest.raises(TrajectoryError, match="strictly inside"):
        sixth_order(0.0, 1.0, 1.0, 0.5)


def test_pose_segment_velocity_matches_finite_differences():
    T0 = pin.SE3(pin.rpy.rpyToMatrix(0.1, -0.2, 0.3), np.array([0.0, -0.1, 0.0]))
    T1 = pin.SE3(T0.rotation @ pin.rpy.rpyToMatrix(0.0, 0.0, 0.4), np.array([0.2, -0.1, 0.0]))
    seg = PoseSegment(1.0, 2.0, T0, T1, apex=np.array([0.0, 0.0, 0.05]), tau_apex=0.4)
    assert seg(1.0)[0].isApprox(T0) and seg(3.0)[0].isApprox(T1)
    assert seg(1.8)[0].translation[2] == pytest.approx(0.05, rel=1e-12)  # apex at tau = 0.4
    h = 1e-6
    for t in (1.3, 1.9, 2.6):
        Tm, nu = seg(t)
        fd = pin.log6(Tm.actInv(seg(t + h)[0])).vector / h  # body velocity
        np.testing.assert_allclose(nu, fd, rtol=1e-4, atol=1e-5)


def test_point_segment_is_constant_outside_its_interval():
    seg = PointSegment(0.5, 1.0, np.zeros(3), np.ones(3))
    np.testing.assert_array_equal(seg(0.0)[0], 0.0)  # (exactly: the end points, not evaluated)
    np.testing.assert_array_equal(seg(2.0)[0], 1.0)
    np.testing.assert_array_equal(seg(2.0)[1], 0.0)
