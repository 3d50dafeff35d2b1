"""Robot models from example-robot-data, loaded through pinocchio once per process.

A :class:`Robot` bundles the pinocchio model, its nominal configuration ``q0``
(half-sitting for the humanoids), task-frame aliases (``right_hand``,
``left_foot``, ...) so that stacks are written once for several robots, and the
tangent-space mask of the joints that have position limits (1-DOF joints with
finite limits; the free flyer and continuous joints are unbounded).
"""

from __future__ import annotations

import difflib
import functools
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from hikbench.problems.errors import HikbenchError

__all__ = [
    "ROBOTS",
    "FrameNotFoundError",
    "Robot",
    "RobotNotFoundError",
    "RobotSpec",
    "load_robot",
    "robot_names",
    "robot_rows",
]

_HUGE = 1e10  #: limits beyond this magnitude count as "no limit" (URDF free flyers use +-DBL_MAX)


class RobotNotFoundError(HikbenchError, KeyError):
    """A robot name that neither hikbench nor example-robot-data knows."""

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""


class FrameNotFoundError(HikbenchError, KeyError):
    """A frame name or alias the robot does not have."""

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""


@dataclass(frozen=True)
class RobotSpec:
    """How to load one robot: its example-robot-data name and frame aliases."""

    loader: str
    description: str
    frames: dict[str, str] = field(default_factory=dict)


#: The curated robots; any other example-robot-data name also loads (without aliases).
ROBOTS: dict[str, RobotSpec] = {
    "talos": RobotSpec("talos", "PAL Talos humanoid (the HRP-2 analogue of ICRA 2010 sec. XII)", {
        "right_hand": "gripper_right_base_link", "left_hand": "gripper_left_base_link",
        "right_foot": "right_sole_link", "left_foot": "left_sole_link", "base": "base_link",
        "head": "head_2_link", "torso": "torso_2_link"}),
    "romeo": RobotSpec("romeo", "Aldebaran Romeo humanoid", {
        "right_hand": "r_wrist", "left_hand": "l_wrist", "right_foot": "r_sole", "left_foot": "l_sole",
        "base": "body"}),
    "g1": RobotSpec("g1", "Unitree G1 humanoid", {
        "right_hand": "right_rubber_hand", "left_hand": "left_rubber_hand",
        "right_foot": "right_ankle_roll_link", "left_foot": "left_ankle_roll_link", "base": "pelvis"}),
    "tiago": RobotSpec("tiago", "PAL TIAGo mobile manipulator (torso, arm, head, hand)", {
        "ee": "hand_grasping_frame", "right_hand": "hand_grasping_frame", "base": "base_footprint"}),
    "panda": RobotSpec("panda", "Franka Emika Panda arm with gripper", {"ee": "panda_hand_tcp",
                                                                        "base": "panda_link0"}),
    "ur5": RobotSpec("ur5", "Universal Robots UR5 arm", {"ee": "tool0", "base": "base_link"}),
    "solo12": RobotSpec("solo12", "ODRI Solo-12 quadruped", {
        "fl_foot": "FL_FOOT", "fr_foot": "FR_FOOT", "hl_foot": "HL_FOOT", "hr_foot": "HR_FOOT",
        "base": "base_link"}),
}


