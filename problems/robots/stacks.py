"""Stacks of tasks: a robot, ordered levels of tasks, gains and dt, read from TOML,
that turn a configuration q into a :class:`~hikbench.problems.hierarchy.Hierarchy` in the
velocity u (n = nv). Level names are the task names (``"+"``-joined when a level
holds several tasks).

TOML format (``problems/robots/stacks/*.toml``)::

    name = "humanoid_reach"
    robot = "talos"          # overridable: any robot with the aliases used below
    dt = 0.02                # control period, s
    # robot = "my_robot.urdf"  (relative to this file), with optional
    # srdf = "my_robot.srdf", floating_base = true, reference = "half_sitting"
    # [frames]               # aliases of this file's robot: alias = frame name
    # right_hand = "r_wrist_link"
    [[levels]]               # level 0 = highest priority
    tasks = [{ type = "joint_limits" }, { type = "velocity_limits", scale = 1.0 }]
    [[levels]]
    tasks = [{ type = "com", gain = 5.0 }]
    [[levels]]
    tasks = [{ type = "pose", name = "right_hand", frame = "right_hand", gain = 5.0 }]

Task types: see :data:`TASK_TYPES`; keys other than ``type`` and ``name`` are the
constructor arguments of the task class. ``dt`` defaults to 0.01 s. A target
given in the file is kept (``position`` / ``com``: ``[x, y, z]``; ``orientation``:
``{ rpy = [r, p, y] }`` or a 3x3 matrix; ``pose``: ``{ position = [...], rpy = [...] }``;
``posture``: nq numbers); the other targets are the values at the robot's
nominal configuration q0 (and :meth:`Stack.set_targets_from` moves only those).
A level is a table with ``tasks`` and an optional ``name``; levels come in file
order, level 0 first.

A frame a task names (``frame``, ``frame_a``, ``frame_b``) must be an alias of
the robot or one of its frame names: a StackError names the file, the key
(``levels[3].tasks[0].frame``) and the close matches. The ``[frames]`` table
applies to the robot the file names, also when it is given again (the same robot
name or URDF file), not to another robot that replaces it: a frame the table
would have named is then an error that says so.
"""

from __future__ import annotations

import difflib
import inspect
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hikbench.problems.errors import HikbenchError
from hikbench.problems.hierarchy import Hierarchy, Level
from hikbench.problems.robots.kinematics import KinematicState
from hikbench.problems.robots.limits import FrameDistance, JointPositionLimits, JointVelocityLimits
from hikbench.problems.robots.models import FrameTable, Robot, RobotFileError, RobotNotFoundError, load_robot, \
    robot_source, same_robot
from hikbench.problems.robots.tasks import (
    AlignmentTask,
    ComTask,
    DirectionTask,
    MinimalVelocityTask,
    OrientationTask,
    PoseTask,
    PositionTask,
    PostureTask,
    Task,
)
from hikbench.problems.schema import Any, Bool, List, Number, Str, Table, Where, read_toml

__all__ = [
    "STACK_DIR",
    "TASK_TYPES",
    "Stack",
    "StackError",
    "StackSpec",
    "build_stack",
    "load_stack_spec",
    "make_task",
    "stack_names",
]

STACK_DIR = Path(__file__).parent / "stacks"

#: ``type`` in a stack file -> task class
TASK_TYPES: dict[str, type[Task]] = {
    "position": PositionTask, "orientation": OrientationTask, "pose": PoseTask,
    "direction": DirectionTask, "alignment": AlignmentTask, "com": ComTask, "posture": PostureTask,
    "velocity": MinimalVelocityTask, "joint_limits": JointPositionLimits,
    "velocity_limits": JointVelocityLimits, "distance": FrameDistance,
}


class StackError(HikbenchError, ValueError):
    """A stack spec or file that cannot be used (unknown task type, bad key, missing file)."""


_TASK = Table({"type": Str(what="a task type"), "name": Str(what="a task name")}, required=("type",),
              values=Any(), what="a task table { type = ..., ... }")
_LEVEL = Table({"tasks": List(_TASK, what="a non-empty list of task tables { type = ..., ... }"),
                "name": Str(what="a level name")}, required=("tasks",), what="a [[levels]] table")
