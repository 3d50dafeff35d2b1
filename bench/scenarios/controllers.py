"""Scenario controllers: closed-loop IK that takes the stack's tasks, not a hierarchy's arrays.

A registered solver (:mod:`hikbench.solvers.registry`) solves any
:class:`~hikbench.problems.hierarchy.Hierarchy` and never sees a robot. A
controller is built on a :class:`~hikbench.problems.robots.stacks.Stack` (its
robot, its tasks and their targets) and only runs in ``hikbench scenario``:
``--solver pink`` names one. Per step the runner calls :meth:`Controller.prepare`
(untimed: the configuration q and the tasks' targets of the step), then
:meth:`Controller.solve` on the step's hierarchy, timed like a solver's call;
its u is recorded and judged like any solver's (``err_<task>``, ``level_norm_<level>``
recomputed from the hierarchy at q).

Controllers (:data:`CONTROLLERS`): ``pink`` (pin-pink's weighted differential IK,
:mod:`hikbench.bench.scenarios.pink_ik`).
"""

from __future__ import annotations

import importlib

from hikbench.bench.scenarios.controller import Controller, ControllerError
from hikbench.extras import install_hint
from hikbench.problems.robots.stacks import Stack

__all__ = ["CONTROLLERS", "Controller", "ControllerError", "build_controller", "controller_class", "is_controller"]

#: name -> (module, class) of the controllers ``hikbench scenario --solver NAME`` knows
CONTROLLERS: dict[str, tuple[str, str]] = {"pink": ("hikbench.bench.scenarios.pink_ik", "PinkController")}


def is_controller(name: str) -> bool:
    return name in CONTROLLERS


def controller_class(name: str) -> type[Controller]:
    """The class of controller ``name``; a ControllerError with the install command when
    its package is missing."""
    module, cls = CONTROLLERS[name]
    try:
        return getattr(importlib.import_module(module), cls)
    except ModuleNotFoundError as err:
        if (err.name or "").split(".")[0] == "hikbench":
            raise
        raise ControllerError(f"controller {name!r} is not available: {install_hint(err.name)}") from err


def build_controller(name: str, stack: Stack, **options) -> Controller:
    """A fresh controller ``name`` on ``stack`` with ``options``; an unknown option is a
    ControllerError naming it and the allowed ones."""
    import inspect

    cls = controller_class(name)
    allowed = [p for p in inspect.signature(cls.__init__).parameters if p not in ("self", "stack")]
    unknown = [k for k in options if k not in allowed]
    if unknown:
        raise ControllerError(f"controller {name!r}: unknown option(s) {', '.join(map(repr, unknown))}; "
                              f"allowed options: {', '.join(allowed) or 'none'}")
    return cls(stack, **options)
