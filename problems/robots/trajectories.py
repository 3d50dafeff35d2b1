"""Sixth-order polynomial trajectories (Boutin et al., sec. III-B/C).

Between two instants a coordinate follows a polynomial of degree 6; its seven
coefficients are fixed by position, velocity and acceleration at both ends
(continuity of position, velocity and acceleration across phases) and one via
point (the apex of a swing foot). On tau = (t - t0) / T in [0, 1]::

    p(tau) = sum_{i=0..6} c_i tau^i,  p(0) = p0, p(1) = p1, p'(0) = p'(1) = 0,
                                      p''(0) = p''(1) = 0,  p(tau_via) = p_via

A 6D segment moves a frame from placement T0 to T1 with a progress s(tau)
(from 0 to 1 through s(1/2) = 1/2) and an apex bump b(tau) (from 0 to 1 at
tau_apex and back to 0)::

    p(t) = p0 + s (p1 - p0) + b h,      R(t) = R0 exp(s log(R0^T R1))
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from hikbench.problems.errors import HikbenchError

__all__ = ["PointSegment", "Polynomial", "PoseSegment", "TrajectoryError", "bump", "progress", "sixth_order"]


class TrajectoryError(HikbenchError, ValueError):
    """A trajectory with bad times or via point."""


@dataclass(frozen=True)
class Polynomial:
    """Coefficients c_0..c_6 on tau in [0, 1] (scalar) and its end values
    ``p(0), p(1)`` as given (the solved coefficients meet them only to
    rounding, which differs between CPUs: sum(c) read 1 - 1.8e-15 on an
    AVX-512 machine for a progress ending at 1)."""

    c: np.ndarray
    p0: float
    p1: float

    def __call__(self, tau: float, derivative: int = 0) -> float:
        """d^k p / d tau^k at tau; outside (0, 1) the end value, exactly, and
        zero derivatives (constant outside)."""
        if tau <= 0.0 or tau >= 1.0:
            return 0.0 if derivative else (self.p0 if tau <= 0.0 else self.p1)
        c = np.polynomial.polynomial.polyder(self.c, derivative) if derivative else self.c
        return float(np.polynomial.polynomial.polyval(tau, c))


def sixth_order(p0: float, p1: float, tau_via: float, p_via: float) -> Polynomial:
    """The degree-6 polynomial with zero end velocities and accelerations through p_via."""
    if not 0.0 < tau_via < 1.0:
        raise TrajectoryError(f"the via point must be strictly inside (0, 1); got tau_via={tau_via}")
    M = np.zeros((7, 7))
    powers = np.arange(7)
    M[0, 0] = 1.0                        # p(0)
    M[1, 1] = 1.0                        # p'(0)
    M[2, 2] = 2.0                        # p''(0)
    M[3] = 1.0                           # p(1)
    M[4] = powers                        # p'(1)
    M[5] = powers * (powers - 1)         # p''(1)
    M[6] = tau_via ** powers             # p(tau_via)
    return Polynomial(np.linalg.solve(M, [p0, 0.0, 0.0, p1, 0.0, 0.0, p_via]), float(p0), float(p1))


def progress() -> Polynomial:
    """s: 0 -> 1 through s(1/2) = 1/2."""
    return sixth_order(0.0, 1.0, 0.5, 0.5)


def bump(tau_apex: float = 0.5) -> Polynomial:
    """b: 0 -> 1 at tau_apex -> 0."""
    return sixth_order(0.0, 0.0, tau_apex, 1.0)


@dataclass(frozen=True)
class PoseSegment:
    """A frame moving from T0 to T1 over [t0, t0 + duration] with an apex offset ``apex``
    (world, m) reached at ``tau_apex``; constant before and after."""

    t0: float
    duration: float
    T0: pin.SE3
    T1: pin.SE3
    apex: np.ndarray = None
    tau_apex: float = 0.5

    def __post_init__(self):
        if not self.duration > 0:
            raise TrajectoryError(f"duration must be > 0 s; got {self.duration}")
        object.__setattr__(self, "apex", np.zeros(3) if self.apex is None else np.asarray(self.apex, float))

    def __call__(self, t: float) -> tuple[pin.SE3, np.ndarray]:
        """Placement at t and its body velocity (shape (6,): linear, angular, frame axes)."""
        tau = (t - self.t0) / self.duration
        s, b = progress(), bump(self.tau_apex)
        w = np.array(pin.log3(self.T0.rotation.T @ self.T1.rotation))
        R = self.T0.rotation @ pin.exp3(s(tau) * w)
        p = self.T0.translation + s(tau) * (self.T1.translation - self.T0.translation) + b(tau) * self.apex
        ds, db = s(tau, 1) / self.duration, b(tau, 1) / self.duration
        v_world = ds * (self.T1.translation - self.T0.translation) + db * self.apex
        omega_world = self.T0.rotation @ (ds * w)  # exp3 about a fixed axis: omega = R0 w ds
        nu = np.concatenate([R.T @ v_world, R.T @ omega_world])
        return pin.SE3(R, p), nu


@dataclass(frozen=True)
class PointSegment:
    """A point (e.g. the CoM) from p0 to p1 over [t0, t0 + duration]: p(t), p_dot(t) (world)."""

    t0: float
    duration: float
    p0: np.ndarray
    p1: np.ndarray

    def __post_init__(self):
        if not self.duration > 0:
            raise TrajectoryError(f"duration must be > 0 s; got {self.duration}")

    def __call__(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        tau = (t - self.t0) / self.duration
        s = progress()
        d = np.asarray(self.p1, float) - np.asarray(self.p0, float)
        return np.asarray(self.p0, float) + s(tau) * d, s(tau, 1) / self.duration * d