#: the stack file (see the module docstring); a task's other keys are its constructor's arguments
#: the robot keys of stack and scenario files (URDF paths relative to the file)
ROBOT_KEYS = {
    "robot": Str(what="a robot name or the path of a .urdf file"),
    "srdf": Str(what="the path of an .srdf file (with a .urdf robot)"),
    "floating_base": Bool(),
    "reference": Str(what="the name of an SRDF group_state (the reference configuration)"),
    "frames": Table(values=Str(what="a frame name of the robot"),
                    what='a table of alias = frame name, e.g. frames = { right_hand = "r_wrist" }'),
}
FRAME_KEYS = ("frame", "frame_a", "frame_b")  #: the task keys that name a frame
SCHEMA = Table({"name": Str(), **ROBOT_KEYS,
                "dt": Number(0, 1, low_open=True, unit="s, the control period"),
                "levels": List(_LEVEL, what="a non-empty list of [[levels]] tables (level 0 first)"),
                "description": Str(empty=True)}, required=("name", "robot", "levels"), defaults={"dt": 0.01})


@dataclass(frozen=True)
class StackSpec:
    """A stack as written in TOML: ``levels`` is a list of lists of task dicts."""

    name: str
    robot: object  #: a robot name or a UrdfSource (:func:`~hikbench.problems.robots.models.robot_source`)
    dt: float
    levels: list[list[dict]]
    level_names: list[str | None] = field(default_factory=list)
    description: str = ""
    source: str = "<dict>"  #: the file it was read from, for error messages
    frames: dict = field(default_factory=dict)  #: the file's [frames] table (for its own robot)

    @classmethod
    def from_dict(cls, d: dict, source: str = "<dict>") -> StackSpec:
        """A spec from parsed TOML, checked against :data:`SCHEMA` (StackError naming
        ``source``, the key path and what was expected); the task tables' own keys
        are checked when the tasks are made (:func:`make_task`)."""
        d = SCHEMA.check(d, "", Where(source, StackError))
        return cls(name=d["name"], robot=file_robot(d, source, StackError), dt=float(d["dt"]),
                   levels=[[dict(t) for t in lv["tasks"]] for lv in d["levels"]],
                   level_names=[lv.get("name") for lv in d["levels"]],
                   description=d.get("description", ""), source=source, frames=dict(d.get("frames", {})))

    @property
    def frame_table(self) -> FrameTable:
        return FrameTable(self.frames, self.source)

    @classmethod
    def from_toml(cls, path: str | os.PathLike) -> StackSpec:
        return cls.from_dict(read_toml(path, StackError, "a stack TOML file"), source=str(path))


def file_robot(d: dict, source: str, error: type[HikbenchError]):
    """The robot a checked stack or scenario table names (``robot``, ``srdf``,
    ``floating_base``, ``reference``; paths relative to the file ``source``), or
    None when it names none."""
    extra = [k for k in ("srdf", "floating_base", "reference") if k in d]
    if "robot" not in d:
        if extra:
            raise error(f"{source}: {', '.join(extra)} without robot: expected robot = \"<path>.urdf\" too")
        return None
    base = Path(source).parent if source != "<dict>" else None
    try:
        return robot_source(d["robot"], d.get("srdf"), d.get("floating_base"), d.get("reference"), base=base)
    except RobotFileError as err:
        raise error(f"{source}: {err}") from err


def stack_names() -> list[str]:
    """Stacks shipped in ``problems/robots/stacks``."""
    return sorted(p.stem for p in STACK_DIR.glob("*.toml"))


def load_stack_spec(name_or_path: str | os.PathLike) -> StackSpec:
    """A shipped stack by name, or a TOML file by path."""
    p = Path(name_or_path)
    if p.suffix == ".toml" or p.exists():
        return StackSpec.from_toml(p)
    path = STACK_DIR / f"{name_or_path}.toml"
    if not path.exists():
        raise StackError(f"unknown stack {str(name_or_path)!r} (shipped: {', '.join(stack_names())}; "
                         "or give the path of a .toml file)")
    return StackSpec.from_toml(path)