@dataclass(frozen=True, eq=False)
class Robot:
    """A loaded robot.

    Attributes
    ----------
    name : str
    model : pinocchio.Model
        nq configuration coordinates, nv velocity (tangent) coordinates.
    q0 : ndarray, shape (nq,)
        Nominal configuration (example-robot-data ``q0``; half-sitting for humanoids).
    frames : dict
        Alias -> frame name.
    bounded : ndarray of bool, shape (nv,)
        Tangent coordinates of 1-DOF joints with finite position limits (eq. 48 applies).
    floating_base : bool
        The root joint is a free flyer.
    """

    name: str
    model: pin.Model
    q0: np.ndarray
    frames: dict[str, str]
    bounded: np.ndarray
    floating_base: bool
    description: str = ""

    @property
    def nq(self) -> int:
        return int(self.model.nq)

    @property
    def nv(self) -> int:
        return int(self.model.nv)

    @functools.cached_property
    def bounded_q(self) -> np.ndarray:
        """Configuration indices of the bounded coordinates, shape (nb,), same order as ``bounded``."""
        return np.array(self._bounded_pairs[0], dtype=int)

    @functools.cached_property
    def bounded_joint_names(self) -> list[str]:
        """Names of the joints of the bounded coordinates, same order as ``bounded_q``."""
        return self._bounded_pairs[2]

    @functools.cached_property
    def _bounded_pairs(self) -> tuple[list[int], list[int], list[str]]:
        iq, iv, names = [], [], []
        for j in range(1, self.model.njoints):
            joint = self.model.joints[j]
            if joint.nv == 1 and joint.nq == 1 and self.bounded[joint.idx_v]:
                iq.append(joint.idx_q)
                iv.append(joint.idx_v)
                names.append(self.model.names[j])
        return iq, iv, names

    @property
    def lower(self) -> np.ndarray:
        """Lower position limits of the bounded coordinates, shape (nb,)."""
        return np.asarray(self.model.lowerPositionLimit)[self.bounded_q]

    @property
    def upper(self) -> np.ndarray:
        """Upper position limits of the bounded coordinates, shape (nb,)."""
        return np.asarray(self.model.upperPositionLimit)[self.bounded_q]

    @functools.cached_property
    def actuated(self) -> np.ndarray:
        """Tangent mask of the joint coordinates (everything but a free-flyer root), shape (nv,)."""
        mask = np.ones(self.nv, dtype=bool)
        if self.floating_base:
            mask[:6] = False
        return mask

    def frame_name(self, name: str) -> str:
        """Resolve an alias (``right_hand``) or check a raw frame name."""
        frame = self.frames.get(name, name)
        if not self.model.existFrame(frame):
            aliases = ", ".join(sorted(self.frames)) or "none"
            names = [f.name for f in self.model.frames]
            close = difflib.get_close_matches(name, names, n=5, cutoff=0.6)
            raise FrameNotFoundError(f"robot {self.name!r} has no frame {name!r} (aliases: {aliases}; "
                                     f"or any of its {len(names)} pinocchio frame names"
                                     + (f", e.g. {', '.join(close)}" if close else
                                        f": {', '.join(names)}" if len(names) <= 60 else "") + ")")
        return frame

    def frame_id(self, name: str) -> int:
        return int(self.model.getFrameId(self.frame_name(name)))

    def random_configuration(self, rng: np.random.Generator, margin: float = 0.02,
                             base_scale: float = 0.1) -> np.ndarray:
        """A random configuration within the limits, shape (nq,).

        Bounded coordinates are uniform in ``[lo + margin (hi - lo), hi - margin (hi - lo)]``;
        the other joints (free flyer, continuous) are ``q0`` integrated along a random
        tangent of standard deviation ``base_scale`` (m or rad)."""
        q = self.q0.copy()
        lo, hi = self.lower, self.upper
        width = hi - lo
        q[self.bounded_q] = rng.uniform(lo + margin * width, hi - margin * width)
        free = ~self.bounded
        if free.any():
            v = np.zeros(self.nv)
            v[free] = rng.normal(scale=base_scale, size=int(free.sum()))
            q = pin.integrate(self.model, q, v)
        return q

    def limit_margin(self, q: np.ndarray) -> np.ndarray:
        """Distance to the nearest limit of each bounded coordinate, ``min(q - lo, hi - q)``,
        shape (nb,) (rad or m; negative when violated)."""
        qb = np.asarray(q)[self.bounded_q]
        return np.minimum(qb - self.lower, self.upper - qb)


def _bounded_mask(model: pin.Model) -> np.ndarray:
    mask = np.zeros(model.nv, dtype=bool)
    lo, hi = np.asarray(model.lowerPositionLimit), np.asarray(model.upperPositionLimit)
    for j in range(1, model.njoints):
        joint = model.joints[j]
        if joint.nq == 1 and joint.nv == 1:
            a, b = lo[joint.idx_q], hi[joint.idx_q]
            if np.isfinite(a) and np.isfinite(b) and abs(a) < _HUGE and abs(b) < _HUGE and a < b:
                mask[joint.idx_v] = True
    return mask


def _erd_names() -> list[str]:
    import example_robot_data

    return sorted(example_robot_data.ROBOTS)


@functools.cache
def load_robot(name: str) -> Robot:
    """Load a robot by name (once per process).

    ``name`` is one of :data:`ROBOTS` or any example-robot-data robot; raises
    :class:`RobotNotFoundError` naming what is available otherwise."""
    import example_robot_data

    spec = ROBOTS.get(name, RobotSpec(name, f"example-robot-data {name}"))
    available = _erd_names()
    if spec.loader not in available:
        raise RobotNotFoundError(
            f"robot {name!r} is not in the installed example-robot-data "
            f"(curated: {', '.join(ROBOTS)}; available: {', '.join(available)})")
    wrapper = example_robot_data.load(spec.loader)
    model = wrapper.model
    q0 = np.array(wrapper.q0, dtype=float) if wrapper.q0 is not None else pin.neutral(model)
    floating = model.njoints > 1 and model.joints[1].shortname() == "JointModelFreeFlyer"
    return Robot(name=name, model=model, q0=q0, frames=dict(spec.frames), bounded=_bounded_mask(model),
                 floating_base=floating, description=spec.description)


def robot_names() -> list[str]:
    """The curated robot names."""
    return list(ROBOTS)


def robot_rows() -> list[tuple[str, str]]:
    """Rows for ``hikbench list robots``: name, then nq, nv and the description."""
    rows = []
    available = set(_erd_names())
    for name, spec in ROBOTS.items():
        if spec.loader not in available:
            rows.append((name, f"(not in the installed example-robot-data) {spec.description}"))
            continue
        r = load_robot(name)
        rows.append((name, (f"nq={r.nq:<3d} nv={r.nv:<3d} bounded={int(r.bounded.sum()):<3d} "
                            f"{'free-flyer ' if r.floating_base else ''}{spec.description}")))
    return rows
