"""Closed-loop scenario definitions: a stack, an initial configuration, and a
schedule of target changes (jumps and sixth-order polynomial trajectories).

The loop itself (solve, integrate q <- q (+) u dt, repeat) is in
``bench/scenarios/runner.py``; this module only says, for each time t, what every task's
target (and target velocity, the feed-forward of eq. 47) is.

TOML format (``problems/robots/scenarios/*.toml``)::

    name = "reach"
    stack = "humanoid_reach"     # a shipped stack name or a stack TOML path
    robot = "talos"              # optional: overrides the stack's robot
    steps = 120                  # default number of control steps
    dt = 0.02                    # optional: overrides the stack's dt (s)
    [initial]                    # start at q0 (+) a seeded perturbation of the joints
    perturbation = 0.02          # rad, standard deviation (0: start at q0)
    seed = 0
    [[events]]                   # at `time` (s) the target of `task` jumps to
    time = 0.0                   # its nominal value (at q0) + `offset` (m, world)
    task = "right_hand"          # (pose tasks: also `rotate_rpy`, rad, frame axes)
    offset = [0.9, -0.2, 0.3]
    [[trajectories]]             # sixth-order polynomial from the target at `start`
    task = "right_foot"          # to that target + `offset` (or to the mean of
    start = 1.0                  # `to_frames` at `start`, + offset), through
    duration = 1.0               # start + `apex` at `tau_apex` (pose, position)
    offset = [0.1, 0.0, 0.0]
    apex = [0.0, 0.0, 0.05]
    [checks]                     # verified by the runner on the per-step record
    limits = true                # joint limits never violated
    regulated = ["com"]          # errors decay exponentially and stay regulated
    reach = { task = "right_hand", out_of_reach_until = 1.2 }
    tracked = { right_foot = 0.005 }   # max error along a trajectory
    [plot]
    joints = ["torso_1_joint"]   # joints of Fig. 3 (default: the 12 that move most)
"""

from __future__ import annotations

import os
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin

from hikbench.problems.errors import HikbenchError
from hikbench.problems.robots.kinematics import KinematicState
from hikbench.problems.robots.stacks import Stack, build_stack
from hikbench.problems.robots.tasks import ComTask, PoseTask, PositionTask, Task
from hikbench.problems.robots.trajectories import PointSegment, PoseSegment

__all__ = ["SCENARIO_DIR", "Scenario", "ScenarioError", "load_scenario", "scenario_names"]

SCENARIO_DIR = Path(__file__).parent / "scenarios"
_TOP_KEYS = {"name", "description", "stack", "robot", "steps", "dt", "initial", "events", "trajectories",
             "checks", "plot"}


class ScenarioError(HikbenchError, ValueError):
    """A scenario file or schedule that cannot be used."""


def _vec3(v, what: str) -> np.ndarray:
    a = np.asarray(v if v is not None else (0.0, 0.0, 0.0), dtype=float)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ScenarioError(f"{what} must be 3 finite numbers; got {v!r}")
    return a


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
    _schedule: dict = field(default_factory=dict)
    _nominal: dict = field(default_factory=dict)

    @property
    def dt(self) -> float:
        return self.stack.dt

    @property
    def robot(self):
        return self.stack.robot

    @classmethod
    def from_dict(cls, d: dict, source: str = "<dict>", robot: str | None = None) -> Scenario:
        unknown = set(d) - _TOP_KEYS
        if unknown:
            raise ScenarioError(f"{source}: unknown key(s) {sorted(unknown)}; expected {sorted(_TOP_KEYS)}")
        for key in ("name", "stack"):
            if key not in d:
                raise ScenarioError(f"{source}: missing key {key!r}")
        stack_ref = d["stack"]
        if isinstance(stack_ref, str) and stack_ref.endswith(".toml") and not os.path.isabs(stack_ref):
            stack_ref = str(Path(source).parent / stack_ref)
        stack = build_stack(stack_ref, robot=robot or d.get("robot"))
        if "dt" in d:
            stack.dt = float(d["dt"])
        steps = int(d.get("steps", 100))
        if steps < 1:
            raise ScenarioError(f"{source}: steps must be >= 1; got {steps}")
        init = d.get("initial", {})
        q = stack.robot.q0.copy()
        scale = float(init.get("perturbation", 0.0))
        if scale > 0:
            rng = np.random.default_rng(int(init.get("seed", 0)))
            v = np.zeros(stack.robot.nv)
            act = stack.robot.actuated
            v[act] = rng.normal(scale=scale, size=int(act.sum()))
            q = pin.integrate(stack.robot.model, q, v)
            qb = stack.robot.bounded_q
            inset = 0.02 * (stack.robot.upper - stack.robot.lower)  # start strictly inside the limits
            q[qb] = np.clip(q[qb], stack.robot.lower + inset, stack.robot.upper - inset)
        joints = d.get("plot", {}).get("joints")
        if joints is not None and robot is None:
            # (on another robot, --robot, names it lacks fall back to the joints that move most)
            plotted = stack.robot.bounded_joint_names
            bad = [j for j in joints if j not in plotted] if isinstance(joints, list) else [joints]
            if bad:
                raise ScenarioError(f"{source}: [plot] joints: {bad} are not bounded 1-DOF joints of "
                                    f"{stack.robot.name}; expected a list of some of {plotted}")
        sc = cls(name=str(d["name"]), stack=stack, steps=steps, q_init=q, checks=dict(d.get("checks", {})),
                 description=str(d.get("description", "")), plot_joints=joints)
        sc._nominal = {t.name: _copy_target(t.target) for t in stack.tasks if hasattr(t, "target")}
        for kind in ("events", "trajectories"):
            for k, item in enumerate(d.get(kind, [])):
                if "task" not in item:
                    raise ScenarioError(f"{source}: {kind}[{k}] needs a 'task'")
                task = stack.task(item["task"])
                start = float(item.get("time" if kind == "events" else "start", 0.0))
                if kind == "trajectories" and "duration" not in item:
                    raise ScenarioError(f"{source}: trajectories[{k}] needs a 'duration' (s)")
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


def load_scenario(name_or_path: str | os.PathLike, robot: str | None = None) -> Scenario:
    """A shipped scenario by name, or a scenario TOML file by path (a name
    ending in ``.toml`` or an existing file; a directory named like a shipped
    scenario does not hide it)."""
    p = Path(name_or_path)
    if not (p.suffix == ".toml" or p.is_file()):
        p = SCENARIO_DIR / f"{name_or_path}.toml"
        if not p.exists():
            raise ScenarioError(f"unknown scenario {str(name_or_path)!r} (shipped: "
                                f"{', '.join(scenario_names())}; or give the path of a .toml file)")
    try:
        with open(p, "rb") as f:
            data = tomllib.load(f)
    except (OSError, tomllib.TOMLDecodeError) as err:
        raise ScenarioError(f"{p}: cannot read scenario file ({err})") from err
    return Scenario.from_dict(data, source=str(p), robot=robot)