def make_task(robot: Robot, spec: dict) -> Task:
    """Build one task from its table ``{type, name?, ...constructor arguments}``: the
    keys are checked against the constructor's arguments (unknown ones with their
    close matches, missing required ones) before it is called."""
    spec = dict(spec)
    task_type = spec.pop("type", None)
    if not isinstance(task_type, str) or task_type not in TASK_TYPES:
        near = difflib.get_close_matches(task_type, list(TASK_TYPES), n=2) if isinstance(task_type, str) else []
        hint = f" (did you mean {' or '.join(map(repr, near))}?)" if near else ""
        raise StackError(f"unknown task type {task_type!r}{hint}; expected one of {', '.join(TASK_TYPES)}")
    cls = TASK_TYPES[task_type]
    params = inspect.signature(cls.__init__).parameters
    allowed = [p for p in params if p not in ("self", "robot")]
    bad = sorted(set(spec) - set(allowed))
    if bad:
        near = sorted({m for k in bad for m in difflib.get_close_matches(str(k), allowed, n=2)})
        hint = f" (did you mean {' or '.join(map(repr, near))}?)" if near else ""
        raise StackError(f"task type {task_type!r}: unknown key(s) {bad}{hint}; expected {allowed}")
    needed = [p for p in allowed if p != "name" and params[p].default is inspect.Parameter.empty]
    missing = [p for p in needed if p not in spec]
    if missing:
        raise StackError(f"task type {task_type!r}: missing key(s) {', '.join(map(repr, missing))}; expected "
                         f"{', '.join(needed)} (optional: {', '.join(p for p in allowed if p not in needed)})")
    if "name" not in spec:  # default: the frame alias, else the class default, else the type
        default = params["name"].default
        if isinstance(spec.get("frame"), str):
            spec["name"] = spec["frame"]
        elif task_type == "distance":
            spec["name"] = f"distance_{spec.get('frame_a')}_{spec.get('frame_b')}"
        else:
            spec["name"] = task_type if default is inspect.Parameter.empty else default
    return cls(robot, **spec)


