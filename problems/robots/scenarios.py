"""Closed-loop scenario definitions: a stack, an initial configuration, and a
schedule of target changes (jumps and sixth-order polynomial trajectories).

The loop itself (solve, integrate q <- q (+) u dt, repeat) is in
``bench/scenarios/runner.py``; this module only says, for each time t, what every task's
target (and target velocity, the feed-forward of eq. 47) is.

TOML format (``problems/robots/scenarios/*.toml``)::

    name = "reach"
    stack = "humanoid_reach"     # a shipped stack name or a stack TOML path
    robot = "talos"              # optional: overrides the stack's robot (a name or a .urdf path,
                                 # with optional srdf, floating_base, reference as in a stack)
    steps = 120                  # default number of control steps
    dt = 0.02                    # optional: overrides the stack's dt (s)
    [initial]                    # start at q0 (+) a seeded perturbation of the joints
    perturbation = 0.02          # rad, standard deviation (0: start at q0)
    seed = 0
    [[events]]                   # at `time` (s) the target of `task` jumps to
    time = 0.0                   # its nominal value (at q0) + `offset` (m, world)
    task = "right_hand"          # (pose tasks: also `rotate_rpy`, rad, frame axes)
    offset = [0.9, -0.2, 0.3]
    unit = "arm_length"          # optional: offset and apex in a length of the robot (below)
    [[trajectories]]             # sixth-order polynomial from the target at `start`
    task = "right_foot"          # to that target + `offset` (or to the mean of
    start = 1.0                  # `to_frames` at `start`, + offset), through
    duration = 1.0               # start + `apex` at `tau_apex` (pose, position)
    offset = [0.1, 0.0, 0.0]
    apex = [0.0, 0.0, 0.05]
    [checks]                     # verified on the per-step record (bench/scenarios/checks.py)
    limits = true                # joint limits never violated, nor the stack's velocity limits
    regulated = ["com"]          # errors decay exponentially and stay regulated
    reach = { task = "right_hand", out_of_reach_until = 1.2 }
    tracked = { right_foot = 0.005 }   # max error along a trajectory
    [plot]
    joints = ["torso_1_joint"]   # joints of Fig. 3 (default: the 12 that move most)
    [frames]                     # aliases of the scenario's robot: alias = frame name
    right_hand = "gripper_right_base_link"

Units: ``offset`` and ``apex`` are metres, or, with ``unit = "arm_length"`` or
``"leg_length"``, multiples of that length of the scenario's robot
(:mod:`hikbench.problems.robots.dimensions`: the summed link lengths of the limb
of its ``right_hand`` (else ``ee``) or ``right_foot`` frame, e.g. talos 0.776 m and
0.812 m, g1 0.452 m and 0.698 m), so that one file holds on robots of other sizes::

    offset_m = unit_length(robot) * offset

A unit the robot cannot measure (no such frame) is a ScenarioError naming the key.

Frames: a ``[frames]`` table applies to the robot of its file (the stack's when
the scenario names none); a robot given to :func:`load_scenario` (``--robot``)
replaces both files' robot and aliases, and takes its own (``--frame``).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin

from hikbench.problems.errors import HikbenchError
from hikbench.problems.robots.dimensions import LENGTHS, robot_length
from hikbench.problems.robots.kinematics import KinematicState
from hikbench.problems.robots.models import FrameTable, same_robot
from hikbench.problems.robots.stacks import ROBOT_KEYS, Stack, file_robot, load_stack_spec
from hikbench.problems.robots.tasks import ComTask, PoseTask, PositionTask, Task
from hikbench.problems.robots.trajectories import PointSegment, PoseSegment
from hikbench.problems.schema import Bool, Int, List, Number, Str, Table, Vec, Where, read_toml

__all__ = ["SCENARIO_DIR", "Scenario", "ScenarioError", "load_scenario", "scenario_names"]

SCENARIO_DIR = Path(__file__).parent / "scenarios"


class ScenarioError(HikbenchError, ValueError):
    """A scenario file or schedule that cannot be used."""


def _vec3(v, what: str) -> np.ndarray:
    a = np.asarray(v if v is not None else (0.0, 0.0, 0.0), dtype=float)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ScenarioError(f"{what} must be 3 finite numbers; got {v!r}")
    return a


MAX_STEPS = 1_000_000       #: control steps of a scenario (a record row each)
MAX_PERTURBATION = math.pi  #: rad, standard deviation of the initial joint perturbation
MAX_OFFSET = 100.0          #: m (and rad for rotate_rpy), per coordinate of a scheduled target change
PLOT_JOINTS_MAX = 80        #: joints of Fig. 3 ([plot] joints): 20 colours x 4 line styles

_NAMES = List(Str(), what="a non-empty list of names")
UNITS = ("m", *LENGTHS)  #: what ``offset`` and ``apex`` are given in (``unit``)
_TARGET_CHANGE = {
    "task": Str(what="a task name of the stack"),
    "offset": Vec(3, "m, world", bound=MAX_OFFSET),
    "unit": Str(UNITS),
    "rotate_rpy": Vec(3, "rad, pose tasks", bound=MAX_OFFSET),
    "to_frames": List(Str(), what="a non-empty list of frame names"),
}
_EVENT = Table({"time": Number(0, unit="s"), **_TARGET_CHANGE}, required=("task",), what="an [[events]] table")
_TRAJECTORY = Table({"start": Number(0, unit="s"), "duration": Number(0, low_open=True, unit="s"),
                     **_TARGET_CHANGE, "apex": Vec(3, "m, world, pose tasks", bound=MAX_OFFSET),
                     "tau_apex": Number(0, 1, low_open=True, high_open=True, unit="pose tasks")},
                    required=("task", "duration"), what="a [[trajectories]] table")
#: the scenario file (see the module docstring); names are checked against the stack after it
SCHEMA = Table({
    "name": Str(), "description": Str(empty=True),
    "stack": Str(what="a shipped stack name or the path of a stack .toml"),
    **ROBOT_KEYS,
    "steps": Int(1, MAX_STEPS),
    "dt": Number(0, 1, low_open=True, unit="s, the control period"),
    "initial": Table({"perturbation": Number(0, MAX_PERTURBATION, unit="rad, a standard deviation"),
                      "seed": Int(0, 2**63 - 1)}),
    "events": List(_EVENT, min_len=0, what="a list of [[events]] tables"),
    "trajectories": List(_TRAJECTORY, min_len=0, what="a list of [[trajectories]] tables"),
    "checks": Table({
        "limits": Bool(),
        "regulated": List(Str(), min_len=0, what='a list of task names, e.g. regulated = ["com"]'),
        "reach": Table({"task": Str(what="a task name"), "out_of_reach_until": Number(0, unit="s")},
                       required=("task", "out_of_reach_until")),
        "tracked": Table(values=Number(0, low_open=True, unit="the task's error units"),
                         what="a table of task name = maximum error, e.g. tracked = { ee = 0.005 }"),
    }),
    "plot": Table({"joints": List(Str(), what="a non-empty list of joint names")}),
}, required=("name", "stack"))
_SCHEDULABLE = (PoseTask, PositionTask, ComTask)
_POSE_ONLY = ("rotate_rpy", "apex", "tau_apex")


def _check_names(d: dict, stack: Stack, at: Where, other_robot: bool) -> None:
    """Task names of the schedule and the checks, frames of ``to_frames`` and the
    plotted joints (on the scenario's own robot) are the stack's."""
    tasks = {t.name: t for t in stack.tasks}
    listed = ", ".join(tasks)

    def task(path: str, name: str, schedulable: bool = False):
        if name not in tasks:
            at.fail(path, name, f"a task of stack {stack.spec.name!r} ({listed})", tasks)
        if schedulable and not isinstance(tasks[name], _SCHEDULABLE):
            at.fail(path, name, f"a pose, position or com task (scheduled targets); {name!r} is a "
                                f"{type(tasks[name]).__name__}")
        return tasks[name]

    for section in ("events", "trajectories"):
        for k, item in enumerate(d.get(section, [])):
            t = task(f"{section}[{k}].task", item["task"], schedulable=True)
            for key in _POSE_ONLY:
                if key in item and not isinstance(t, PoseTask):
                    at.say(f"{section}[{k}].{key}: task {t.name!r} is a {type(t).__name__}; expected "
                           f"{key} only for pose tasks")
            for i, frame in enumerate(item.get("to_frames", [])):
                try:
                    stack.robot.frame_id(frame)
                except HikbenchError as err:
                    at.fail(f"{section}[{k}].to_frames[{i}]", frame, f"a frame of the robot: {err}")
    checks = d.get("checks", {})
    for i, name in enumerate(checks.get("regulated", [])):
        task(f"checks.regulated[{i}]", name)
    for name in checks.get("tracked", {}):
        task(f"checks.tracked.{name}", name)
    if "reach" in checks:
        task("checks.reach.task", checks["reach"]["task"])
    plotted = stack.robot.bounded_joint_names
    joints = d.get("plot", {}).get("joints", [])
    if len(joints) > PLOT_JOINTS_MAX:
        at.say(f"plot.joints: {len(joints)} joints; expected at most {PLOT_JOINTS_MAX} (Fig. 3 gives each its "
               "own colour and line style)")
    for i, joint in enumerate(joints):
        # (on another robot, --robot, names it lacks fall back to the joints that move most)
        if not other_robot and joint not in plotted:
            at.fail(f"plot.joints[{i}]", joint, f"a bounded 1-DOF joint of {stack.robot.name} "
                                                f"({', '.join(plotted)})", plotted)


def _resolve_units(d: dict, robot, at: Where) -> dict[str, float]:
    """Turn every ``offset`` and ``apex`` given in a robot length (``unit``) into metres,
    in place; returns the lengths used (name -> m). A length the robot cannot measure
    (it lacks the frame) is a ScenarioError naming the key."""
    used = {}
    for section in ("events", "trajectories"):
        for k, item in enumerate(d.get(section, [])):
            unit = item.pop("unit", "m")
            if unit == "m":
                continue
            if unit not in used:
                length = robot_length(robot, unit)
                if length is None:
                    at.fail(f"{section}[{k}].unit", unit, f"'m' or a length robot {robot.name!r} has: {unit} is "
                                                       f"measured on the {' or '.join(LENGTHS[unit])} frame, "
                                                       "which it lacks (set it in [frames], or give metres)")
                used[unit] = length
            for key in ("offset", "apex"):
                if key in item:
                    item[key] = [used[unit] * float(v) for v in item[key]]
    return used


def _initial_configuration(stack: Stack, scale: float, seed: int) -> np.ndarray:
    """q0 (+) a seeded normal perturbation of the actuated joints (standard deviation
    ``scale`` rad), kept strictly inside the joint limits; q0 when ``scale`` is 0."""
    robot = stack.robot
    q = robot.q0.copy()
    if scale <= 0:
        return q
    rng = np.random.default_rng(seed)
    v = np.zeros(robot.nv)
    v[robot.actuated] = rng.normal(scale=scale, size=int(robot.actuated.sum()))
    q = pin.integrate(robot.model, q, v)
    qb = robot.bounded_q
    inset = 0.02 * (robot.upper - robot.lower)  # start strictly inside the limits
    q[qb] = np.clip(q[qb], robot.lower + inset, robot.upper - inset)
    return q


@dataclass
class _Item:
    """One scheduled change of one task's target, from ``start`` (s) on."""

    task: Task
    start: float
    spec: dict
    segment: object = None

    def activate(self, state: KinematicState, nominal, current) -> None:
        """Fix the segment from the target current at ``start`` (and the robot state then)."""
        spec, task = self.spec, self.task
        offset = _vec3(spec.get("offset"), f"{task.name}: offset")
        rot = pin.rpy.rpyToMatrix(*_vec3(spec.get("rotate_rpy"), f"{task.name}: rotate_rpy"))
        is_event = "duration" not in spec
        base = nominal if is_event else current
        if isinstance(task, PoseTask):
            T1 = pin.SE3(base.rotation @ rot, base.translation + offset)
            if "to_frames" in spec:
                T1.translation = self._frames_mean(state) + offset
            self.segment = T1 if is_event else PoseSegment(
                self.start, float(spec["duration"]), pin.SE3(current), T1,
                _vec3(spec.get("apex"), f"{task.name}: apex"), float(spec.get("tau_apex", 0.5)))
        elif isinstance(task, (PositionTask, ComTask)):
            p1 = base + offset
            if "to_frames" in spec:
                m = self._frames_mean(state)
                p1 = np.array(base, dtype=float)
                p1[task.axes] = m[task.axes] + offset[task.axes]
            self.segment = p1 if is_event else PointSegment(self.start, float(spec["duration"]),
                                                            np.array(current), p1)
        else:
            raise ScenarioError(f"task {task.name!r} ({type(task).__name__}): scheduled targets are "
                                "supported for pose, position and com tasks")

    def _frames_mean(self, state: KinematicState) -> np.ndarray:
        ids = [state.robot.frame_id(f) for f in self.spec["to_frames"]]
        return np.mean([state.position(i) for i in ids], axis=0)

    def apply(self, t: float) -> None:
        if isinstance(self.segment, (pin.SE3, np.ndarray)):
            self.task.target = pin.SE3(self.segment) if isinstance(self.segment, pin.SE3) else \
                np.array(self.segment)
            self.task.target_velocity = None
            return
        target, velocity = self.segment(t)
        self.task.target = target
        self.task.target_velocity = velocity


@dataclass
class Scenario:
    """A closed-loop scenario: stack, initial configuration, schedule, checks.

    Attributes
    ----------
    stack : Stack
    steps : int
        Default number of control steps.
    dt : float
        Control period (s); the stack's unless overridden.
    q_init : ndarray, shape (nq,)
    checks : dict
        The ``[checks]`` table (see the module docstring).
    """

    name: str
    stack: Stack
    steps: int
    q_init: np.ndarray
    checks: dict = field(default_factory=dict)
    description: str = ""
    plot_joints: list[str] | None = None
    units: dict = field(default_factory=dict)  #: length name -> m, for the ``unit`` values the file uses
    _schedule: dict = field(default_factory=dict)
    _nominal: dict = field(default_factory=dict)

    @property
    def dt(self) -> float:
        return self.stack.dt

    @property
    def robot(self):
        return self.stack.robot

    @classmethod
    def from_dict(cls, d: dict, source: str = "<dict>", robot=None, frames: FrameTable | None = None) -> Scenario:
        """A scenario from parsed TOML; every value is checked against :data:`SCHEMA`, then
        the task, frame and joint names against the stack (ScenarioError naming
        ``source``, the key path and what was expected). ``robot`` (a name, URDF path
        or UrdfSource) replaces the files' robot, ``frames`` adds aliases to it."""
        at = Where(source, ScenarioError)
        d = SCHEMA.check(d, "", at)
        stack_ref = d["stack"]
        if stack_ref.endswith(".toml") and not os.path.isabs(stack_ref):
            stack_ref = str(Path(source).parent / stack_ref)
        extra = [frames] if frames is not None else []
        own = file_robot(d, source, ScenarioError)
        spec = load_stack_spec(stack_ref)
        # the files' [frames] tables are written for their robot: given again (the same name or
        # URDF file) it keeps them; another robot does not
        other_robot = robot is not None and not same_robot(robot, own if own is not None else spec.robot)
        if other_robot:
            stack = Stack(spec, robot=robot, frames=extra)
        else:
            stack = Stack(spec, robot=own if robot is None else robot,
                          frames=[FrameTable(dict(d.get("frames", {})), source), *extra])
        if "dt" in d:
            stack.dt = float(d["dt"])
        _check_names(d, stack, at, other_robot=other_robot)
        units = _resolve_units(d, stack.robot, at)
        init = d.get("initial", {})
        q = _initial_configuration(stack, float(init.get("perturbation", 0.0)), int(init.get("seed", 0)))
        sc = cls(name=d["name"], stack=stack, steps=int(d.get("steps", 100)), q_init=q,
                 checks=dict(d.get("checks", {})), description=d.get("description", ""),
                 plot_joints=d.get("plot", {}).get("joints"), units=units)
        sc._nominal = {t.name: _copy_target(t.target) for t in stack.tasks if hasattr(t, "target")}
        for section in ("events", "trajectories"):
            for item in d.get(section, []):
                task = stack.task(item["task"])
                start = float(item.get("time" if section == "events" else "start", 0.0))
                spec = {k2: v for k2, v in item.items() if k2 not in ("task", "time", "start")}
                sc._schedule.setdefault(task.name, []).append(_Item(task, start, spec))
        for items in sc._schedule.values():
            items.sort(key=lambda it: it.start)
        return sc

    def targets_at(self, t: float, state: KinematicState) -> None:
        """Set every scheduled task's target (and target velocity) for time t (s)."""
        for name, items in self._schedule.items():
            live = [it for it in items if it.start <= t + 1e-9]
            if not live:
                continue
            item = live[-1]
            if item.segment is None:
                item.activate(state, self._nominal[name], _copy_target(item.task.target))
            item.apply(t)

    def event_times(self) -> list[float]:
        """Start times (s) of the scheduled changes after t = 0 (for plots)."""
        return sorted({it.start for items in self._schedule.values() for it in items if it.start > 0})

    def reset(self) -> None:
        """Back to the nominal targets and an unstarted schedule (before a new run)."""
        for t in self.stack.tasks:
            if t.name in self._nominal:
                t.target = _copy_target(self._nominal[t.name])
                t.target_velocity = None
        for items in self._schedule.values():
            for it in items:
                it.segment = None


def _copy_target(target):
    if target is None:
        return None
    return pin.SE3(target) if isinstance(target, pin.SE3) else np.array(target, copy=True)


def scenario_names() -> list[str]:
    """Scenarios shipped in ``problems/robots/scenarios``."""
    return sorted(p.stem for p in SCENARIO_DIR.glob("*.toml"))


def load_scenario(name_or_path: str | os.PathLike, robot=None, frames: FrameTable | None = None) -> Scenario:
    """A shipped scenario by name, or a scenario TOML file by path (a name
    ending in ``.toml`` or an existing file; a directory named like a shipped
    scenario does not hide it)."""
    p = Path(name_or_path)
    if not (p.suffix == ".toml" or p.is_file()):
        p = SCENARIO_DIR / f"{name_or_path}.toml"
        if not p.exists():
            raise ScenarioError(f"unknown scenario {str(name_or_path)!r} (shipped: "
                                f"{', '.join(scenario_names())}; or give the path of a .toml file)")
    return Scenario.from_dict(read_toml(p, ScenarioError, "a scenario TOML file"), source=str(p), robot=robot,
                              frames=frames)

