"""Robot models from example-robot-data or a user's URDF, loaded through pinocchio
once per process.

A :class:`Robot` bundles the pinocchio model, its nominal configuration ``q0``
(half-sitting for the humanoids), task-frame aliases (``right_hand``,
``left_foot``, ...) so that stacks are written once for several robots, and the
tangent-space mask of the joints that have position limits (1-DOF joints with
finite limits; the free flyer and continuous joints are unbounded).

A robot is named by a curated name (:data:`ROBOTS`, with their aliases), any
other example-robot-data name, or a URDF path (``*.urdf``, or a
:class:`~hikbench.problems.robots.urdf.UrdfSource` with an SRDF and the root
joint: :mod:`hikbench.problems.robots.urdf`). Robots without curated aliases get
the aliases their link names match (:mod:`hikbench.problems.robots.frames`);
a ``[frames]`` table of a stack or scenario file (:class:`FrameTable`) adds or
replaces aliases.
"""

from __future__ import annotations

import dataclasses
import difflib
import functools
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin

from hikbench.problems.errors import HikbenchError
from hikbench.problems.robots.frames import ALIAS_RULES, find_frames
from hikbench.problems.robots.urdf import RobotFileError, UrdfSource, is_urdf_path, load_urdf

__all__ = [
    "ROBOTS",
    "FrameNotFoundError",
    "FrameTable",
    "Robot",
    "RobotFileError",
    "RobotNotFoundError",
    "RobotSpec",
    "UrdfSource",
    "load_robot",
    "robot_source",
    "robot_names",
    "same_robot",
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


@dataclass(frozen=True)
class FrameTable:
    """Aliases a file gives (alias -> frame name of the model), with where they were
    written for errors: ``source`` (a file, or ``--frame``) and ``key`` (``frames``)."""

    names: dict
    source: str
    key: str = "frames"

    def place(self, alias: str, frame) -> str:
        """``FILE: frames.ALIAS = 'FRAME'`` (``--frame ALIAS=FRAME`` for the command line)."""
        return f"{self.source}: {self.key}.{alias} = {frame!r}" if self.key else f"{self.source} {alias}={frame}"


#: aliases that a frame table can set for a robot that lacks them (shipped stacks use these)
KNOWN_ALIASES = (*ALIAS_RULES, "base", "fl_foot", "fr_foot", "hl_foot", "hr_foot")


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

    def has_frame(self, name: str) -> bool:
        """``name`` is an alias of this robot or one of its pinocchio frame names."""
        return self.model.existFrame(self.frames.get(name, name))

    def frame_choices(self, name: str) -> str:
        """What a frame name of this robot can be, with the close matches of ``name``
        and, for a known alias it lacks, the key that sets it (for one-line errors)."""
        aliases = ", ".join(sorted(self.frames)) or "none"
        names = [f.name for f in self.model.frames]
        close = difflib.get_close_matches(name, [*self.frames, *names], n=3, cutoff=0.6)
        text = (f"an alias of robot {self.name!r} ({aliases}) or one of its {len(names)} pinocchio frame names"
                + (f" (did you mean {' or '.join(map(repr, close))}?)" if close else
                   f": {', '.join(names)}" if len(names) <= 60 else ""))
        if name in KNOWN_ALIASES:
            text += (f"; to name the {name} frame, set frames.{name} = \"<frame name>\" in the stack or scenario "
                     f"file (or --frame {name}=FRAME)")
        return text

    def frame_name(self, name: str) -> str:
        """Resolve an alias (``right_hand``) or check a raw frame name."""
        frame = self.frames.get(name, name)
        if not self.model.existFrame(frame):
            raise FrameNotFoundError(f"robot {self.name!r} has no frame {name!r}; "
                                     f"expected {self.frame_choices(name)}")
        return frame

    def with_frames(self, *tables: FrameTable) -> Robot:
        """This robot with the aliases of ``tables`` added (later tables win); each
        value must be a pinocchio frame name of the model (FrameNotFoundError naming
        the table's file and key otherwise)."""
        frames = dict(self.frames)
        for table in tables:
            for alias, frame in table.names.items():
                if not isinstance(frame, str) or not self.model.existFrame(frame):
                    names = [f.name for f in self.model.frames]
                    close = difflib.get_close_matches(str(frame), names, n=3, cutoff=0.6)
                    raise FrameNotFoundError(
                        f"{table.place(alias, frame)}: expected a pinocchio frame name of robot {self.name!r}"
                        + (f" (did you mean {' or '.join(map(repr, close))}?)" if close else
                           f" ({', '.join(names)})" if len(names) <= 60 else
                           f" (one of its {len(names)} frames)"))
                frames[alias] = frame
        if frames == self.frames:
            return self
        return dataclasses.replace(self, frames=frames)

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


def robot_source(ref, srdf=None, floating_base: bool | None = None, reference: str | None = None,
                 base: str | os.PathLike | None = None):
    """A robot reference as :func:`load_robot` takes it: a robot name stays a name; a
    URDF path (``*.urdf``) becomes a :class:`UrdfSource` with ``srdf``,
    ``floating_base`` and ``reference``, its relative paths taken from the folder
    ``base`` (a TOML file's folder; default: the working directory). SRDF options
    with a robot name are an error."""
    if isinstance(ref, UrdfSource):
        return ref
    here = Path(base) if base is not None else Path.cwd()
    if not is_urdf_path(ref):
        given = [k for k, v in (("srdf", srdf), ("floating_base", floating_base), ("reference", reference))
                 if v is not None]
        if given:
            verb = "applies" if len(given) == 1 else "apply"
            raise RobotFileError(f"robot {ref!r}: {', '.join(given)} {verb} to a URDF robot only; expected robot "
                                 "to be the path of a .urdf file")
        return ref
    if srdf is None and reference is not None:
        raise RobotFileError(f"robot {ref!r}: reference = {reference!r} names an SRDF group_state; expected an "
                             "srdf as well")
    return UrdfSource(urdf=(here / Path(ref)).resolve(),
                      srdf=None if srdf is None else (here / Path(srdf)).resolve(),
                      floating_base=floating_base, reference=reference)


def same_robot(a, b) -> bool:
    """Whether two robot references (names, URDF paths or UrdfSources, as
    :func:`robot_source` takes them) load their model from the same place: the same
    robot name, or the same URDF file (its SRDF and root joint aside: the frames, which
    a ``[frames]`` table names, are the URDF's links)."""
    if a is None or b is None:
        return False
    a, b = robot_source(a), robot_source(b)
    if isinstance(a, UrdfSource) and isinstance(b, UrdfSource):
        return a.urdf.resolve() == b.urdf.resolve()
    return not isinstance(a, UrdfSource) and not isinstance(b, UrdfSource) and a == b


def load_robot(ref) -> Robot:
    """Load a robot (once per process for a given reference).

    ``ref`` is one of :data:`ROBOTS`, any example-robot-data robot, a URDF path
    (``*.urdf``, relative to the working directory) or a :class:`UrdfSource`;
    raises :class:`RobotNotFoundError` naming what is available for an unknown
    name and :class:`RobotFileError` naming the file for a bad URDF or SRDF."""
    return _load(robot_source(ref))


@functools.cache
def _load(ref) -> Robot:
    if isinstance(ref, UrdfSource):
        loaded = load_urdf(ref)
        model = loaded.model
        return Robot(name=ref.name, model=model, q0=loaded.q0, frames=find_frames(model),
                     bounded=_bounded_mask(model), floating_base=loaded.floating_base,
                     description=loaded.description)
    return _load_erd(ref)


def _load_erd(name: str) -> Robot:
    """An example-robot-data robot: curated aliases, or those its link names match."""
    import example_robot_data

    spec = ROBOTS.get(name, RobotSpec(name, f"example-robot-data {name}"))
    available = _erd_names()
    if spec.loader not in available:
        raise RobotNotFoundError(
            f"robot {name!r} is not in the installed example-robot-data "
            f"(curated: {', '.join(ROBOTS)}; available: {', '.join(available)}; or the path of a .urdf file)")
    wrapper = example_robot_data.load(spec.loader)
    model = wrapper.model
    q0 = np.array(wrapper.q0, dtype=float) if wrapper.q0 is not None else pin.neutral(model)
    floating = model.njoints > 1 and model.joints[1].shortname() == "JointModelFreeFlyer"
    frames = dict(spec.frames) if name in ROBOTS else find_frames(model)
    return Robot(name=name, model=model, q0=q0, frames=frames, bounded=_bounded_mask(model),
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