class Stack:
    """Ordered levels of tasks of one robot (level 0 the highest priority).

    Parameters
    ----------
    spec : StackSpec
    robot : str or UrdfSource, optional
        Overrides ``spec.robot``; the spec's ``[frames]``, written for its robot, applies
        when ``robot`` is the same robot name or URDF file (:func:`same_robot`), else not.
    frames : sequence of FrameTable
        Aliases added after the spec's (a scenario file's ``[frames]``, ``--frame``).
    """

    def __init__(self, spec: StackSpec, robot=None, frames=()):
        self.spec = spec
        #: the spec's [frames] table applies (its own robot), or was left out (another robot)
        self.file_frames_applied = robot is None or same_robot(robot, spec.robot)
        self.robot = _robot(spec, robot, frames, self.file_frames_applied)
        self.dt = spec.dt
        self.levels: list[list[Task]] = []
        for k, lv in enumerate(spec.levels):
            tasks = []
            for i, t in enumerate(lv):
                self._check_frames(k, i, t)
                try:
                    tasks.append(make_task(self.robot, t))
                except HikbenchError as err:  # (a TaskError or StackError without the place)
                    raise StackError(f"{spec.source}: level {k}, task {i} (type {t.get('type')!r}): {err}") from err
            self.levels.append(tasks)
        self.level_names = [given or "+".join(t.name for t in lv)
                            for given, lv in zip(spec.level_names or [None] * len(self.levels), self.levels)]
        names = [t.name for t in self.tasks]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise StackError(f"{spec.source}: stack {spec.name!r}: task names must be unique; repeated: {dup} "
                             f"(a task's name defaults to its frame, else its type)")
        #: tasks whose target the file gives: kept by set_targets_from
        self.given_targets = {task.name for lv, specs in zip(self.levels, spec.levels)
                              for task, t in zip(lv, specs) if "target" in t}
        self.set_targets_from(self.robot.q0)

    def _check_frames(self, k: int, i: int, task: dict) -> None:
        """The frames task ``i`` of level ``k`` names are the robot's (StackError naming the key)."""
        for key in FRAME_KEYS:
            frame = task.get(key)
            if isinstance(frame, str) and not self.robot.has_frame(frame):
                raise StackError(f"{self.spec.source}: levels[{k}].tasks[{i}].{key} = {frame!r}: expected "
                                 f"{self.robot.frame_choices(frame)}{self._frames_left_out(frame)}")

    def _frames_left_out(self, alias: str) -> str:
        """Why the file's [frames] entry for ``alias``, if any, does not apply (another robot)."""
        if self.file_frames_applied or alias not in self.spec.frames:
            return ""
        return (f"; the file's frames.{alias} = {self.spec.frames[alias]!r} is written for its robot "
                f"{robot_label(self.spec.robot)!r} and is not applied to robot {self.robot.name!r}: name the "
                f"frame for this robot where the robot is given (a scenario file's [frames] table, --frame "
                f"{alias}=FRAME), or give the stack's own robot")

    @property
    def tasks(self) -> list[Task]:
        return [t for lv in self.levels for t in lv]

    def task(self, name: str) -> Task:
        for t in self.tasks:
            if t.name == name:
                return t
        raise StackError(f"stack {self.spec.name!r} has no task {name!r} "
                         f"(tasks: {', '.join(t.name for t in self.tasks)})")

    def set_targets_from(self, q: np.ndarray) -> None:
        """Every task's target := its value at q (error 0 there), but the targets
        given in the stack file (:attr:`given_targets`), which are kept."""
        state = KinematicState(self.robot, q)
        for t in self.tasks:
            if t.name not in self.given_targets:
                t.set_target_from(state)

    def hierarchy(self, q: np.ndarray, state: KinematicState | None = None) -> Hierarchy:
        """The hierarchy in u (shape (nv,)) at configuration q: one level per task level,
        rows of eq. (47) for equality tasks, bounds (eq. 48 ...) for inequality tasks."""
        state = state or KinematicState(self.robot, q)
        levels = []
        for name, tasks in zip(self.level_names, self.levels):
            rows = [t.rows(state, self.dt) for t in tasks]
            levels.append(Level(np.vstack([r[0] for r in rows]), np.concatenate([r[1] for r in rows]),
                                np.concatenate([r[2] for r in rows]), name))
        return Hierarchy.from_levels(levels, n=self.robot.nv)

    def errors(self, q: np.ndarray, u: np.ndarray | None = None,
               state: KinematicState | None = None) -> dict[str, float | None]:
        """Task name -> its error norm (``Task.error_norm``) at q, shape (nq,), and for the tasks
        of the velocity (``velocity_limits``: total excess over the limits, rad/s; ``velocity``:
        ||u||) at u, shape (nv,): None for those when u is not given."""
        state = state or KinematicState(self.robot, q)
        return {t.name: t.error_norm(state, u) for t in self.tasks}


def robot_label(ref) -> str:
    """The name a robot reference loads as (a URDF file's stem), without loading it."""
    ref = robot_source(ref)
    return ref if isinstance(ref, str) else ref.name


def _robot(spec: StackSpec, robot, frames, file_frames: bool) -> Robot:
    """The robot of a stack: ``robot`` if given, else the spec's; with the spec's [frames]
    table when ``file_frames``, then ``frames``. A robot the spec names that cannot be
    loaded is a StackError naming the stack file."""
    if robot is not None:
        own = [spec.frame_table] if file_frames else []
        return load_robot(robot).with_frames(*own, *frames)
    try:
        loaded = load_robot(spec.robot)
    except (RobotFileError, RobotNotFoundError) as err:
        raise StackError(f"{spec.source}: robot: {err}") from err
    return loaded.with_frames(spec.frame_table, *frames)


def build_stack(name_or_path: str | os.PathLike, robot=None, frames=()) -> Stack:
    """A :class:`Stack` from a shipped name or a TOML path, optionally on another robot
    (a name, a URDF path or a UrdfSource) with extra frame aliases (FrameTable)."""
    return Stack(load_stack_spec(name_or_path), robot=robot, frames=frames)
